//! Why MG-SLAM's epipolar test (LK tracks, F by LO-RANSAC, dynamic above 0.40 px) flags so
//! few of the walking people's tracks, measured against the generator's ground truth (used
//! here for analysis only, never by a rule): for every tracked point on a person that the
//! test leaves static, the cause; for every static point it flags, the cause.
//!
//! Per track, from the exact depth and camera poses: the point's static prediction (where it
//! would be were it static), hence the person's own image motion `r` (observed minus
//! predicted, pixels), and the distance to its epipolar line under the exact F (`d_true`,
//! from the true relative pose) and under the estimated F (`d_est`). A missed dynamic track
//! is "little own motion" (`|r|` < 0.4 px: between two frames the person barely moved in the
//! image), "no baseline" (the camera only rotated between the frames: F is undefined, so no
//! epipolar test can see anything), "along its epipolar line" (`|r|` >= 0.4 but `d_true` < 0.4: the motion has no
//! component across the line, which no one-frame epipolar test can see) or "F estimate"
//! (`d_true` >= 0.4, `d_est` < 0.4: the estimated F, pulled by the dynamic tracks or by
//! RANSAC, hides it). A flagged static track is "track error" (`d_true` >= 0.4: the LK track
//! itself is off, e.g. a window straddling a person's outline) or "F estimate".
//!
//! `cargo bench --bench epipolar_causes` (add `-- PAIRS`, default 40 consecutive pairs per
//! camera motion, the default synthetic scene).
#![allow(clippy::unwrap_used, clippy::panic)]

use dynaflow_culling as rules;
use dynaflow_datasets::synth::{Generator, Motion, SynthConfig};
use dynaflow_vision::flow::{LkConfig, LkTracker};
use dynaflow_vision::geometry::RansacConfig;
use nalgebra::{Matrix3, Vector3};

#[path = "common/synth_tracks.rs"]
mod synth_tracks;

const THRESHOLD: f32 = 0.4;

fn skew(t: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0)
}

/// Distance in pixels of `q` from the epipolar line of `p` under `f` (in `q`'s image).
fn line_distance(f: &Matrix3<f64>, p: [f32; 2], q: [f32; 2]) -> f64 {
    let l = f * Vector3::new(f64::from(p[0]), f64::from(p[1]), 1.0);
    (f64::from(q[0]) * l.x + f64::from(q[1]) * l.y + l.z).abs() / (l.x * l.x + l.y * l.y).sqrt().max(1e-12)
}

fn main() {
    let pairs: u64 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(40);
    println!("epipolar test (0.40 px) on the synthetic scene, {pairs} consecutive pairs per motion\n");
    println!(
        "| motion | dynamic tracks | flagged (recall) | ceiling with the exact F | missed: little own motion | missed: no baseline | missed: along the epipolar line | missed: F estimate | static tracks | off their exact line by > 0.4 px (LK error) | flagged (false) | false: track error | false: F estimate | median camera translation per frame |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for motion in [Motion::Xyz, Motion::Halfsphere, Motion::Rpy] {
        let g = Generator::new(SynthConfig { motion, ..SynthConfig::default() });
        let k = g.config().intrinsics.clone();
        let (w, h) = (k.width as usize, k.height as usize);
        let camera = rules::Pinhole::new(k.fx, k.fy, k.cx, k.cy);
        let kmat = Matrix3::new(k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0);
        let kinv = kmat.try_inverse().unwrap();
        let mut lk = LkTracker::new(LkConfig { fb_threshold: Some(1.0), ..LkConfig::default() });
        // dynamic: total, flagged, flagged under the exact F, missed by cause (3); static:
        // total, flagged, by cause (2).
        let mut n = [0u64; 12];
        let mut baselines = Vec::new();
        let mut next = g.frame(0, false);
        for f in 0..pairs {
            let cur = std::mem::replace(&mut next, g.frame(f + 1, false));
            let (prev, curp, _) = synth_tracks::lk_tracks(&mut lk, &cur.rgb, &next.rgb, w, h);
            let Some((_, d_est)) =
                rules::epipolar_distances(&prev, &curp, &vec![true; prev.len()], &RansacConfig::default(), f)
            else {
                continue;
            };
            let next_from_cur = next.world_from_cam.inverse() * cur.world_from_cam;
            let e = skew(&next_from_cur.translation.vector) * next_from_cur.rotation.to_rotation_matrix().into_inner();
            let f_true = kinv.transpose() * e * kinv;
            let baseline = next_from_cur.translation.vector.norm();
            baselines.push(baseline);
            for i in 0..prev.len() {
                let (p, q) = (prev[i], curp[i]);
                let (px, py) = (p[0].round() as usize, p[1].round() as usize);
                if px >= w || py >= h {
                    continue;
                }
                let z = cur.depth_true[py * w + px];
                if z <= 0.0 {
                    continue;
                }
                let dynamic = cur.class[py * w + px] == 1;
                let x = next_from_cur * camera.unproject([f64::from(p[0]), f64::from(p[1])], f64::from(z));
                let Some(pred) = camera.project(&x) else { continue };
                let own = ((f64::from(q[0]) - pred[0]).powi(2) + (f64::from(q[1]) - pred[1]).powi(2)).sqrt();
                let d_true = line_distance(&f_true, p, q);
                let flagged = d_est[i] > THRESHOLD;
                let t = f64::from(THRESHOLD);
                if dynamic {
                    n[0] += 1;
                    n[1] += u64::from(flagged);
                    n[2] += u64::from(baseline >= 1e-6 && d_true > t);
                    if !flagged {
                        let cause = if own < t {
                            3
                        } else if baseline < 1e-6 {
                            10
                        } else if d_true <= t {
                            4
                        } else {
                            5
                        };
                        n[cause] += 1;
                    }
                } else {
                    n[6] += 1;
                    n[11] += u64::from(d_true > t);
                    if flagged {
                        n[7] += 1;
                        n[if d_true > t { 8 } else { 9 }] += 1;
                    }
                }
            }
        }
        let pct = |a: u64, b: u64| format!("{:.0} %", 100.0 * a as f64 / b.max(1) as f64);
        let missed = n[0] - n[1];
        baselines.sort_by(f64::total_cmp);
        let median = baselines.get(baselines.len() / 2).copied().unwrap_or(0.0);
        println!(
            "| {motion:?} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} mm |",
            n[0],
            pct(n[1], n[0]),
            pct(n[2], n[0]),
            pct(n[3], missed),
            pct(n[10], missed),
            pct(n[4], missed),
            pct(n[5], missed),
            n[6],
            pct(n[11], n[6]),
            pct(n[7], n[6]),
            pct(n[8], n[7]),
            pct(n[9], n[7]),
            median * 1e3,
        );
    }
}
