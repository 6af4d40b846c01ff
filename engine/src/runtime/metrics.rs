//! Per-node and per-edge measurements, and the end-of-run report.

use std::time::{Duration, Instant};

use super::edge::EdgeStats;

/// Raw per-node counters, filled by the node's task.
#[derive(Clone, Debug, Default)]
pub(crate) struct NodeMetrics {
    pub frames: u64,
    pub skipped: u64,
    pub busy: Duration,
    /// Per fired frame: time from inputs complete to outputs handed on.
    pub latency: Histogram,
    /// The same for the first and the last [`ENDS_FRAMES`] frames: does a node slow down as
    /// the run goes on (a map that grows)?
    pub ends: LatencyEnds,
    /// Per fired frame: time since the source emitted the frame.
    pub age: Histogram,
    /// The operator's own contribution to the summary.
    pub report: Option<serde_json::Value>,
    /// Parameters changed while running, in order.
    pub parameter_changes: Vec<ParameterChange>,
    /// The newest frame handled (processed or skipped).
    pub last_seq: Option<u64>,
    /// When the first and the newest frame were handled.
    pub first_at: Option<Instant>,
    pub last_at: Option<Instant>,
}

impl NodeMetrics {
    /// Frame `seq` handled (processed or skipped) now.
    pub fn handled(&mut self, seq: u64) {
        let now = Instant::now();
        self.first_at.get_or_insert(now);
        self.last_at = Some(now);
        self.last_seq = Some(self.last_seq.map_or(seq, |s| s.max(seq)));
    }

    /// Frames handled per second between the first and the newest (0 before two).
    pub fn rate_hz(&self) -> f64 {
        let n = self.frames + self.skipped;
        match (self.first_at, self.last_at) {
            (Some(a), Some(b)) if n >= 2 && b > a => (n - 1) as f64 / (b - a).as_secs_f64(),
            _ => 0.0,
        }
    }
}

/// A parameter changed while the graph ran (`run --set-at`): from frame `frame` on.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ParameterChange {
    /// The first frame computed with the new value.
    pub frame: u64,
    /// The parameter.
    pub param: String,
    /// Its value before.
    pub old: serde_json::Value,
    /// And after.
    pub new: serde_json::Value,
}

/// Frames at each end of a run whose latencies the summary reports apart
/// ([`NodeReport::latency_ends`]).
pub const ENDS_FRAMES: usize = 1000;

/// The latencies of a node's first and last [`ENDS_FRAMES`] frames (a ring of the last ones:
/// 4 KiB a node, however long the run).
#[derive(Clone, Debug, Default)]
pub(crate) struct LatencyEnds {
    first: Histogram,
    last: std::collections::VecDeque<f32>,
}

impl LatencyEnds {
    pub fn record(&mut self, d: Duration) {
        if self.first.n < ENDS_FRAMES as u64 {
            self.first.record(d);
        }
        if self.last.len() == ENDS_FRAMES {
            self.last.pop_front();
        }
        self.last.push_back(d.as_secs_f32());
    }

    /// Both ends, once the run has had two windows' worth of frames (so they do not overlap).
    pub fn report(&self, frames: u64) -> Option<EndsStats> {
        if frames < 2 * ENDS_FRAMES as u64 {
            return None;
        }
        let mut last = Histogram::default();
        for &s in &self.last {
            last.record(Duration::from_secs_f32(s));
        }
        Some(EndsStats { frames: ENDS_FRAMES, first: self.first.stats(), last: last.stats() })
    }
}

/// A node's latency over the first and over the last frames of a run.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EndsStats {
    /// Frames in each window.
    pub frames: usize,
    /// The first `frames` frames.
    pub first: LatencyStats,
    /// The last `frames` frames.
    pub last: LatencyStats,
}

/// Relative width of a histogram bucket: quantiles are exact to within 1 %.
const BUCKET_GROWTH: f64 = 1.01;
/// Durations below this (1 µs) share the first bucket.
const BUCKET_FLOOR_S: f64 = 1e-6;

/// A log-bucketed histogram of durations: constant memory however long the run (a few
/// thousand buckets at most, for durations up to days), quantiles within 1 %, exact mean and
/// maximum.
#[derive(Clone, Debug, Default)]
pub(crate) struct Histogram {
    counts: Vec<u64>,
    n: u64,
    sum_s: f64,
    max_s: f64,
}

impl Histogram {
    fn bucket(seconds: f64) -> usize {
        if seconds <= BUCKET_FLOOR_S {
            return 0;
        }
        // Finite and positive here; the cast saturates for absurd values.
        ((seconds / BUCKET_FLOOR_S).ln() / BUCKET_GROWTH.ln()).ceil() as usize
    }

    /// The upper edge of bucket `i`, seconds.
    fn upper(i: usize) -> f64 {
        BUCKET_FLOOR_S * BUCKET_GROWTH.powi(i32::try_from(i).unwrap_or(i32::MAX))
    }

    pub fn record(&mut self, d: Duration) {
        let s = d.as_secs_f64();
        let i = Self::bucket(s);
        if self.counts.len() <= i {
            self.counts.reserve_exact(i + 1 - self.counts.len());
            self.counts.resize(i + 1, 0);
        }
        if let Some(c) = self.counts.get_mut(i) {
            *c += 1;
        }
        self.n += 1;
        self.sum_s += s;
        self.max_s = self.max_s.max(s);
    }

    /// The `q`-quantile (nearest rank), seconds: the upper edge of its bucket, capped at the
    /// maximum seen.
    fn quantile(&self, q: f64) -> f64 {
        if self.n == 0 {
            return 0.0;
        }
        let rank = ((self.n as f64 * q).ceil() as u64).clamp(1, self.n);
        let mut seen = 0;
        for (i, c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Self::upper(i).min(self.max_s);
            }
        }
        self.max_s
    }

    /// Summary in milliseconds.
    pub fn stats(&self) -> LatencyStats {
        if self.n == 0 {
            return LatencyStats::default();
        }
        LatencyStats {
            mean_ms: self.sum_s / self.n as f64 * 1e3,
            p50_ms: self.quantile(0.5) * 1e3,
            p95_ms: self.quantile(0.95) * 1e3,
            max_ms: self.max_s * 1e3,
        }
    }

    /// Heap bytes held.
    #[cfg(test)]
    fn heap_bytes(&self) -> usize {
        self.counts.capacity() * std::mem::size_of::<u64>()
    }
}

/// Summary statistics of a set of durations, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LatencyStats {
    /// Mean.
    pub mean_ms: f64,
    /// Median (within 1 %).
    pub p50_ms: f64,
    /// 95th percentile (within 1 %).
    pub p95_ms: f64,
    /// Maximum.
    pub max_ms: f64,
}

/// What one node did.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct NodeReport {
    /// Node id.
    pub node: String,
    /// Operator.
    pub op: String,
    /// Frames processed (for sources: produced).
    pub frames: u64,
    /// Frames skipped because a required input was absent (or the node is disabled).
    pub skipped: u64,
    /// Frames handled (processed or skipped) per second, from the first to the last: the
    /// rate `dynaflow top` shows.
    #[serde(default)]
    pub rate_hz: f64,
    /// Processing latency per frame.
    pub latency: LatencyStats,
    /// Processing latency over the first and over the last [`ENDS_FRAMES`] frames (runs of at
    /// least twice that).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency_ends: Option<EndsStats>,
    /// Time since the source emitted the frame, when this node finished it.
    pub age: LatencyStats,
    /// Total time inside the operator, seconds.
    pub busy_s: f64,
    /// Largest queue depth over the node's inputs.
    pub max_queue: usize,
    /// Messages dropped on the node's inputs.
    pub dropped: u64,
    /// Parameters changed while running (`run --set-at`), in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parameter_changes: Vec<ParameterChange>,
    /// What the operator reported (e.g. a tracker's ATE), if anything.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub report: Option<serde_json::Value>,
}

/// What one edge did.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct EdgeReport {
    /// `producer.port -> consumer/port`.
    pub edge: String,
    /// Counters.
    #[serde(flatten)]
    pub stats: EdgeStats,
}

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
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
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Failure {
    /// Node id, or `sink:<name>`.
    pub node: String,
    /// The error, including panics.
    pub error: String,
}

/// Everything measured in a run; written as `<out>/<name>.summary.json`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct RunReport {
    /// Graph name.
    pub graph: String,
    /// Variant.
    pub variant: Option<String>,
    /// `Some` for an oracle run: the decisions that read ground truth. Its results measure a
    /// bound, not a system.
    pub oracle: Option<Vec<String>>,
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
    /// Per recorder (by name): file size, bytes and drops per port.
    pub recorders: std::collections::BTreeMap<String, crate::sink::SinkReport>,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_quantiles_are_within_one_percent_of_exact_ones() {
        let mut h = Histogram::default();
        // 10 000 durations spread over four decades (20 µs .. 200 ms), in a scrambled order.
        let mut exact: Vec<f64> = Vec::new();
        for i in 0..10_000u64 {
            let j = (i * 7919) % 10_000;
            let d = Duration::from_secs_f64(20e-6 * 10f64.powf(4.0 * j as f64 / 10_000.0));
            exact.push(d.as_secs_f64());
            h.record(d);
        }
        exact.sort_by(f64::total_cmp);
        let nearest_rank = |q: f64| exact[((exact.len() as f64 * q).ceil() as usize).clamp(1, exact.len()) - 1];
        let stats = h.stats();
        for (got_ms, q) in [(stats.p50_ms, 0.5), (stats.p95_ms, 0.95)] {
            let want_ms = nearest_rank(q) * 1e3;
            assert!((got_ms - want_ms).abs() <= 0.0101 * want_ms, "q{q}: {got_ms} vs {want_ms}");
        }
        assert!((stats.max_ms - exact[exact.len() - 1] * 1e3).abs() < 1e-9);
        let mean = exact.iter().sum::<f64>() / exact.len() as f64;
        assert!((stats.mean_ms - mean * 1e3).abs() < 1e-9 * mean * 1e3 + 1e-12);
    }

    #[test]
    fn latency_ends_are_the_first_and_last_windows() {
        let mut e = LatencyEnds::default();
        let n = 2 * ENDS_FRAMES + 500;
        for i in 0..n {
            // 1 ms for the first window, 2 ms after, 5 ms for the last window.
            let ms = if i < ENDS_FRAMES {
                1.0
            } else if i + ENDS_FRAMES < n {
                2.0
            } else {
                5.0
            };
            e.record(Duration::from_secs_f64(ms * 1e-3));
        }
        let r = e.report(n as u64).unwrap();
        assert!((r.first.p95_ms - 1.0).abs() < 0.011 && (r.first.max_ms - 1.0).abs() < 1e-6, "{r:?}");
        assert!((r.last.p50_ms - 5.0).abs() < 0.051 && (r.last.mean_ms - 5.0).abs() < 1e-3, "{r:?}");
        assert!(LatencyEnds::default().report(2 * ENDS_FRAMES as u64 - 1).is_none());
        assert_eq!(e.last.len(), ENDS_FRAMES);
    }

    #[test]
    fn histogram_memory_does_not_grow_with_the_number_of_samples() {
        let mut h = Histogram::default();
        for i in 0..100_000u64 {
            h.record(Duration::from_micros(100 + i % 50));
        }
        let after_100k = h.heap_bytes();
        for i in 0..2_000_000u64 {
            h.record(Duration::from_micros(100 + i % 50));
        }
        assert_eq!(h.heap_bytes(), after_100k);
        // Even a day-long frame needs only a few thousand buckets.
        h.record(Duration::from_secs(86_400));
        assert!(h.heap_bytes() < 32 * 1024, "{}", h.heap_bytes());
    }
}
