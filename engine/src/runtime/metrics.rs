//! Per-node and per-edge measurements, and the end-of-run report.

use std::time::Duration;

use super::edge::EdgeStats;

/// Raw per-node counters, filled by the node's task.
#[derive(Clone, Debug, Default)]
pub(crate) struct NodeMetrics {
    pub frames: u64,
    pub skipped: u64,
    pub busy: Duration,
    /// Per fired frame: time from inputs complete to outputs handed on (µs).
    pub latency_us: Vec<f32>,
    /// Per fired frame: time since the source emitted the frame (µs).
    pub age_us: Vec<f32>,
}

/// Summary statistics of a set of durations, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct LatencyStats {
    /// Mean.
    pub mean_ms: f64,
    /// Median.
    pub p50_ms: f64,
    /// 95th percentile.
    pub p95_ms: f64,
    /// Maximum.
    pub max_ms: f64,
}

impl LatencyStats {
    pub(crate) fn from_us(samples: &[f32]) -> Self {
        if samples.is_empty() {
            return Self::default();
        }
        let mut v: Vec<f64> = samples.iter().map(|&s| f64::from(s) / 1000.0).collect();
        v.sort_by(f64::total_cmp);
        let pick = |q: f64| {
            let i = ((v.len() - 1) as f64 * q).round() as usize;
            v.get(i).copied().unwrap_or_default()
        };
        Self {
            mean_ms: v.iter().sum::<f64>() / v.len() as f64,
            p50_ms: pick(0.5),
            p95_ms: pick(0.95),
            max_ms: pick(1.0),
        }
    }
}

/// What one node did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct NodeReport {
    /// Node id.
    pub node: String,
    /// Operator.
    pub op: String,
    /// Frames processed (for sources: produced).
    pub frames: u64,
    /// Frames skipped because a required input was absent (or the node is disabled).
    pub skipped: u64,
    /// Processing latency per frame.
    pub latency: LatencyStats,
    /// Time since the source emitted the frame, when this node finished it.
    pub age: LatencyStats,
    /// Total time inside the operator, seconds.
    pub busy_s: f64,
    /// Largest queue depth over the node's inputs.
    pub max_queue: usize,
    /// Messages dropped on the node's inputs.
    pub dropped: u64,
}

/// What one edge did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct EdgeReport {
    /// `producer.port -> consumer/port`.
    pub edge: String,
    /// Counters.
    #[serde(flatten)]
    pub stats: EdgeStats,
}

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    /// All sources ended and every frame went through.
    Completed,
    /// Stopped by SIGINT/SIGTERM; in-flight frames were finished.
    Interrupted,
    /// An operator or sink failed.
    Failed,
}

/// A node (or sink) that failed.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Failure {
    /// Node id, or `sink:<name>`.
    pub node: String,
    /// The error, including panics.
    pub error: String,
}

/// Everything measured in a run; written as `<out>/<name>.summary.json`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunReport {
    /// Graph name.
    pub graph: String,
    /// Variant.
    pub variant: Option<String>,
    /// Seed.
    pub seed: u64,
    /// Paced at sensor rate?
    pub realtime: bool,
    /// Outcome.
    pub status: RunStatus,
    /// Frames produced by the sources (max over sources).
    pub frames: u64,
    /// Wall-clock seconds.
    pub wall_s: f64,
    /// Per node, in graph order.
    pub nodes: Vec<NodeReport>,
    /// Per edge.
    pub edges: Vec<EdgeReport>,
    /// Total messages dropped by queue policies.
    pub dropped: u64,
    /// Messages recorded but lost because a sink failed.
    pub sink_dropped: u64,
    /// Failures.
    pub failures: Vec<Failure>,
}

impl RunReport {
    /// A fixed-width table for the terminal.
    pub fn table(&self) -> String {
        let mut out = format!(
            "{:<16} {:<14} {:>7} {:>7} {:>9} {:>9} {:>9} {:>9} {:>8} {:>6} {:>7}\n",
            "node", "op", "frames", "skipped", "mean ms", "p50 ms", "p95 ms", "max ms", "busy s", "queue", "dropped"
        );
        for n in &self.nodes {
            out.push_str(&format!(
                "{:<16} {:<14} {:>7} {:>7} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>8.3} {:>6} {:>7}\n",
                n.node,
                n.op,
                n.frames,
                n.skipped,
                n.latency.mean_ms,
                n.latency.p50_ms,
                n.latency.p95_ms,
                n.latency.max_ms,
                n.busy_s,
                n.max_queue,
                n.dropped
            ));
        }
        out.push_str(&format!(
            "{:?}: {} frames in {:.2} s, {} messages dropped by queue policies\n",
            self.status, self.frames, self.wall_s, self.dropped
        ));
        out
    }
}
