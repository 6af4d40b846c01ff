//! `dynaflow compare`: several recorded runs (an ablation: "semantic only", "geometric only",
//! both) in one rerun recording laid out for comparison. The rerun viewer cannot
//! sync timelines across recordings nor keep a layout per recording, so the runs go into one:
//! each under `/runs/<name>/` on one shared `frame` timeline.
//!
//! - `/runs/<name>/camera`: the run's camera image, with `/runs/<name>/camera/labels`, the
//!   points tracking decided with, red where dynamic and green where static (the rule and its
//!   measure on hover): one 2-D view per run, in a grid.
//! - `/runs/<name>/world/path` and `/ground_truth/path`: every run's trajectory and the
//!   ground truth in one 3-D view.
//! - `/metrics/ate/<name>` (position error per frame after the run's best rigid alignment to
//!   the ground truth, metres) and `/metrics/dynamic/<name>` (points labelled dynamic per
//!   frame), each metric one plot of all runs.
//! - `/parting`: the frame where each run first parts from the first one (`dynaflow diff`'s
//!   first divergence on the labels and poses), as a text log on the timeline.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use rerun::blueprint::{
    Blueprint, BlueprintActivation, ContainerLike, Grid, Horizontal, Spatial2DView, Spatial3DView, TextLogView,
    TimeSeriesView, Vertical,
};
use serde_json::Value;

use super::{Error, Recording, metrics, read_mcap_bytes};

/// One run to compare: its name and what was read of its MCAP file.
#[derive(Debug)]
pub struct Run {
    /// Name in the comparison (`/runs/<name>`).
    pub name: String,
    /// The recording.
    pub rec: Recording,
    /// The camera topic's images: frame -> (file bytes, `jpeg`/`png`).
    images: BTreeMap<u64, (Vec<u8>, String)>,
}

/// What `compare` found per run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunSummary {
    /// Name.
    pub name: String,
    /// File.
    pub path: PathBuf,
    /// The pose topic compared with the ground truth.
    pub pose: String,
    /// The point-labels topic drawn on the camera.
    pub labels: Option<String>,
    /// Frames with a pose.
    pub frames: usize,
    /// ATE RMSE after rigid alignment, metres (against the ground truth of the same frames).
    pub ate_rmse_m: Option<f64>,
    /// Mean dynamic points per frame.
    pub dynamic_mean: Option<f64>,
    /// Whether the run decided with ground truth (an oracle: a bound, not a result).
    pub oracle: bool,
    /// First `(frame, topic)` where this run parts from the first (none for the first).
    pub parts_at: Option<(u64, String)>,
}

/// Read `path` as a run named `name`.
pub fn read_run(name: &str, path: &Path) -> Result<Run, Error> {
    let bad = |message: String| Error::BadInput { path: path.to_path_buf(), message };
    if path.extension().is_some_and(|e| e == "rrd") {
        return Err(bad(
            "`dynaflow compare` reads MCAP recordings; give the `.mcap` written next to this `.rrd`".into()
        ));
    }
    let buf = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    let rec = read_mcap_bytes(path, &buf)?;
    if rec.topics.is_empty() {
        return Err(bad("no recorded message: nothing to compare".into()));
    }
    // The camera: a source's colour image (`…/rgb`, `…/left`), else the first colour image.
    let colour: Vec<&String> =
        rec.topics.iter().filter(|(_, t)| t.schema == "foxglove.CompressedImage").map(|(n, _)| n).collect();
    let camera = crate::rrd::camera_of(&colour).map(|s| (*s).clone());
    let mut images = BTreeMap::new();
    if let Some(cam) = &camera {
        use crate::mcap::scan::{Event, scan};
        scan(&buf, |event| {
            if let Event::Message { channel, header, data, .. } = event
                && &channel.topic == cam
            {
                let img = crate::mcap::proto::read_image(data, false)?;
                let seq = serde_json::from_slice::<Value>(img.payload)
                    .ok()
                    .and_then(|p| p.get("seq").and_then(Value::as_u64))
                    .unwrap_or(u64::from(header.sequence));
                images.insert(seq, (img.data.to_vec(), img.format.to_owned()));
            }
            Ok(())
        })
        .map_err(bad)?;
    }
    Ok(Run { name: name.to_owned(), rec, images })
}

fn topics_of(rec: &Recording, ty: &str) -> Vec<String> {
    rec.topics.iter().filter(|(_, t)| t.ty == ty).map(|(n, _)| n.clone()).collect()
}

/// The tracker's pose topic and the ground truth's.
fn pose_topics(rec: &Recording) -> (Option<String>, Option<String>) {
    let gt: Vec<String> = rec
        .metadata
        .get("ground_truth_topics")
        .map(|s| s.split(',').filter(|t| !t.is_empty()).map(str::to_owned).collect())
        .unwrap_or_default();
    let poses = topics_of(rec, "pose");
    let truth = poses.iter().find(|p| gt.contains(p)).or(poses.iter().find(|p| p.ends_with("gt_pose"))).cloned();
    let est = poses
        .iter()
        .find(|p| Some(*p) != truth.as_ref() && p.ends_with("/pose"))
        .or(poses.iter().find(|p| Some(*p) != truth.as_ref()))
        .cloned();
    (est, truth)
}

/// The labels tracking decided with (`decisions` in the provenance), else `…/combined/labels`,
/// else the first point-labels topic.
fn labels_topic(rec: &Recording) -> Option<String> {
    let all = topics_of(rec, "point_labels");
    let declared =
        rec.metadata.get("decisions").and_then(|d| d.split(',').map(|p| format!("/{p}")).find(|p| all.contains(p)));
    declared.or_else(|| all.iter().find(|t| t.ends_with("/combined/labels")).cloned()).or_else(|| all.first().cloned())
}

fn position(v: &Value) -> Option<Vector3<f64>> {
    let t = v.get("data")?.get("t")?.as_array()?;
    Some(Vector3::new(t.first()?.as_f64()?, t.get(1)?.as_f64()?, t.get(2)?.as_f64()?))
}

/// Per-frame position errors of `est` against `gt` on their common frames after the best
/// rigid alignment (as the ATE: [`metrics::rigid_alignment`]), with the frames.
fn aligned_errors(est: &BTreeMap<u64, Vector3<f64>>, gt: &BTreeMap<u64, Vector3<f64>>) -> Vec<(u64, f64)> {
    let common: Vec<(u64, Vector3<f64>, Vector3<f64>)> =
        est.iter().filter_map(|(k, p)| gt.get(k).map(|q| (*k, *p, *q))).collect();
    if common.len() < 3 {
        return Vec::new();
    }
    let (g, e): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) = common.iter().map(|c| (c.2, c.1)).unzip();
    let Some((r, t)) = metrics::rigid_alignment(&g, &e) else { return Vec::new() };
    common.iter().map(|(k, e, g)| (*k, (r * e + t - g).norm())).collect()
}

/// The first frame where `b`'s decisions (its labels) or its pose differ from `a`'s (content
/// digests; a frame one run has and the other lacks counts), with the topic. Timing and other
/// measurement ports are left out: they differ between any two runs.
fn parting(a: &Recording, b: &Recording) -> Option<(u64, String)> {
    let topics: Vec<String> = [labels_topic(a), pose_topics(a).0].into_iter().flatten().collect();
    let mut first: Option<(u64, String)> = None;
    for t in topics {
        let (Some(ta), Some(tb)) = (a.topics.get(&t), b.topics.get(&t)) else { continue };
        let frames: std::collections::BTreeSet<u64> = ta.frames.keys().chain(tb.frames.keys()).copied().collect();
        let differs = frames.into_iter().find(|k| match (ta.frames.get(k), tb.frames.get(k)) {
            (Some(x), Some(y)) => x.get("digest") != y.get("digest"),
            _ => true,
        });
        if let Some(k) = differs
            && first.as_ref().is_none_or(|(f, _)| k < *f)
        {
            first = Some((k, t));
        }
    }
    first
}

/// Refuse runs that cannot be laid side by side: two of one name, or runs of different
/// graphs whose ports differ (named, with the topics only one of them has).
fn check(runs: &[Run]) -> Result<(), Error> {
    let first = runs.first().ok_or_else(|| Error::Overlay("no runs to compare".into()))?;
    if runs.len() < 2 {
        return Err(Error::Overlay("give at least two runs to compare".into()));
    }
    for (i, r) in runs.iter().enumerate() {
        if let Some(o) = runs[..i].iter().find(|o| o.name == r.name) {
            return Err(Error::Overlay(format!(
                "two runs are named `{}` ({} and {}): give distinct --names",
                r.name,
                o.rec.path.display(),
                r.rec.path.display()
            )));
        }
        if !r.name.chars().all(|c| c.is_ascii_alphanumeric() || "_-+.".contains(c)) || r.name.is_empty() {
            return Err(Error::Overlay(format!("run name `{}`: use letters, digits, `_`, `-`, `+` and `.`", r.name)));
        }
        let graph = |x: &Run| x.rec.metadata.get("graph").cloned().unwrap_or_default();
        let topics = |x: &Run| x.rec.topics.keys().cloned().collect::<std::collections::BTreeSet<_>>();
        if graph(r) != graph(first) && topics(r) != topics(first) {
            let only: Vec<String> = topics(r).symmetric_difference(&topics(first)).take(6).cloned().collect();
            return Err(Error::BadInput {
                path: r.rec.path.clone(),
                message: format!(
                    "a run of graph `{}` whose ports differ from {}'s (graph `{}`): {} ...; compare runs of one graph (its variants), or of graphs with the same ports",
                    graph(r),
                    first.rec.path.display(),
                    graph(first),
                    only.join(", ")
                ),
            });
        }
        if pose_topics(&r.rec).0.is_none() {
            return Err(Error::BadInput {
                path: r.rec.path.clone(),
                message: "no pose topic: no trajectory to compare".into(),
            });
        }
    }
    Ok(())
}

fn blueprint(runs: &[Run]) -> Blueprint {
    let cells: Vec<ContainerLike> = runs
        .iter()
        .map(|r| {
            let oracle = if r.rec.is_oracle() { " (oracle)" } else { "" };
            Spatial2DView::new(format!("{}{oracle}: dynamic (red) / static (green)", r.name))
                .with_origin(format!("/runs/{}/camera", r.name))
                .into()
        })
        .collect();
    let right: Vec<ContainerLike> = vec![
        Spatial3DView::new("trajectories and ground truth (white)")
            .with_origin("/")
            .with_contents(["/runs/*/world/**", "/ground_truth/**"])
            .into(),
        TimeSeriesView::new("position error per frame, aligned (m)").with_origin("/metrics/ate").into(),
        TimeSeriesView::new("dynamic points per frame").with_origin("/metrics/dynamic").into(),
        TextLogView::new("where the runs part").with_origin("/parting").into(),
    ];
    Blueprint::new(
        Horizontal::new([Grid::new(cells).into(), Vertical::new(right).into()]).with_column_shares([3.0, 2.0]),
    )
}

/// Distinct colours for the runs' trajectories and plots.
fn run_color(i: usize) -> rerun::Color {
    const C: [[u8; 3]; 6] =
        [[31, 119, 180], [255, 127, 14], [44, 160, 44], [148, 103, 189], [214, 39, 40], [140, 86, 75]];
    let [r, g, b] = C[i % C.len()];
    rerun::Color::from_rgb(r, g, b)
}

/// Write the comparison of `runs` (the first is the reference the others part from) to `out`.
pub fn write_compare(runs: &[Run], out: &Path) -> Result<Vec<RunSummary>, Error> {
    // Written beside `out` under a temporary name and renamed into place: a reader never
    // sees half a recording, and a symlink at `out` is replaced, not followed.
    dynaflow_engine::files::write_renamed_into_place(
        out,
        |tmp| write_compare_at(runs, tmp, out),
        |e| Error::Overlay(format!("{}: {e}", out.display())),
    )
}

/// [`write_compare`] into the file `path`; `out` names the recording in errors.
fn write_compare_at(runs: &[Run], path: &Path, out: &Path) -> Result<Vec<RunSummary>, Error> {
    check(runs)?;
    let err = |e: &dyn std::fmt::Display| Error::Overlay(format!("{}: {e}", out.display()));
    let rec = rerun::RecordingStreamBuilder::new("dynaflow-compare").save(path).map_err(|e| err(&e))?;
    rec.set_log_time_enabled(false);
    blueprint(runs).send(&rec, BlueprintActivation { make_active: true, make_default: true }).map_err(|e| err(&e))?;
    let (_, gt_topic) = pose_topics(&runs[0].rec);
    let positions = |r: &Recording, topic: &str| -> BTreeMap<u64, Vector3<f64>> {
        r.topics
            .get(topic)
            .map(|t| t.frames.iter().filter_map(|(k, v)| Some((*k, position(v)?))).collect())
            .unwrap_or_default()
    };
    let gt = gt_topic.as_deref().map(|t| positions(&runs[0].rec, t)).unwrap_or_default();
    if !gt.is_empty() {
        let path: Vec<[f32; 3]> = gt.values().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
        rec.log_static(
            "ground_truth/path",
            &rerun::LineStrips3D::new([path]).with_colors([rerun::Color::from_rgb(240, 240, 240)]),
        )
        .map_err(|e| err(&e))?;
    }
    let mut summaries = Vec::new();
    for (i, run) in runs.iter().enumerate() {
        let color = run_color(i);
        let base = format!("runs/{}", run.name);
        let (pose_topic, _) = pose_topics(&run.rec);
        let pose_topic = pose_topic.unwrap_or_default();
        let est = positions(&run.rec, &pose_topic);
        let path: Vec<[f32; 3]> = est.values().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
        rec.log_static(format!("{base}/world/path"), &rerun::LineStrips3D::new([path]).with_colors([color]))
            .map_err(|e| err(&e))?;
        rec.log_static(
            format!("metrics/ate/{}", run.name),
            &rerun::SeriesLines::new().with_names([run.name.clone()]).with_colors([color]),
        )
        .map_err(|e| err(&e))?;
        rec.log_static(
            format!("metrics/dynamic/{}", run.name),
            &rerun::SeriesLines::new().with_names([run.name.clone()]).with_colors([color]),
        )
        .map_err(|e| err(&e))?;
        for (k, (bytes, format)) in &run.images {
            rec.set_time_sequence("frame", *k as i64);
            let media = if format == "png" { rerun::MediaType::png() } else { rerun::MediaType::jpeg() };
            rec.log(
                format!("{base}/camera"),
                &rerun::EncodedImage::from_file_contents(bytes.clone()).with_media_type(media),
            )
            .map_err(|e| err(&e))?;
        }
        let labels = labels_topic(&run.rec);
        let mut dynamic_counts = Vec::new();
        if let Some(t) = labels.as_ref().and_then(|l| run.rec.topics.get(l)) {
            for (k, v) in &t.frames {
                let d = &v["data"];
                let flags: Vec<bool> = d["dynamic"]
                    .as_array()
                    .map(|a| a.iter().map(|b| b.as_bool().unwrap_or(false)).collect())
                    .unwrap_or_default();
                let at = d["at"].as_array().cloned().unwrap_or_default();
                let reasons = d["reason"].as_array().cloned().unwrap_or_default();
                let scores = d["score"].as_array().cloned().unwrap_or_default();
                let points = flags.iter().enumerate().filter_map(|(j, dynamic)| {
                    let p = at.get(j)?;
                    let (x, y) = (p[0].as_f64()?, p[1].as_f64()?);
                    let reason = reasons.get(j).and_then(Value::as_str).unwrap_or("?");
                    let score = scores.get(j).and_then(Value::as_f64).unwrap_or(f64::NAN);
                    Some(([x as f32, y as f32], *dynamic, format!("{reason} {score:.2}")))
                });
                let count = flags.iter().filter(|d| **d).count();
                dynamic_counts.push(count as f64);
                rec.set_time_sequence("frame", *k as i64);
                rec.log(format!("{base}/camera/labels"), &crate::rrd::label_points(points)).map_err(|e| err(&e))?;
                rec.log(format!("metrics/dynamic/{}", run.name), &rerun::Scalars::new([count as f64]))
                    .map_err(|e| err(&e))?;
            }
        }
        let errors = aligned_errors(&est, &gt);
        for (k, e) in &errors {
            rec.set_time_sequence("frame", *k as i64);
            rec.log(format!("metrics/ate/{}", run.name), &rerun::Scalars::new([*e])).map_err(|e| err(&e))?;
        }
        let parts_at = if i == 0 { None } else { parting(&runs[0].rec, &run.rec) };
        if let Some((frame, topic)) = &parts_at {
            rec.set_time_sequence("frame", *frame as i64);
            rec.log(
                "parting",
                &rerun::TextLog::new(format!(
                    "`{}` parts from `{}` at frame {frame}, first on {topic}",
                    run.name, runs[0].name
                )),
            )
            .map_err(|e| err(&e))?;
        }
        let ate =
            (!errors.is_empty()).then(|| (errors.iter().map(|(_, e)| e * e).sum::<f64>() / errors.len() as f64).sqrt());
        summaries.push(RunSummary {
            name: run.name.clone(),
            path: run.rec.path.clone(),
            pose: pose_topic,
            labels,
            frames: est.len(),
            ate_rmse_m: ate,
            dynamic_mean: (!dynamic_counts.is_empty())
                .then(|| dynamic_counts.iter().sum::<f64>() / dynamic_counts.len() as f64),
            oracle: run.rec.is_oracle(),
            parts_at,
        });
    }
    rec.flush_blocking().map_err(|e| err(&e))?;
    drop(rec);
    Ok(summaries)
}
