//! Synthetic rectified stereo pairs and our sparse stereo matching on them, shared by
//! `vision/tests/stereo.rs` and `benches/stereo.rs`, with the OpenCV StereoSGBM peer
//! (`tests/peers/stereo_sgbm.py`).
#![allow(clippy::unwrap_used, clippy::panic, dead_code)]

use std::path::Path;
use std::process::Command;

use dynaflow_datasets::synth::{Generator, Motion, SynthConfig};
use dynaflow_vision::GrayImage;
use dynaflow_vision::orb::{OrbConfig, OrbExtractor, OrbFeatures};
use dynaflow_vision::stereo::{StereoMatches, StereoRig, StereoView, stereo_match};

/// A rectified pair of the synthetic scene and the exact disparity of each left pixel.
pub struct Pair {
    pub left: GrayImage,
    pub right: GrayImage,
    pub disparity: Vec<f32>,
    pub rig: StereoRig,
}

/// Frame `k` of the walking scene (`motion`, `seed`) with a right camera `baseline` m to the right.
pub fn synth_stereo(motion: Motion, seed: u64, k: u64, baseline: f64) -> Pair {
    let g = Generator::new(SynthConfig { motion, seed, ..SynthConfig::default() });
    let f = g.frame(k, false);
    let right = g.right(&f, baseline).unwrap();
    let i = &g.config().intrinsics;
    let (w, h) = (i.width as usize, i.height as usize);
    Pair {
        left: GrayImage::from_rgb8(w, h, &f.rgb).unwrap(),
        right: GrayImage::from_rgb8(w, h, &right).unwrap(),
        disparity: g.disparity(&f, baseline),
        rig: StereoRig { bf: i.fx * baseline, baseline, scale_factor: 1.2 },
    }
}

/// ORB (ORB-SLAM2's settings, 1000 features) on both images and the stereo matches, with
/// the left features.
pub fn match_pair(pair: &Pair) -> (OrbFeatures, StereoMatches) {
    let mut left = OrbExtractor::new(OrbConfig::default());
    let mut right = OrbExtractor::new(OrbConfig::default());
    let fl = left.extract(&pair.left, None);
    let fr = right.extract(&pair.right, None);
    let (ll, rl) = (left.pyramid(&pair.left), right.pyramid(&pair.right));
    let m = stereo_match(
        &StereoView { keypoints: &fl.keypoints, descriptors: &fl.descriptors, levels: &ll },
        &StereoView { keypoints: &fr.keypoints, descriptors: &fr.descriptors, levels: &rl },
        &pair.rig,
    )
    .unwrap();
    (fl, m)
}

/// The exact disparity at a keypoint (nearest pixel), `None` on no surface or where it jumps
/// by more than a pixel within the 3x3 neighbourhood (a depth edge: which side the keypoint
/// belongs to is not defined to a pixel).
pub fn exact_disparity(pair: &Pair, x: f32, y: f32) -> Option<f32> {
    let w = pair.left.width as i64;
    let h = pair.left.height as i64;
    let (xi, yi) = (x.round() as i64, y.round() as i64);
    if xi < 1 || yi < 1 || xi >= w - 1 || yi >= h - 1 {
        return None;
    }
    let at = |dx: i64, dy: i64| pair.disparity[((yi + dy) * w + xi + dx) as usize];
    let d = at(0, 0);
    let near: Vec<f32> = (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (dx, dy))).map(|(dx, dy)| at(dx, dy)).collect();
    (d > 0.0 && near.iter().all(|v| (v - d).abs() <= 1.0)).then_some(d)
}

/// Quantile `q` of `v` (sorted in place), NaN when empty.
pub fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// StereoSGBM's disparities at `points` of each pair (PNG files written to `dir`), and its
/// time per pair (ms).
pub fn sgbm(python: &Path, dir: &Path, pairs: &[(&Pair, Vec<[f32; 2]>)], reps: usize) -> Vec<(Vec<Option<f64>>, f64)> {
    let mut jobs = Vec::new();
    for (i, (pair, points)) in pairs.iter().enumerate() {
        let (l, r) = (dir.join(format!("left{i}.png")), dir.join(format!("right{i}.png")));
        super::frontend::save_gray(&pair.left, &l);
        super::frontend::save_gray(&pair.right, &r);
        jobs.push(serde_json::json!({ "left": l, "right": r, "points": points }));
    }
    let job = dir.join("sgbm.json");
    std::fs::write(&job, serde_json::json!({ "pairs": jobs, "reps": reps }).to_string()).unwrap();
    let out = Command::new(python)
        .arg(super::frontend::repo().join("tests/peers/stereo_sgbm.py"))
        .arg(&job)
        .output()
        .unwrap();
    assert!(out.status.success(), "sgbm peer: {}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    v["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let d = p["disparity"].as_array().unwrap().iter().map(serde_json::Value::as_f64).collect();
            (d, p["ms"].as_f64().unwrap())
        })
        .collect()
}
