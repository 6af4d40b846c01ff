//! dynaflow's recorders and run tools: the rerun `.rrd` recorder, the MCAP recorder, the ROS 2
//! bag recorder, the JSON-lines message log and `dynaflow diff` of two recorded runs. This is
//! the only crate that depends on `rerun`, and on `mcap` but for the bag reader.
//!
//! Modules: `rrd` (rerun), `live` (the same stream to a running viewer), `mcap` (MCAP + Foxglove
//! JSON schemas), `ros2` (a rosbag2 bag: `ros2msg` schemas, CDR), `jsonl` (message log),
//! `payload` (the numeric `dynaflow` object stored with each MCAP message), `encode` (pixel
//! codecs), `diff` (run comparison), `replay` (the
//! `mcap_replay` source); [`Error`] is the crate's one error type.

#![warn(missing_docs)]

pub mod diff;
pub mod encode;
mod error;
mod jsonl;
pub mod live;
pub mod mcap;
pub mod merge;
mod payload;
pub mod replay;
pub mod ros2;
pub mod rrd;

pub use encode::{EncodeCache, ImageCodec};
pub use error::Error;
pub use jsonl::MessageLog;
pub use live::LiveSink;
pub use mcap::McapSink;
pub use ros2::Ros2Sink;
pub use rrd::RrdSink;

/// Register the operators this crate provides (`mcap_replay`).
pub fn register(registry: &mut dynaflow_engine::op::Registry) {
    registry.register(replay::MCAP_REPLAY);
}
