//! `dynaflow diff A B`: where and when two recorded runs part.
//!
//! Both runs are read from their MCAP recordings (`read`), aligned by topic and frame, and
//! compared message by message (`metrics`): exactly by content digest, or numerically within
//! a tolerance given with `--tol PATTERN[:METRIC]=VALUE`. `overlay` writes both runs and the
//! per-frame differences into one rerun recording.
//!
//! A frame of a topic *differs* when it exists in only one run, or its digests differ and
//! either no tolerance matches the topic or one of its metrics exceeds the tolerance. A
//! tolerance on a topic without numeric metrics (images, depth, masks) ignores it.

pub mod compare;
mod metrics;
mod overlay;
mod read;

use std::collections::BTreeMap;
use std::path::PathBuf;

use nalgebra::Vector3;
use serde::Serialize;

pub use overlay::write_overlay;
pub use read::{Recording, Topic, read_mcap, read_mcap_bytes};

pub use crate::Error;

/// One `--tol` entry.
#[derive(Clone, Debug, PartialEq)]
pub struct Tolerance {
    /// Glob over topic names (`*` any run of characters, `?` one).
    pub pattern: String,
    /// Metric it applies to (all metrics if `None`).
    pub metric: Option<String>,
    /// Largest allowed value.
    pub value: f64,
}

impl std::str::FromStr for Tolerance {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self, Error> {
        let (lhs, value) = s.rsplit_once('=').ok_or_else(|| Error::BadTolerance(s.to_owned()))?;
        let value: f64 = value.trim().parse().map_err(|_| Error::BadTolerance(s.to_owned()))?;
        if value.is_nan() || value < 0.0 {
            return Err(Error::BadTolerance(s.to_owned()));
        }
        let (pattern, metric) = match lhs.rsplit_once(':') {
            Some((p, m)) if !m.contains('/') && !m.contains('*') => (p.to_owned(), Some(m.to_owned())),
            _ => (lhs.to_owned(), None),
        };
        if pattern.is_empty() {
            return Err(Error::BadTolerance(s.to_owned()));
        }
        Ok(Self { pattern, metric, value })
    }
}

/// Glob match: `*` matches any run (including `/`), `?` one character.
pub fn glob(pattern: &str, text: &str) -> bool {
    let (p, t): (Vec<char>, Vec<char>) = (pattern.chars().collect(), text.chars().collect());
    let (mut pi, mut ti, mut star, mut mark) = (0, 0, None, 0);
    while ti < t.len() {
        match p.get(pi) {
            Some('*') => {
                star = Some(pi);
                mark = ti;
                pi += 1;
            }
            Some(c) if *c == '?' || Some(c) == t.get(ti) => {
                pi += 1;
                ti += 1;
            }
            _ => match star {
                Some(s) => {
                    pi = s + 1;
                    mark += 1;
                    ti = mark;
                }
                None => return false,
            },
        }
    }
    p.get(pi..).is_some_and(|rest| rest.iter().all(|c| *c == '*'))
}

/// The comparison of one topic.
#[derive(Clone, Debug, Serialize)]
pub struct TopicDiff {
    /// Topic `/<node>/<port>`.
    pub topic: String,
    /// Port type.
    #[serde(rename = "type")]
    pub ty: String,
    /// Messages in A.
    pub count_a: usize,
    /// Messages in B.
    pub count_b: usize,
    /// Frames whose digests differ (before tolerances).
    pub frames_changed: usize,
    /// Frames that differ after tolerances.
    pub frames_differing: usize,
    /// First differing frame.
    pub first_diff_frame: Option<u64>,
    /// Why that frame differs.
    pub first_diff_reason: Option<String>,
    /// Largest value of each metric over common frames.
    pub max: BTreeMap<String, f64>,
    /// Mean of each metric over common frames.
    pub mean: BTreeMap<String, f64>,
}

/// ATE between the two runs' poses on one topic.
#[derive(Clone, Debug, Serialize)]
pub struct Ate {
    /// Pose topic.
    pub topic: String,
    /// Frames compared.
    pub frames: usize,
    /// RMSE of position differences as recorded, metres.
    pub rmse_m: f64,
    /// RMSE after the best rigid alignment, metres.
    pub aligned_rmse_m: f64,
}

/// The result of `dynaflow diff`.
#[derive(Clone, Debug, Serialize)]
pub struct DiffReport {
    /// Run A.
    pub a: PathBuf,
    /// Run B.
    pub b: PathBuf,
    /// Whether run A is an oracle's (decides with ground truth), from its provenance.
    pub oracle_a: bool,
    /// Whether run B is.
    pub oracle_b: bool,
    /// Whether either file was cut short.
    pub truncated: bool,
    /// Per topic present in both runs.
    pub topics: Vec<TopicDiff>,
    /// Topics recorded only in A.
    pub only_in_a: Vec<String>,
    /// Topics recorded only in B.
    pub only_in_b: Vec<String>,
    /// Trajectory error between the runs per pose topic.
    pub ate: Vec<Ate>,
    /// Earliest `(frame, topic)` where the runs differ.
    pub first_divergence: Option<(u64, String)>,
    /// True when nothing differs beyond tolerance.
    pub same: bool,
    /// Set when the recordings use different content-digest schemes (one made before scheme
    /// 2): frames were compared on their numeric payload only, pixels not at all.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub digests: Option<String>,
}

fn tolerance_for<'a>(tols: &'a [Tolerance], topic: &str) -> Vec<&'a Tolerance> {
    tols.iter().filter(|t| glob(&t.pattern, topic)).collect()
}

fn exceeds(tols: &[&Tolerance], metrics: &BTreeMap<String, f64>) -> Option<String> {
    metrics.iter().find_map(|(name, v)| {
        // The most specific tolerance wins: a metric-specific one over a topic-wide one.
        let limit = tols
            .iter()
            .filter(|t| t.metric.as_deref() == Some(name.as_str()))
            .map(|t| t.value)
            .next()
            .or_else(|| tols.iter().filter(|t| t.metric.is_none()).map(|t| t.value).next())
            .unwrap_or(0.0);
        (*v > limit || v.is_nan()).then(|| format!("{name} = {v:.6} > {limit}"))
    })
}

/// Compare two recordings.
pub fn diff(a: &Recording, b: &Recording, tols: &[Tolerance]) -> DiffReport {
    // Recordings made before digest scheme 2 carry no `digest` metadata (scheme 1); digests of
    // two schemes never match, so frames are then compared on their numeric payload alone.
    let scheme = |r: &Recording| r.metadata.get("digest").cloned().unwrap_or_else(|| "dynaflow-digest-1".into());
    let comparable = scheme(a) == scheme(b);
    let mut topics = Vec::new();
    let mut ate = Vec::new();
    for (name, ta) in &a.topics {
        let Some(tb) = b.topics.get(name) else { continue };
        let tol = tolerance_for(tols, name);
        let mut d = TopicDiff {
            topic: name.clone(),
            ty: ta.ty.clone(),
            count_a: ta.frames.len(),
            count_b: tb.frames.len(),
            frames_changed: 0,
            frames_differing: 0,
            first_diff_frame: None,
            first_diff_reason: None,
            max: BTreeMap::new(),
            mean: BTreeMap::new(),
        };
        let mut sums: BTreeMap<String, (f64, usize)> = BTreeMap::new();
        let frames: std::collections::BTreeSet<u64> = ta.frames.keys().chain(tb.frames.keys()).copied().collect();
        for k in frames {
            let reason = match (ta.frames.get(&k), tb.frames.get(&k)) {
                (Some(pa), Some(pb)) => {
                    let m = metrics::compare(&ta.ty, &pa["data"], &pb["data"]);
                    for (key, v) in &m {
                        let e = sums.entry(key.clone()).or_insert((0.0, 0));
                        e.0 += v;
                        e.1 += 1;
                        let slot = d.max.entry(key.clone()).or_insert(0.0);
                        *slot = slot.max(*v);
                    }
                    let same = if comparable { pa["digest"] == pb["digest"] } else { m.values().all(|v| *v == 0.0) };
                    if same {
                        None
                    } else {
                        d.frames_changed += 1;
                        if tol.is_empty() {
                            Some(match m.iter().find(|(_, v)| **v != 0.0) {
                                Some((key, v)) => format!("content differs ({key} = {v:.6})"),
                                None => "content differs".to_owned(),
                            })
                        } else {
                            exceeds(&tol, &m)
                        }
                    }
                }
                (Some(_), None) => Some("only in A".to_owned()),
                (None, Some(_)) => Some("only in B".to_owned()),
                (None, None) => None,
            };
            if let Some(reason) = reason {
                d.frames_differing += 1;
                if d.first_diff_frame.is_none() {
                    d.first_diff_frame = Some(k);
                    d.first_diff_reason = Some(reason);
                }
            }
        }
        d.mean = sums.into_iter().map(|(k, (s, n))| (k, s / n.max(1) as f64)).collect();
        if ta.ty == "pose" {
            let common: Vec<u64> = ta.frames.keys().filter(|k| tb.frames.contains_key(k)).copied().collect();
            let pos = |t: &Topic| -> Vec<Vector3<f64>> {
                common.iter().filter_map(|k| t.frames.get(k)).map(|p| metrics::pose(&p["data"]).0).collect()
            };
            let (rmse_m, aligned_rmse_m) = metrics::ate(&pos(ta), &pos(tb));
            ate.push(Ate { topic: name.clone(), frames: common.len(), rmse_m, aligned_rmse_m });
        }
        topics.push(d);
    }
    let only_in_a: Vec<String> = a.topics.keys().filter(|t| !b.topics.contains_key(*t)).cloned().collect();
    let only_in_b: Vec<String> = b.topics.keys().filter(|t| !a.topics.contains_key(*t)).cloned().collect();
    let first_divergence = topics.iter().filter_map(|t| t.first_diff_frame.map(|f| (f, t.topic.clone()))).min();
    let same = first_divergence.is_none() && only_in_a.is_empty() && only_in_b.is_empty();
    DiffReport {
        a: a.path.clone(),
        b: b.path.clone(),
        oracle_a: a.is_oracle(),
        oracle_b: b.is_oracle(),
        truncated: a.truncated || b.truncated,
        topics,
        only_in_a,
        only_in_b,
        ate,
        first_divergence,
        same,
        digests: (!comparable).then(|| {
            format!(
                "A and B use different content digests ({} vs {}): frames compared on their numeric payload only; images, depth and masks not compared",
                scheme(a),
                scheme(b)
            )
        }),
    }
}

impl DiffReport {
    /// A human-readable table.
    pub fn table(&self) -> String {
        let mark = |o: bool| if o { " (oracle: decides with ground truth)" } else { "" };
        let mut out = format!(
            "A: {}{}\nB: {}{}\n\n",
            self.a.display(),
            mark(self.oracle_a),
            self.b.display(),
            mark(self.oracle_b)
        );
        out.push_str(&format!(
            "{:<28} {:<12} {:>6} {:>6} {:>8} {:>10}  {}\n",
            "topic", "type", "A", "B", "differ", "first", "largest deltas"
        ));
        for t in &self.topics {
            let deltas: Vec<String> =
                t.max.iter().filter(|(_, v)| **v != 0.0).map(|(k, v)| format!("{k}={v:.4}")).collect();
            out.push_str(&format!(
                "{:<28} {:<12} {:>6} {:>6} {:>8} {:>10}  {}\n",
                t.topic,
                t.ty,
                t.count_a,
                t.count_b,
                t.frames_differing,
                t.first_diff_frame.map_or("-".to_owned(), |f| f.to_string()),
                deltas.join(" ")
            ));
        }
        for t in &self.only_in_a {
            out.push_str(&format!("{t:<28} only in A\n"));
        }
        for t in &self.only_in_b {
            out.push_str(&format!("{t:<28} only in B\n"));
        }
        for a in &self.ate {
            out.push_str(&format!(
                "ATE {}: {:.6} m raw, {:.6} m aligned over {} frames\n",
                a.topic, a.rmse_m, a.aligned_rmse_m, a.frames
            ));
        }
        if self.truncated {
            out.push_str("note: a recording was cut short (killed run); compared up to its last complete chunk\n");
        }
        if let Some(note) = &self.digests {
            out.push_str(&format!("note: {note}\n"));
        }
        match &self.first_divergence {
            None if self.same => out.push_str("identical within tolerance\n"),
            None => out.push_str("the runs recorded different topics\n"),
            Some((frame, topic)) => {
                let reason = self
                    .topics
                    .iter()
                    .find(|t| &t.topic == topic)
                    .and_then(|t| t.first_diff_reason.clone())
                    .unwrap_or_default();
                out.push_str(&format!("first divergence: {topic} at frame {frame} ({reason})\n"));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs() {
        assert!(glob("/orb/*", "/orb/keypoints"));
        assert!(glob("*", "/a/b"));
        assert!(glob("/a/?", "/a/b"));
        assert!(!glob("/orb/*", "/flow/tracks"));
        assert!(glob("*/pose", "/track/pose"));
    }

    #[test]
    fn tolerances_parse() {
        let t: Tolerance = "/track/pose:rotation_deg=0.5".parse().unwrap();
        assert_eq!((t.pattern.as_str(), t.metric.as_deref(), t.value), ("/track/pose", Some("rotation_deg"), 0.5));
        let t: Tolerance = "/orb/*=2".parse().unwrap();
        assert_eq!(t.metric, None);
        assert!("nonsense".parse::<Tolerance>().is_err());
        assert!("/x=-1".parse::<Tolerance>().is_err());
    }
}
