#![allow(clippy::unwrap_used)]

use nalgebra::Point3;

use super::*;

fn small(motion: Motion, noise: bool) -> Generator {
    Generator::new(SynthConfig {
        motion,
        intrinsics: scaled_fr3(320, 240),
        depth_noise: noise,
        image_noise: if noise { 2.0 } else { 0.0 },
        blur: noise,
        ..SynthConfig::default()
    })
}

/// Depth of frame k, back-projected with the GT pose of k and projected into frame k + 5,
/// must agree with frame k + 5's depth on static pixels.
fn reprojection_errors(g: &Generator, k: u64, step: u64) -> Vec<f64> {
    let (a, b) = (g.frame(k, false), g.frame(k + step, false));
    let c = &g.config().intrinsics;
    let (w, h) = (c.width as usize, c.height as usize);
    let cam_b_from_cam_a = b.world_from_cam.inverse() * a.world_from_cam;
    let mut errors = Vec::new();
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            let z = f64::from(a.depth[i]);
            if a.class[i] != 0 || z <= 0.0 {
                continue;
            }
            let p = cam_b_from_cam_a * Point3::new((u as f64 - c.cx) / c.fx * z, (v as f64 - c.cy) / c.fy * z, z);
            if p.z <= 0.1 {
                continue;
            }
            let (ub, vb) = ((c.fx * p.x / p.z + c.cx).round(), (c.fy * p.y / p.z + c.cy).round());
            if ub < 0.0 || vb < 0.0 || ub >= w as f64 || vb >= h as f64 {
                continue;
            }
            let j = vb as usize * w + ub as usize;
            if b.class[j] != 0 || b.depth[j] <= 0.0 {
                continue;
            }
            errors.push((f64::from(b.depth[j]) - p.z).abs());
        }
    }
    errors
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn depth_reprojects_with_ground_truth_poses() {
    for motion in [Motion::Xyz, Motion::Rpy, Motion::Halfsphere] {
        let g = small(motion, false);
        let errors = reprojection_errors(&g, 40, 5);
        assert!(errors.len() > 20_000, "{motion:?}: only {} pixels compared", errors.len());
        let m = median(errors);
        assert!(m < 0.01, "{motion:?}: median reprojection error {m} m");
    }
    // With Kinect noise the median grows to the noise level but stays a few centimetres.
    let m = median(reprojection_errors(&small(Motion::Xyz, true), 40, 5));
    assert!(m < 0.04, "noisy median {m}");
}

#[test]
fn static_flow_matches_reprojection_and_people_move() {
    let g = small(Motion::Xyz, false);
    let f = g.frame(30, true);
    let flow = f.flow.as_ref().unwrap();
    let c = &g.config().intrinsics;
    let next = g.pose(31).inverse() * g.pose(30);
    let (mut checked, mut person_moving) = (0, 0);
    for (i, fl) in flow.iter().enumerate() {
        let z = f64::from(f.depth_true[i]);
        let (u, v) = ((i % c.width as usize) as f64, (i / c.width as usize) as f64);
        if f.class[i] == 0 && z > 0.0 {
            let p = next * Point3::new((u - c.cx) / c.fx * z, (v - c.cy) / c.fy * z, z);
            let (du, dv) = (c.fx * p.x / p.z + c.cx - u, c.fy * p.y / p.z + c.cy - v);
            assert!(
                (f64::from(fl[0]) - du).abs() < 1e-2 && (f64::from(fl[1]) - dv).abs() < 1e-2,
                "pixel {i}: {fl:?} vs {du},{dv}"
            );
            checked += 1;
        } else if f.class[i] == 1 && fl[0].hypot(fl[1]) > 0.5 {
            person_moving += 1;
        }
    }
    assert!(checked > 50_000);
    assert!(person_moving > 100, "people should move in the image: {person_moving}");
}

#[test]
fn deterministic_by_seed() {
    let a = small(Motion::Xyz, true).frame(7, false);
    let b = small(Motion::Xyz, true).frame(7, false);
    assert_eq!(a.rgb, b.rgb);
    assert_eq!(a.depth, b.depth);
    let other = Generator::new(SynthConfig { seed: 1, intrinsics: scaled_fr3(320, 240), ..SynthConfig::default() })
        .frame(7, false);
    assert_ne!(a.rgb, other.rgb);
}

#[test]
fn people_sometimes_cover_a_large_part_of_the_image() {
    let g = Generator::new(SynthConfig { intrinsics: scaled_fr3(160, 120), ..SynthConfig::default() });
    let coverage: Vec<f64> = (0..300)
        .step_by(3)
        .map(|k| {
            let f = g.frame(k, false);
            f.class.iter().filter(|&&c| c == 1).count() as f64 / f.class.len() as f64
        })
        .collect();
    let max = coverage.iter().copied().fold(0.0, f64::max);
    let mean = coverage.iter().sum::<f64>() / coverage.len() as f64;
    assert!((0.2..=0.6).contains(&max), "max person coverage {max}");
    assert!(mean > 0.03, "people are rarely visible: mean coverage {mean}");
}

#[test]
fn kinect_noise_scales_with_depth_squared_and_leaves_holes() {
    let g = small(Motion::Static, true);
    let f = g.frame(0, false);
    let valid: Vec<(f32, f32)> =
        f.depth.iter().zip(&f.depth_true).filter(|(n, _)| **n > 0.0).map(|(n, t)| (*n, *t)).collect();
    let holes = 1.0 - valid.len() as f64 / f.depth.len() as f64;
    assert!((0.003..0.3).contains(&holes), "hole fraction {holes}");
    let rel: Vec<f64> = valid.iter().map(|(n, t)| f64::from((n - t).abs()) / f64::from(t * t)).collect();
    let m = median(rel);
    // σ = 0.0015 z² plus disparity quantisation: the median |error|/z² is of that order.
    assert!((0.0005..0.006).contains(&m), "median |error|/z² = {m}");
}
