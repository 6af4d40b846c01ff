//! The run summary (`<out>/<stem>.summary.json`) as one typed struct: written by `run`, read
//! by `bench`, `eval` and the tests, so no one edits or reads it by key.

use std::collections::BTreeMap;
use std::path::Path;

use dynaflow_engine::runtime::RunReport;
pub use dynaflow_operators::report::{LabelAccuracyReport, NodeReport, TrackerReport};

/// A tracker's absolute trajectory error, as the tracker reports it (its node named).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Ate {
    /// The tracker node (set on the summary's top-level `ate`, the first tracker's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node: Option<String>,
    /// Root mean square error, metres.
    pub rmse: f64,
    /// Mean, metres.
    pub mean: f64,
    /// Median, metres.
    pub median: f64,
    /// Standard deviation, metres.
    pub std: f64,
    /// Poses matched with ground truth.
    #[serde(default)]
    pub pairs: u64,
    /// The alignment (`se3`, `sim3`, `none`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub align: Option<String>,
    /// Whatever else the tracker put there.
    #[serde(flatten)]
    pub more: serde_json::Map<String, serde_json::Value>,
}

/// Everything a run wrote about itself.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Summary {
    /// The engine's report: status, frames, per-node and per-edge metrics, recorders, failures.
    #[serde(flatten)]
    pub run: RunReport,
    /// The first tracker's ATE (in graph order: the reference the others are compared with).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ate: Option<Ate>,
    /// Every tracker's ATE, by node.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub trackers: BTreeMap<String, Ate>,
    /// Per-port content digests (`--digest`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub digests: Option<serde_json::Value>,
}

impl Summary {
    /// The summary of `report`: trackers' ATEs lifted from their node reports, recorders'
    /// costs per frame filled in.
    pub fn of(mut run: RunReport) -> Self {
        let frames = run.frames.max(1) as f64;
        for r in run.recorders.values_mut() {
            r.bytes_per_frame = r.file_bytes.map(|b| (b as f64 / frames).round());
            for p in r.ports.values_mut() {
                p.bytes_per_frame = Some((p.bytes as f64 / frames).round());
            }
        }
        let trackers: BTreeMap<String, Ate> = run
            .nodes
            .iter()
            .filter_map(|n| {
                let Some(NodeReport::Tracker(t)) = n.report.as_ref().and_then(NodeReport::from_json) else {
                    return None;
                };
                Some((n.node.clone(), serde_json::from_value(serde_json::to_value(t.ate?).ok()?).ok()?))
            })
            .collect();
        let ate = run.nodes.iter().find_map(|n| {
            let mut a = trackers.get(&n.node)?.clone();
            a.node = Some(n.node.clone());
            Some(a)
        });
        Self { run, ate, trackers, digests: None }
    }

    /// Read a summary file.
    pub fn read(path: &Path) -> Result<Self, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        serde_json::from_slice(&bytes).map_err(|e| format!("{}: not a dynaflow summary: {e}", path.display()))
    }

    /// Write it (pretty JSON and a newline), as a new file renamed into place.
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        dynaflow_engine::files::write_atomic(path, (text + "\n").as_bytes())
    }

    /// What the operator of node `node` reported, if anything.
    pub fn node_report(&self, node: &str) -> Option<&serde_json::Value> {
        self.run.nodes.iter().find(|n| n.node == node)?.report.as_ref()
    }

    /// Every node's typed report, by node, in graph order (reports of no known kind left out).
    pub fn reports(&self) -> impl Iterator<Item = (&str, NodeReport)> {
        self.run.nodes.iter().filter_map(|n| Some((n.node.as_str(), NodeReport::from_json(n.report.as_ref()?)?)))
    }

    /// The tracker report of node `node`.
    pub fn tracker(&self, node: &str) -> Option<TrackerReport> {
        match NodeReport::from_json(self.node_report(node)?)? {
            NodeReport::Tracker(t) => Some(*t),
            _ => None,
        }
    }
}
