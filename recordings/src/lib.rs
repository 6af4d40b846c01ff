//! dynaflow's recorders. Today: a JSON-lines message log (one line per recorded message with
//! its header, type, content digest and a small summary). The rerun `.rrd` and MCAP sinks and
//! `dynaflow diff` build on the same [`dynaflow_engine::sink::Sink`] interface.

mod jsonl;

pub use jsonl::MessageLog;
