//! Precision and recall of "dynamic" for each culling rule on the synthetic walking scene,
//! against the generator's ground truth: a tracked point is truly dynamic when it lies on a
//! person in the first frame of the pair (walking people always move).
//!
//! `cargo bench --bench culling` (add `-- FRAMES`, default 60 pairs per sequence). Tracks are
//! what `lk_flow` produces (FAST seeds 5 px apart, pyramidal LK, forward-backward check 1 px);
//! the rules are the functions `cull` calls; boxes are the `oracle_boxes` of the ground-truth
//! masks.
#![allow(clippy::unwrap_used, clippy::panic)]

use dynaflow_culling::{self as rules, LabelledBox};
use dynaflow_datasets::synth::{Generator, Motion, SynthConfig};
use dynaflow_vision::GrayImage;
use dynaflow_vision::flow::{LkConfig, LkTracker, seed_corners};
use dynaflow_vision::geometry::RansacConfig;

#[path = "common/synth_tracks.rs"]
mod synth_tracks;

const MODES: [&str; 8] = [
    "epipolar_fixed",
    "epipolar_adaptive",
    "mask",
    "semantic_prior",
    "semantic_prior+fixed",
    "mask|fixed",
    "flow (homography 1 px)",
    "flow (F 1 px)",
];

fn main() {
    let pairs: u64 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(60);
    println!("culling on the synthetic scene (2 walking people, 640x480), {pairs} frame pairs per sequence");
    println!("{:<12} {:<22} {:>9} {:>7} {:>6} {:>8}", "motion", "mode", "precision", "recall", "F1", "points");
    for motion in [Motion::Xyz, Motion::Halfsphere] {
        let g = Generator::new(SynthConfig { motion, ..SynthConfig::default() });
        let k = g.config().intrinsics.clone();
        let (w, h) = (k.width as usize, k.height as usize);
        let mut lk = LkTracker::new(LkConfig { fb_threshold: Some(1.0), ..LkConfig::default() });
        let mut counts = [rules::Confusion::default(); MODES.len()];
        let mut depth_counts = rules::Confusion::default();
        let mut total = 0u64;
        let mut next = g.frame(0, false);
        for f in 0..pairs {
            let cur = std::mem::replace(&mut next, g.frame(f + 1, false));
            let (prev, curp, errors) = synth_tracks::lk_tracks(&mut lk, &cur.rgb, &next.rgb, w, h);
            let truth: Vec<bool> =
                prev.iter().map(|p| cur.class[p[1].round() as usize * w + p[0].round() as usize] == 1).collect();
            // What `oracle_boxes` emits (every instance, however small).
            let boxes: Vec<LabelledBox> = rules::instance_boxes(&next.instance, &next.class, w, 1)
                .into_iter()
                .map(|(bbox, _)| LabelledBox { bbox, label: "person".into() })
                .collect();
            let in_box = rules::in_any_box(&curp, &boxes);
            let ransac = RansacConfig::default();
            let Some((_, d_all)) = rules::epipolar_distances(&prev, &curp, &vec![true; prev.len()], &ransac, f) else {
                continue;
            };
            let outside: Vec<bool> = in_box.iter().map(|b| !b).collect();
            let fixed = rules::epipolar_fixed(&d_all, 0.4);
            let adaptive = match rules::epipolar_distances(&prev, &curp, &outside, &ransac, f) {
                Some((_, d)) => rules::epipolar_adaptive(&d, &in_box).0,
                None => fixed.clone(),
            };
            let mask = rules::mask_rule(&curp, |x, y| x < w && y < h && next.class[y * w + x] == 1);
            let value = |l: &str| if l == "person" { 1.0 } else { 0.0 };
            let semantic = rules::semantic_prior(&curp, &boxes, value, false);
            let quality: Vec<f64> = errors.iter().map(|e| 1.0 / (1.0 + f64::from(*e))).collect();
            let flow_h = match rules::homography_residuals(&prev, &curp, &quality, 1.0, f) {
                Some((_, r)) => rules::flow_consistency(&r, 1.0),
                None => fixed.clone(),
            };
            let flow_f = rules::flow_consistency(&d_all, 1.0);
            // Depth check against a key frame 10 frames back (a walking person moves about
            // 0.3 m in that time; frame to frame only 3 cm, below the depth noise).
            let camera = rules::Pinhole::new(k.fx, k.fy, k.cx, k.cy);
            let key_f = f.saturating_sub(10);
            let key = g.frame(key_f, false);
            let kimg = GrayImage::from_rgb8(w, h, &key.rgb).unwrap();
            let kseeds = seed_corners(&kimg, 1000, 20, 5.0, 10, &[]);
            // The key frame's points themselves are checked (no tracking needed: they are
            // projected).
            let kprev = kseeds;
            let cur_from_world = next.world_from_cam.inverse();
            let at = |d: &[f32], x: f32, y: f32| {
                let (xi, yi) = (x.round() as usize, y.round() as usize);
                if xi < w && yi < h { d[yi * w + xi] } else { 0.0 }
            };
            let predicted: Vec<_> = kprev
                .iter()
                .map(|p| {
                    let z = at(&key.depth, p[0], p[1]);
                    (z > 0.0).then(|| {
                        cur_from_world
                            * (key.world_from_cam * camera.unproject([f64::from(p[0]), f64::from(p[1])], f64::from(z)))
                    })
                })
                .collect();
            let depth = rules::depth_consistency(&predicted, camera, |x, y| at(&next.depth, x, y), 0.1);
            for (i, d) in depth.iter().enumerate() {
                let truth = key.class[kprev[i][1].round() as usize * w + kprev[i][0].round() as usize] == 1;
                depth_counts.add(d.dynamic, truth);
            }
            for i in 0..prev.len() {
                let predictions = [
                    fixed[i].dynamic,
                    adaptive[i].dynamic,
                    mask[i].dynamic,
                    semantic[i].dynamic,
                    semantic[i].dynamic && fixed[i].dynamic,
                    mask[i].dynamic || fixed[i].dynamic,
                    flow_h[i].dynamic,
                    flow_f[i].dynamic,
                ];
                for (c, p) in counts.iter_mut().zip(predictions) {
                    c.add(p, truth[i]);
                }
            }
            total += prev.len() as u64;
        }
        for (mode, c) in MODES.iter().copied().zip(counts).chain([("depth_consistency (key 10 back)", depth_counts)]) {
            println!(
                "{:<12} {:<22} {:>9.3} {:>7.3} {:>6.3} {:>8}",
                format!("{motion:?}"),
                mode,
                c.precision(),
                c.recall(),
                c.f1(),
                total
            );
        }
    }
}
