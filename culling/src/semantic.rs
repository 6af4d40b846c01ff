//! Semantic rules: masks (DynaSLAM, MG-SLAM), YG-SLAM's class prior over boxes, boxes from
//! instance masks and depth, and labels carried from tracks to nearby points.

use super::*;

/// DynaSLAM / MG-SLAM masks: dynamic where the point lies on a pixel of a dynamic class.
/// `dynamic_at(x, y)` answers for a pixel.
pub fn mask_rule(points: &[[f32; 2]], dynamic_at: impl Fn(usize, usize) -> bool) -> Vec<Decision> {
    points
        .iter()
        .map(|p| {
            let on = p[0] >= 0.0 && p[1] >= 0.0 && dynamic_at(p[0].round() as usize, p[1].round() as usize);
            if on {
                Decision { dynamic: true, reason: LabelReason::Semantic, score: 1.0 }
            } else {
                Decision::keep(LabelReason::Static, 0.0)
            }
        })
        .collect()
}

/// A label per point from labelled tracks: each point whose nearest labelled track lies within
/// `radius` px (or exactly on it, for radius 0) is marked dynamic when that track is; a point
/// already dynamic stays so (a mask's verdict is never undone by a static track). This is how a
/// tracker's keypoints take the culling labels of the optical-flow tracks beside them, as a
/// segment would speak for its pixels. Tracks are bucketed in a grid of `radius`-sized cells,
/// so only nine cells are searched; ties keep the first found (deterministic).
pub fn nearest_track_labels(labelled: &[([f32; 2], bool)], points: &[[f32; 2]], radius: f32, dynamic: &mut [bool]) {
    if labelled.is_empty() || !labelled.iter().any(|l| l.1) {
        return;
    }
    let cell = radius.max(1.0);
    let key = |p: [f32; 2]| ((p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = std::collections::HashMap::new();
    for (i, (p, _)) in labelled.iter().enumerate() {
        if p[0].is_finite() && p[1].is_finite() {
            grid.entry(key(*p)).or_default().push(i);
        }
    }
    let r2 = radius * radius;
    for (d, p) in dynamic.iter_mut().zip(points) {
        let (cx, cy) = key(*p);
        let mut best: Option<(f32, usize)> = None;
        for gy in cy - 1..=cy + 1 {
            for gx in cx - 1..=cx + 1 {
                for &i in grid.get(&(gx, gy)).map_or(&[][..], Vec::as_slice) {
                    let q = labelled[i].0;
                    let d2 = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
                    if d2 <= r2 && best.is_none_or(|(b, _)| d2 < b) {
                        best = Some((d2, i));
                    }
                }
            }
        }
        if let Some((_, i)) = best {
            *d |= labelled[i].1;
        }
    }
}

/// YG-SLAM's dynamic values per COCO class (as the vendored detectors name them: `tvmonitor`,
/// `diningtable`); unlisted classes are 0 (static).
pub const DEFAULT_DYNAMIC_VALUES: &[(&str, f32)] = &[
    ("person", 1.0),
    ("cup", 0.7),
    ("cell phone", 0.7),
    ("keyboard", 0.7),
    ("mouse", 0.7),
    ("chair", 0.6),
    ("tvmonitor", 0.5),
    ("diningtable", 0.2),
    ("book", 0.1),
];

/// YG-SLAM's semantic prior. A point takes the largest dynamic value m of the boxes holding
/// it: m > 0.8 is dynamic; 0.4 < m <= 0.8 dynamic only on key frames; m <= 0.4 static. A point
/// that also lies in a static object's box (m <= 0.4) is kept: the static object is in front.
pub fn semantic_prior(
    points: &[[f32; 2]],
    boxes: &[LabelledBox],
    value_of: impl Fn(&str) -> f32,
    key_frame: bool,
) -> Vec<Decision> {
    let values: Vec<f32> = boxes.iter().map(|b| value_of(&b.label)).collect();
    points
        .iter()
        .map(|&p| {
            let holding: Vec<f32> =
                boxes.iter().zip(&values).filter(|(b, _)| inside(&b.bbox, p)).map(|(_, v)| *v).collect();
            let m = holding.iter().copied().fold(0.0f32, f32::max);
            let in_static_box = holding.iter().any(|&v| v <= 0.4);
            let dynamic = !in_static_box && (m > 0.8 || (m > 0.4 && key_frame));
            Decision { dynamic, reason: if dynamic { LabelReason::Semantic } else { LabelReason::Static }, score: m }
        })
        .collect()
}

/// One box per instance of an instance mask (`instances`, 0 = none) with its class (from
/// `classes`, 0 = background, skipped), in instance order; instances under `min_pixels` pixels
/// are left out. What `oracle_boxes` reports.
pub fn instance_boxes(instances: &[u16], classes: &[u16], width: usize, min_pixels: u64) -> Vec<([f32; 4], u16)> {
    let w = width.max(1);
    // Per instance: bounding box, pixel count, class.
    let mut found: std::collections::BTreeMap<u16, ([usize; 4], u64, u16)> = std::collections::BTreeMap::new();
    for (i, (&inst, &class)) in instances.iter().zip(classes).enumerate() {
        if inst == 0 || class == 0 {
            continue;
        }
        let (x, y) = (i % w, i / w);
        let e = found.entry(inst).or_insert(([x, y, x, y], 0, class));
        e.0 = [e.0[0].min(x), e.0[1].min(y), e.0[2].max(x), e.0[3].max(y)];
        e.1 += 1;
    }
    found.into_values().filter(|(_, n, _)| *n >= min_pixels).map(|(b, _, class)| (b.map(|v| v as f32), class)).collect()
}

/// Whether each point lies inside any box.
pub fn in_any_box(points: &[[f32; 2]], boxes: &[LabelledBox]) -> Vec<bool> {
    points.iter().map(|&p| boxes.iter().any(|b| inside(&b.bbox, p))).collect()
}

/// Per pixel of a `width x height` depth image: the index + 1 of the box whose object it
/// belongs to, 0 for none. A box's object is its dominant foreground depth: the depths
/// inside it histogrammed in `bin` metre bins, the nearest bin holding at least half as many
/// pixels as the fullest one (a person in front of a wall: the person, not the wall behind);
/// pixels within `tolerance` metres of that depth are the object's. Pixels without depth
/// stay 0. Later boxes overwrite earlier ones where they overlap (callers pass boxes in
/// ascending score, so the best box wins).
pub fn box_depth_mask(
    boxes: &[[f32; 4]],
    depth: &[f32],
    width: usize,
    height: usize,
    bin: f32,
    tolerance: f32,
) -> Vec<u16> {
    let mut mask = vec![0u16; width * height];
    if depth.len() < width * height || bin <= 0.0 || bin.is_nan() {
        return mask;
    }
    for (k, b) in boxes.iter().enumerate() {
        let x0 = (b[0].max(0.0) as usize).min(width);
        let y0 = (b[1].max(0.0) as usize).min(height);
        let x1 = (b[2].max(0.0).ceil() as usize).min(width);
        let y1 = (b[3].max(0.0).ceil() as usize).min(height);
        let mut hist: Vec<u32> = Vec::new();
        for y in y0..y1 {
            for &d in &depth[y * width + x0..y * width + x1] {
                if d > 0.0 && d.is_finite() {
                    let i = (d / bin) as usize;
                    if i < 4096 {
                        if hist.len() <= i {
                            hist.resize(i + 1, 0);
                        }
                        hist[i] += 1;
                    }
                }
            }
        }
        let Some(&top) = hist.iter().max() else { continue };
        if top == 0 {
            continue;
        }
        let Some(front) = hist.iter().position(|&c| 2 * c >= top) else { continue };
        let centre = (front as f32 + 0.5) * bin;
        let id = u16::try_from(k + 1).unwrap_or(u16::MAX);
        for y in y0..y1 {
            for x in x0..x1 {
                let d = depth[y * width + x];
                if d > 0.0 && (d - centre).abs() <= tolerance {
                    mask[y * width + x] = id;
                }
            }
        }
    }
    mask
}
