//! One rerun recording holding both runs (`/a/…`, `/b/…`) and per-frame differences
//! (`/diff/<topic>/<metric>`), so a user scrubs to where the runs part.

use std::path::Path;

use rerun::blueprint::{
    Blueprint, BlueprintActivation, ContainerLike, Horizontal, Spatial2DView, Spatial3DView, TimeSeriesView, Vertical,
};
use serde_json::Value;

use super::{Error, Recording, metrics};

fn xy(v: &Value) -> Vec<[f32; 2]> {
    v.as_array()
        .map(|a| a.iter().map(|p| [p[0].as_f64().unwrap_or(0.0) as f32, p[1].as_f64().unwrap_or(0.0) as f32]).collect())
        .unwrap_or_default()
}

fn log_run(
    rec: &rerun::RecordingStream,
    side: &str,
    run: &Recording,
    color: rerun::Color,
) -> Result<(), rerun::RecordingStreamError> {
    for (topic, t) in &run.topics {
        let path = format!("{side}{topic}");
        let mut trail: Vec<[f32; 3]> = Vec::new();
        for (frame, payload) in &t.frames {
            rec.set_time_sequence("frame", *frame as i64);
            let data = &payload["data"];
            match t.ty.as_str() {
                "pose" => {
                    let (p, _) = metrics::pose(data);
                    trail.push([p.x as f32, p.y as f32, p.z as f32]);
                    rec.log(
                        path.clone(),
                        &rerun::Points3D::new([[p.x as f32, p.y as f32, p.z as f32]])
                            .with_colors([color])
                            .with_radii([0.02]),
                    )?;
                }
                "keypoints" => rec
                    .log(path.clone(), &rerun::Points2D::new(xy(&data["xy"])).with_colors([color]).with_radii([2.0]))?,
                "tracks" => {
                    let (prev, cur) = (xy(&data["prev"]), xy(&data["cur"]));
                    let vectors: Vec<[f32; 2]> =
                        prev.iter().zip(&cur).map(|(p, c)| [c[0] - p[0], c[1] - p[1]]).collect();
                    rec.log(
                        path.clone(),
                        &rerun::Arrows2D::from_vectors(vectors).with_origins(prev).with_colors([color]),
                    )?;
                }
                "detections" => {
                    let boxes: Vec<[f32; 4]> = data["bbox"]
                        .as_array()
                        .map(|a| {
                            a.iter().map(|b| std::array::from_fn(|i| b[i].as_f64().unwrap_or(0.0) as f32)).collect()
                        })
                        .unwrap_or_default();
                    let mins: Vec<[f32; 2]> = boxes.iter().map(|b| [b[0], b[1]]).collect();
                    let sizes: Vec<[f32; 2]> = boxes.iter().map(|b| [b[2] - b[0], b[3] - b[1]]).collect();
                    rec.log(path.clone(), &rerun::Boxes2D::from_mins_and_sizes(mins, sizes).with_colors([color]))?;
                }
                "scalars" => {
                    if let Some(obj) = data.as_object() {
                        for (k, v) in obj {
                            if let Some(v) = v.as_f64() {
                                rec.log(format!("{path}/{k}"), &rerun::Scalars::new([v]))?;
                            }
                        }
                    }
                }
                _ => {}
            }
        }
        if !trail.is_empty() {
            rec.log_static(format!("{path}/path"), &rerun::LineStrips3D::new([trail]).with_colors([color]))?;
        }
    }
    Ok(())
}

/// Write the overlay of runs `a` and `b` to `out`.
pub fn write_overlay(a: &Recording, b: &Recording, out: &Path) -> Result<(), Error> {
    // Written beside `out` under a temporary name and renamed into place: a reader never
    // sees half a recording, and a symlink at `out` is replaced, not followed.
    dynaflow_engine::files::write_renamed_into_place(
        out,
        |tmp| write_overlay_at(a, b, tmp, out),
        |e| Error::Overlay(format!("{}: {e}", out.display())),
    )
}

/// [`write_overlay`] into the file `path`; `out` names the recording in errors.
fn write_overlay_at(a: &Recording, b: &Recording, path: &Path, out: &Path) -> Result<(), Error> {
    let err = |e: &dyn std::fmt::Display| Error::Overlay(format!("{}: {e}", out.display()));
    let rec = rerun::RecordingStreamBuilder::new("dynaflow-diff").save(path).map_err(|e| err(&e))?;
    let image_topics: Vec<String> = a
        .topics
        .iter()
        .filter(|(_, t)| matches!(t.ty.as_str(), "keypoints" | "tracks" | "detections"))
        .flat_map(|(name, _)| [format!("/a{name}"), format!("/b{name}")])
        .collect();
    let mut left: Vec<ContainerLike> =
        vec![Spatial3DView::new("poses: A green, B orange").with_origin("/").with_contents(["/a/**", "/b/**"]).into()];
    if !image_topics.is_empty() {
        left.push(Spatial2DView::new("image space").with_origin("/").with_contents(image_topics).into());
    }
    let bp = Blueprint::new(Horizontal::new([
        Vertical::new(left).into(),
        ContainerLike::from(TimeSeriesView::new("differences").with_origin("/diff")),
    ]));
    bp.send(&rec, BlueprintActivation { make_active: true, make_default: true }).map_err(|e| err(&e))?;
    let (green, orange) = (rerun::Color::from_rgb(40, 200, 60), rerun::Color::from_rgb(255, 140, 0));
    log_run(&rec, "a", a, green).map_err(|e| err(&e))?;
    log_run(&rec, "b", b, orange).map_err(|e| err(&e))?;
    for (topic, ta) in &a.topics {
        let Some(tb) = b.topics.get(topic) else { continue };
        for (frame, pa) in &ta.frames {
            let Some(pb) = tb.frames.get(frame) else { continue };
            rec.set_time_sequence("frame", *frame as i64);
            let differs = f64::from(u8::from(pa["digest"] != pb["digest"]));
            rec.log(format!("diff{topic}/changed"), &rerun::Scalars::new([differs])).map_err(|e| err(&e))?;
            for (metric, v) in metrics::compare(&ta.ty, &pa["data"], &pb["data"]) {
                if v.is_finite() {
                    rec.log(format!("diff{topic}/{metric}"), &rerun::Scalars::new([v])).map_err(|e| err(&e))?;
                }
            }
        }
    }
    rec.flush_blocking().map_err(|e| err(&e))?;
    drop(rec);
    Ok(())
}
