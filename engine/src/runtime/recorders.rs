//! The recorders' side of a run: each sink on its own thread with its own bounded queue, fed
//! by the node tasks' taps (recorded messages and parameter changes).

use std::sync::Arc;

use super::metrics::{Failure, ParameterChange};
use crate::msg::Message;
use crate::sink::{RunInfo, Sink, SinkError, SinkReport};
use crate::spec::RecordPolicy;

/// What a node task hands the recorders.
pub(crate) enum Tap {
    /// A recorded message of `node.port`.
    Message { node: Arc<str>, port: &'static str, msg: Arc<Message> },
    /// A parameter of `node` changed while running, at sensor time `stamp`.
    Change { node: Arc<str>, change: ParameterChange, stamp: f64 },
}

/// Capacity of each recorder's queue; producers wait when it is full, so recording applies
/// backpressure instead of losing messages.
const TAP_CAPACITY: usize = 256;

/// What a recorder thread hands back: its failures, messages it never saw after failing,
/// and its report.
pub(crate) struct SinkDone {
    pub name: String,
    pub failures: Vec<Failure>,
    pub lost: u64,
    pub report: SinkReport,
}

pub(crate) type SinkJoin = std::thread::JoinHandle<SinkDone>;

/// Open every sink, then give each its own thread and queue, so a slow recorder (image
/// encoding) never holds up a fast one.
pub(crate) fn sink_threads(
    mut sinks: Vec<Box<dyn Sink>>,
    info: &RunInfo,
) -> Result<(Vec<tokio::sync::mpsc::Sender<Tap>>, Vec<SinkJoin>), SinkError> {
    for i in 0..sinks.len() {
        if let Some(Err(e)) = sinks.get_mut(i).map(|s| s.open(info)) {
            // Close the ones already open so their files are valid.
            for s in sinks.iter_mut().take(i) {
                let _ = s.close();
            }
            return Err(e);
        }
    }
    let mut senders = Vec::new();
    let mut handles = Vec::new();
    for mut sink in sinks {
        let (tx, mut rx) = tokio::sync::mpsc::channel::<Tap>(TAP_CAPACITY);
        let name = format!("dynaflow-sink-{}", sink.name());
        let handle = std::thread::Builder::new()
            .name(name)
            .spawn(move || {
                let mut failures = Vec::new();
                let mut lost = 0u64;
                let mut live = true;
                while let Some(tap) = rx.blocking_recv() {
                    if !live {
                        lost += 1;
                        continue;
                    }
                    let done = match &tap {
                        Tap::Message { node, port, msg } => sink.record_shared(node, port, msg),
                        Tap::Change { node, change, stamp } => sink.parameter_change(node, change, *stamp),
                    };
                    if let Err(e) = done {
                        tracing::error!("recording stopped: {e}");
                        failures.push(Failure { node: format!("sink:{}", sink.name()), error: e.to_string() });
                        let _ = sink.close();
                        live = false;
                    }
                }
                if live && let Err(e) = sink.close() {
                    failures.push(Failure { node: format!("sink:{}", sink.name()), error: e.to_string() });
                }
                SinkDone { name: sink.name().to_owned(), failures, lost, report: sink.report() }
            })
            .map_err(|e| SinkError::new("sinks", format!("cannot start a recorder thread: {e}")))?;
        senders.push(tx);
        handles.push(handle);
    }
    Ok((senders, handles))
}

/// Whether a message of frame `seq` is recorded under `policy`.
pub(crate) fn records(policy: RecordPolicy, seq: u64) -> bool {
    match policy {
        RecordPolicy::All => true,
        RecordPolicy::None => false,
        RecordPolicy::Every(n) => seq.is_multiple_of(n.max(1)),
    }
}
