//! Per-type numeric differences between two messages of the same topic and frame.

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;

/// Largest distance for two keypoints to count as the same point, pixels.
const MATCH_RADIUS_PX: f64 = 8.0;
/// Smallest IoU for two detections to count as the same object.
const MATCH_IOU: f64 = 0.3;

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

fn xy(v: &Value) -> Vec<[f64; 2]> {
    v.as_array().map(|a| a.iter().map(|p| [f(&p[0]), f(&p[1])]).collect()).unwrap_or_default()
}

fn arr(v: &Value) -> &[Value] {
    v.as_array().map_or(&[], Vec::as_slice)
}

/// Metrics between payload data `a` and `b` of port type `ty`. Empty for types compared by
/// digest only (images, depth, masks, …).
pub fn compare(ty: &str, a: &Value, b: &Value) -> BTreeMap<String, f64> {
    let mut m = BTreeMap::new();
    match ty {
        "pose" => {
            let (ta, qa) = pose(a);
            let (tb, qb) = pose(b);
            m.insert("translation_m".into(), (ta - tb).norm());
            m.insert("rotation_deg".into(), qa.angle_to(&qb).to_degrees());
        }
        "keypoints" => {
            let (pa, pb) = (xy(&a["xy"]), xy(&b["xy"]));
            m.insert("count".into(), (pa.len() as f64 - pb.len() as f64).abs());
            let (mean, unmatched) = mutual_nn(&pa, &pb);
            m.insert("position_px".into(), mean);
            m.insert("unmatched".into(), unmatched as f64);
        }
        "tracks" => {
            let (ca, cb) = (xy(&a["cur"]), xy(&b["cur"]));
            m.insert("count".into(), (ca.len() as f64 - cb.len() as f64).abs());
            let (mean, unmatched) = mutual_nn(&ca, &cb);
            m.insert("position_px".into(), mean);
            m.insert("unmatched".into(), unmatched as f64);
        }
        "point_labels" => {
            let (ia, da) = (arr(&a["index"]), arr(&a["dynamic"]));
            let (ib, db) = (arr(&b["index"]), arr(&b["dynamic"]));
            let lb: BTreeMap<u64, bool> =
                ib.iter().zip(db).filter_map(|(i, d)| Some((i.as_u64()?, d.as_bool()?))).collect();
            let flipped = ia
                .iter()
                .zip(da)
                .filter(|(i, d)| i.as_u64().and_then(|i| lb.get(&i)).is_some_and(|x| Some(*x) != d.as_bool()))
                .count();
            m.insert("flipped".into(), flipped as f64);
            m.insert("count".into(), (ia.len() as f64 - ib.len() as f64).abs());
        }
        "detections" => {
            let boxes = |v: &Value| -> Vec<([f64; 4], u64)> {
                arr(&v["bbox"])
                    .iter()
                    .zip(arr(&v["class_id"]))
                    .map(|(b, c)| ([f(&b[0]), f(&b[1]), f(&b[2]), f(&b[3])], c.as_u64().unwrap_or(0)))
                    .collect()
            };
            let (ba, bb) = (boxes(a), boxes(b));
            let mut used = vec![false; bb.len()];
            let mut ious = Vec::new();
            for (box_a, class_a) in &ba {
                let best = bb
                    .iter()
                    .enumerate()
                    .filter(|(j, (_, c))| !used[*j] && c == class_a)
                    .map(|(j, (box_b, _))| (j, iou(box_a, box_b)))
                    .max_by(|x, y| x.1.total_cmp(&y.1));
                if let Some((j, v)) = best
                    && v >= MATCH_IOU
                {
                    used[j] = true;
                    ious.push(v);
                }
            }
            m.insert("missing".into(), (ba.len() - ious.len()) as f64);
            m.insert("extra".into(), (bb.len() - ious.len()) as f64);
            let mean = if ious.is_empty() { 1.0 } else { ious.iter().sum::<f64>() / ious.len() as f64 };
            m.insert("iou_loss".into(), 1.0 - mean);
        }
        "scalars" => {
            if let (Some(oa), Some(ob)) = (a.as_object(), b.as_object()) {
                for (k, va) in oa {
                    // Two NaNs (or two equal infinities) are the same value recorded twice.
                    let d = ob.get(k).map_or(f64::INFINITY, |vb| {
                        let (x, y) = (f(va), f(vb));
                        if x == y || (x.is_nan() && y.is_nan()) { 0.0 } else { (x - y).abs() }
                    });
                    m.insert(k.clone(), if d.is_nan() { f64::INFINITY } else { d });
                }
                for k in ob.keys().filter(|k| !oa.contains_key(*k)) {
                    m.insert(k.clone(), f64::INFINITY);
                }
            }
        }
        "trajectory" => {
            let (ta, tb) = (arr(&a["t"]), arr(&b["t"]));
            let worst = ta
                .iter()
                .zip(tb)
                .map(|(p, q)| {
                    (Vector3::new(f(&p[0]), f(&p[1]), f(&p[2])) - Vector3::new(f(&q[0]), f(&q[1]), f(&q[2]))).norm()
                })
                .fold(0.0, f64::max);
            m.insert("translation_m".into(), worst);
            m.insert("count".into(), (ta.len() as f64 - tb.len() as f64).abs());
        }
        _ => {}
    }
    m
}

/// Translation and rotation of a pose payload.
pub fn pose(v: &Value) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let t = Vector3::new(f(&v["t"][0]), f(&v["t"][1]), f(&v["t"][2]));
    let q =
        UnitQuaternion::from_quaternion(Quaternion::new(f(&v["q"][3]), f(&v["q"][0]), f(&v["q"][1]), f(&v["q"][2])));
    (t, q)
}

fn iou(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    let ix = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let iy = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = ix * iy;
    let union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter;
    if union > 0.0 { inter / union } else { 0.0 }
}

/// A one-to-one matching of two point sets within the match radius, nearest pairs first (ties
/// by index, so it is deterministic): the mean distance of the matched pairs, and the number
/// of points of either set left unmatched. Points at one position (a keypoint found on two
/// pyramid levels) each find their own partner, so a set matched with itself leaves none.
fn mutual_nn(a: &[[f64; 2]], b: &[[f64; 2]]) -> (f64, usize) {
    // Candidate pairs from a grid of radius-sized cells: only neighbouring cells are searched.
    let cell = |p: &[f64; 2]| ((p[0] / MATCH_RADIUS_PX).floor() as i64, (p[1] / MATCH_RADIUS_PX).floor() as i64);
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> = std::collections::HashMap::new();
    for (j, q) in b.iter().enumerate().filter(|(_, q)| q[0].is_finite() && q[1].is_finite()) {
        grid.entry(cell(q)).or_default().push(j);
    }
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, p) in a.iter().enumerate().filter(|(_, p)| p[0].is_finite() && p[1].is_finite()) {
        let (cx, cy) = cell(p);
        for gy in cy - 1..=cy + 1 {
            for gx in cx - 1..=cx + 1 {
                for &j in grid.get(&(gx, gy)).map_or(&[][..], Vec::as_slice) {
                    let d = (p[0] - b[j][0]).hypot(p[1] - b[j][1]);
                    if d <= MATCH_RADIUS_PX {
                        pairs.push((d, i, j));
                    }
                }
            }
        }
    }
    pairs.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    let (mut used_a, mut used_b) = (vec![false; a.len()], vec![false; b.len()]);
    let mut dists = Vec::new();
    for (d, i, j) in pairs {
        if !used_a[i] && !used_b[j] {
            used_a[i] = true;
            used_b[j] = true;
            dists.push(d);
        }
    }
    let mean = if dists.is_empty() { 0.0 } else { dists.iter().sum::<f64>() / dists.len() as f64 };
    (mean, a.len() + b.len() - 2 * dists.len())
}

/// Absolute trajectory error between two position sequences: RMSE as recorded and after the
/// best rigid alignment (Horn/Umeyama without scale), in metres.
pub fn ate(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> (f64, f64) {
    let n = a.len().min(b.len());
    if n == 0 {
        return (0.0, 0.0);
    }
    let rmse = |pairs: &mut dyn Iterator<Item = f64>| (pairs.map(|d| d * d).sum::<f64>() / n as f64).sqrt();
    let raw = rmse(&mut a.iter().zip(b).map(|(p, q)| (p - q).norm()));
    let Some((r, t)) = rigid_alignment(&a[..n], &b[..n]) else { return (raw, raw) };
    let aligned = rmse(&mut a.iter().zip(b).map(|(p, q)| (p - (r * q + t)).norm()));
    (raw, aligned)
}

/// The rotation and translation taking `b` onto `a` (pairs in order) with the least squared
/// error: Horn/Umeyama without scale. `None` for no pairs or a degenerate decomposition.
pub fn rigid_alignment(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let n = a.len().min(b.len());
    if n == 0 {
        return None;
    }
    let ca = a.iter().take(n).sum::<Vector3<f64>>() / n as f64;
    let cb = b.iter().take(n).sum::<Vector3<f64>>() / n as f64;
    let mut h = Matrix3::zeros();
    for (p, q) in a.iter().zip(b).take(n) {
        h += (q - cb) * (p - ca).transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else { return None };
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = (u * d * v_t).transpose();
    Some((r, ca - r * cb))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ate_alignment_removes_a_rigid_offset() {
        let a: Vec<Vector3<f64>> =
            (0..20).map(|i| Vector3::new(i as f64 * 0.1, (i as f64 * 0.3).sin(), 0.05 * i as f64)).collect();
        let rot = nalgebra::Rotation3::from_euler_angles(0.1, -0.2, 0.3);
        let b: Vec<Vector3<f64>> = a.iter().map(|p| rot * p + Vector3::new(1.0, 2.0, 3.0)).collect();
        let (raw, aligned) = ate(&a, &b);
        assert!(raw > 1.0);
        assert!(aligned < 1e-9, "{aligned}");
    }

    #[test]
    fn a_set_matches_itself_one_to_one_even_with_points_at_one_position() {
        // Keypoints found at one position on two pyramid levels, and a NaN scalar.
        let a = serde_json::json!({"xy": [[10, 10], [10, 10], [10, 10], [50, 50]], "octave": [0, 1, 2, 0]});
        let m = compare("keypoints", &a, &a);
        assert_eq!((m["unmatched"], m["position_px"], m["count"]), (0.0, 0.0, 0.0));
        // Three at one place against two there: one is left over, the rest pair.
        let b = serde_json::json!({"xy": [[10, 10], [10, 10], [50, 50]]});
        assert_eq!(compare("keypoints", &a, &b)["unmatched"], 1.0);
        let s = serde_json::json!({"ratio": null, "n": 3});
        assert!(compare("scalars", &s, &s).values().all(|v| *v == 0.0));
    }

    #[test]
    fn detection_and_keypoint_metrics() {
        let a = serde_json::json!({"bbox": [[0, 0, 10, 10], [20, 20, 30, 30]], "class_id": [0, 1]});
        let b = serde_json::json!({"bbox": [[0, 0, 10, 12]], "class_id": [0]});
        let m = compare("detections", &a, &b);
        assert_eq!(m["missing"], 1.0);
        assert_eq!(m["extra"], 0.0);
        assert!((m["iou_loss"] - (1.0 - 100.0 / 120.0)).abs() < 1e-12);
        let a = serde_json::json!({"xy": [[0, 0], [100, 100]]});
        let b = serde_json::json!({"xy": [[3, 4], [300, 300]]});
        let m = compare("keypoints", &a, &b);
        assert_eq!(m["position_px"], 5.0);
        assert_eq!(m["unmatched"], 2.0);
    }
}
