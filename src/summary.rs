//! The run summary (`<out>/<stem>.summary.json`) as one typed struct: written by `run`, read
//! by `bench`, `eval` and the tests, so no one edits or reads it by key.

use std::collections::BTreeMap;
use std::path::Path;

use dynaflow_engine::runtime::RunReport;
pub use dynaflow_engine::sink::PortDigest;
pub use dynaflow_operators::report::{
    Ate, BagReport, GateReport, InferenceReport, LabelAccuracyReport, LocalMappingReport, LoopClosingReport,
    LoopReport, MaskAccuracyReport, NodeReport, OctomapReport, ReportKind, SourceReport, TrackerReport,
};

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
    /// Per-port content digests (`--digest`), by `node/port`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub digests: Option<BTreeMap<String, PortDigest>>,
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
                Some((n.node.clone(), t.ate?))
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

    /// What the operator of node `node` reported, typed (`None` without a report of a known kind).
    pub fn report(&self, node: &str) -> Option<NodeReport> {
        NodeReport::from_json(self.run.nodes.iter().find(|n| n.node == node)?.report.as_ref()?)
    }

    /// Node `node`'s report if it is of kind `T`: `summary.report_as::<LoopClosingReport>("closing")`.
    pub fn report_as<T: ReportKind>(&self, node: &str) -> Option<T> {
        T::from_report(self.report(node)?)
    }

    /// Every node's typed report, by node, in graph order (reports of no known kind left out).
    pub fn reports(&self) -> impl Iterator<Item = (&str, NodeReport)> {
        self.run.nodes.iter().filter_map(|n| Some((n.node.as_str(), NodeReport::from_json(n.report.as_ref()?)?)))
    }

    /// The tracker report of node `node`.
    pub fn tracker(&self, node: &str) -> Option<TrackerReport> {
        self.report_as(node)
    }
}
