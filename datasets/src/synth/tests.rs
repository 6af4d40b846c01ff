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
    // Holes, as the model makes them: every pixel out of range, `EDGE_DROPOUT` of the pixels
    // at a depth edge, `DROPOUT` of the rest; the count within 4 binomial sigmas of that.
    use super::sensor::{DISPARITY_C, DROPOUT, EDGE_DROPOUT, EDGE_STEP_M, MAX_RANGE, MIN_RANGE, SIGMA_Z2};
    let (t, w) = (&f.depth_true, g.config().intrinsics.width as usize);
    let (mut mean, mut var) = (0.0f64, 0.0f64);
    for (i, &z) in t.iter().enumerate() {
        let p = if !(MIN_RANGE..=MAX_RANGE).contains(&z) {
            1.0
        } else {
            let step = |k: Option<usize>| k.and_then(|k| t.get(k)).is_some_and(|&n| (n - z).abs() > EDGE_STEP_M);
            let edge = [i.checked_sub(1), Some(i + 1), i.checked_sub(w), Some(i + w)].into_iter().any(step);
            f64::from(if edge { EDGE_DROPOUT } else { DROPOUT })
        };
        mean += p;
        var += p * (1.0 - p);
    }
    let holes = (f.depth.len() - valid.len()) as f64;
    eprintln!("holes {holes}, the model's expectation {mean:.0} +- {:.0}", var.sqrt());
    assert!((holes - mean).abs() <= 4.0 * var.sqrt() + 1.0, "{holes} holes, expected {mean} +- {}", var.sqrt());
    // Noise: the median |error| / z² against the same model simulated here, with its own
    // random numbers, at the same true depths: σ = SIGMA_Z2 z² times the generator's
    // approximately normal variable (the sum of four uniform bytes, standardised), then the
    // disparity quantisation. 3 % allows for sampling (tens of thousands of pixels).
    let rel: Vec<f64> = valid.iter().map(|(n, t)| f64::from((n - t).abs()) / f64::from(t * t)).collect();
    let m = median(rel);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut normal = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let bytes: u64 = (0..4).map(|k| (state >> (8 * k)) & 0xff).sum();
        (bytes as f64 - 510.0) / 147.8
    };
    let simulated: Vec<f64> = valid
        .iter()
        .map(|&(_, z)| {
            let z = f64::from(z);
            let n = normal();
            let noisy = z + n * SIGMA_Z2 * z * z;
            let quantised = DISPARITY_C / (DISPARITY_C / noisy).round().max(1.0);
            (quantised - z).abs() / (z * z)
        })
        .collect();
    let want = median(simulated);
    eprintln!("median |error|/z^2: {m:.6}, the model simulated {want:.6}");
    assert!((m / want - 1.0).abs() <= 0.03, "median |error|/z² = {m}, the model's {want}");
}

/// The right image of a stereo pair shows each left pixel at `u - d` (exact disparity), and
/// nowhere else: the colour difference there is small, and grows when the disparity is off by
/// a few pixels. A baseline that is not positive gives no right image.
#[test]
fn the_right_image_sees_left_pixels_at_their_exact_disparity() {
    let g = small(Motion::Xyz, false);
    let left = g.frame(30, false);
    let right = g.right(&left, 0.08).unwrap();
    let disparity = g.disparity(&left, 0.08);
    let (w, h) = (320usize, 240usize);
    let grey = |rgb: &[u8], i: usize| f64::from(rgb[3 * i]) + f64::from(rgb[3 * i + 1]) + f64::from(rgb[3 * i + 2]);
    let diff = |offset: f32| {
        let mut d = Vec::new();
        for v in 0..h {
            for u in 0..w {
                let i = v * w + u;
                let disparity = disparity[i];
                let ur = (u as f32 - disparity - offset).round();
                if disparity <= 0.0 || ur < 0.0 || ur >= w as f32 {
                    continue;
                }
                d.push((grey(&left.rgb, i) - grey(&right, v * w + ur as usize)).abs());
            }
        }
        median(d)
    };
    let (at, off) = (diff(0.0), diff(3.0));
    assert!(at < 15.0 && off > 2.0 * at, "median colour difference {at} at the disparity, {off} 3 px off");
    // Disparity is fx * b / z.
    let i = 120 * w + 160;
    let expected = g.config().intrinsics.fx * 0.08 / f64::from(left.depth_true[i]);
    assert!((f64::from(disparity[i]) - expected).abs() < 1e-3);
    assert!(g.right(&left, 0.0).is_none() && g.right(&left, f64::NAN).is_none());
}

#[test]
fn on_the_loop_people_pass_the_camera_at_a_distance_and_stay_in_view() {
    // The loop's camera walks through the middle of the room; people keep their lanes
    // `WALKWAY_CLEARANCE` from its band, so none walks through the camera, yet they are seen.
    for seed in [0, 1, 2, 3] {
        let g = Generator::new(SynthConfig {
            motion: Motion::Loop,
            seed,
            intrinsics: scaled_fr3(160, 120),
            ..SynthConfig::default()
        });
        let (mut nearest, mut seen) = (f64::INFINITY, 0);
        for k in (0..900).step_by(10) {
            let cam = g.pose(k).translation.vector;
            for (part, _) in g.people_boxes(k) {
                let d = part.translation.vector - cam;
                nearest = nearest.min((d.x * d.x + d.y * d.y).sqrt());
            }
            let f = g.frame(k, false);
            seen += usize::from(f.class.contains(&1));
        }
        assert!(nearest > 0.8, "seed {seed}: a person comes within {nearest:.2} m of the camera");
        println!("seed {seed}: nearest {nearest:.2} m, people in view in {seen} of 90 frames");
        assert!(seen >= 15, "seed {seed}: people in view in only {seen} of 90 frames");
    }
}

#[test]
fn culling_by_screen_rectangles_changes_no_pixel() {
    culling_changes_no_pixel(scaled_fr3(160, 120));
}

#[test]
fn culling_a_fisheye_on_the_unit_plane_changes_no_pixel() {
    culling_changes_no_pixel(super::fisheye(160, 120));
}

fn culling_changes_no_pixel(intrinsics: super::Intrinsics) {
    // Every case of the rectangles: the loop walks through the middle of the room (furniture
    // and people beside, behind and in front of the camera), and a camera set beside each
    // piece of furniture looking along it, so the box reaches from behind the camera into view.
    let g = Generator::new(SynthConfig { motion: Motion::Loop, intrinsics, ..SynthConfig::default() });
    let k = &g.config().intrinsics;
    let mut views: Vec<(u64, nalgebra::Isometry3<f64>)> = (0..900).step_by(15).map(|f| (f, g.pose(f))).collect();
    for part in g.scene.statics() {
        let c = part.world_from_part.translation.vector;
        let side = nalgebra::Vector3::new(0.0, -c.y.signum() * (part.half.y + 0.3), 0.0);
        let at = nalgebra::Translation3::from(c + side);
        views.push((
            0,
            nalgebra::Isometry3::from_parts(at, scene::look_rotation(&nalgebra::Vector3::x(), &nalgebra::Vector3::z())),
        ));
    }
    let mut straddling = 0;
    for (frame, pose) in views {
        let parts = g.scene.people_parts(g.time(frame));
        let culled = render::render_culled(&g.scene, &parts, &pose, k, true, true);
        let every = render::render_culled(&g.scene, &parts, &pose, k, true, false);
        assert_eq!(culled.rgb, every.rgb, "frame {frame}");
        assert_eq!(culled.instance, every.instance, "frame {frame}");
        let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&culled.depth), bits(&every.depth), "frame {frame}");
        let hits =
            |r: &render::Rendered| r.hits.iter().map(|h| (h.part, h.point.map(f32::to_bits))).collect::<Vec<_>>();
        assert_eq!(hits(&culled), hits(&every), "frame {frame}");
        // Count the views where a box both seen and partly behind the camera was rendered.
        let cam_from_world = pose.inverse();
        straddling += usize::from(g.scene.statics().iter().chain(&parts).any(|p| {
            let zs = render::box_corners(p, &(cam_from_world * p.world_from_part)).map(|c| c.z);
            zs.iter().any(|&z| z < 0.0) && zs.iter().any(|&z| z > 0.5)
        }));
    }
    assert!(straddling >= 10, "only {straddling} views with a box reaching from behind the camera into view");
}

#[test]
fn the_noisy_imu_has_the_datasheets_white_noise_and_is_seeded() {
    // 60 s at 200 Hz. The sample-to-sample differences of the error cancel the slowly walking
    // bias (its step is 1e-3 of the white noise's), leaving twice the white variance.
    let calibration = dynaflow_msg::ImuCalibration::adis16448();
    let g = Generator::new(SynthConfig { motion: Motion::Halfsphere, seed: 5, ..SynthConfig::default() });
    let (noisy, exact) = (g.imu(&calibration, 60.0, true), g.imu(&calibration, 60.0, false));
    assert_eq!(noisy.len(), 12_001);
    let std_of_differences = |pick: &dyn Fn(&dynaflow_msg::ImuSample) -> nalgebra::Vector3<f64>| {
        let e: Vec<nalgebra::Vector3<f64>> = noisy.iter().zip(&exact).map(|(n, x)| pick(n) - pick(x)).collect();
        let d: Vec<f64> = e.windows(2).flat_map(|w| (w[1] - w[0]).iter().copied().collect::<Vec<_>>()).collect();
        (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64 / 2.0).sqrt()
    };
    let rate_sqrt = calibration.rate_hz.sqrt();
    for (name, measured, expected) in [
        ("gyro", std_of_differences(&|s| s.gyro), calibration.gyro_noise_density * rate_sqrt),
        ("accel", std_of_differences(&|s| s.accel), calibration.accel_noise_density * rate_sqrt),
    ] {
        println!("{name}: white noise {measured:.4e}, datasheet {expected:.4e}");
        assert!((measured / expected - 1.0).abs() < 0.03, "{name}: {measured:.4e} against {expected:.4e}");
    }
    assert_eq!(g.imu(&calibration, 1.0, true), noisy[..201].to_vec(), "the same seed draws the same samples");
    let other = Generator::new(SynthConfig { motion: Motion::Halfsphere, seed: 6, ..SynthConfig::default() });
    assert_ne!(other.imu(&calibration, 1.0, true)[1], noisy[1]);
}

#[test]
fn a_fisheye_folder_carries_its_lens_in_calibration_txt() {
    let dir = std::env::temp_dir().join(format!("dynaflow-fisheye-calib-{}", std::process::id()));
    let k = super::fisheye(32, 24);
    let g = Generator::new(SynthConfig { intrinsics: k.clone(), people: 0, ..SynthConfig::default() });
    super::write_tum(&g, &dir, &super::WriteOptions { frames: 1, flow: false }).unwrap();
    let read = crate::intrinsics::read_calibration(&dir).unwrap().unwrap().camera_info(32, 24);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(read.model, dynaflow_msg::LensModel::KannalaBrandt);
    for (a, b) in [read.fx, read.fy, read.cx, read.cy]
        .iter()
        .chain(&read.distortion)
        .zip([k.fx, k.fy, k.cx, k.cy].iter().chain(&k.distortion))
    {
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{read:?} vs {k:?}");
    }
}

#[test]
fn the_drive_goes_round_the_block_at_its_speed_clear_of_the_buildings_and_its_depth_reprojects() {
    // One round: back where it started, at the same heading, after `drive_period`; the speed
    // constant along the way (straights and corners), the camera at KITTI's height.
    let m = Motion::Drive;
    let period = drive_period();
    let (a, b) = (m.pose(0.0), m.pose(period));
    assert!((a.translation.vector - b.translation.vector).norm() < 1e-6, "{a} vs {b}");
    assert!(a.rotation.angle_to(&b.rotation) < 1e-6);
    let dt = 0.1;
    let mut length = 0.0;
    for k in 0..(period / dt).ceil() as usize {
        let (p, q) = (m.pose(k as f64 * dt), m.pose((k + 1) as f64 * dt));
        let step = (q.translation.vector - p.translation.vector).norm();
        assert!((step - DRIVE_SPEED * dt).abs() < 1e-3, "step {step} at {k}");
        assert!((p.translation.vector.z - 1.65).abs() < 1e-9);
        length += step;
    }
    assert!((length - drive_length()).abs() < 0.05 * DRIVE_SPEED, "{length} vs {}", drive_length());
    // The road is clear: every building and parked car at least 3 m from the camera.
    let g = Generator::new(SynthConfig {
        motion: m,
        people: 0,
        rate_hz: 10.0,
        intrinsics: scaled_kitti(310, 94),
        depth_noise: false,
        image_noise: 0.0,
        blur: false,
        ..SynthConfig::default()
    });
    let parts = g.scene.statics();
    assert!(parts.len() > 50, "{} boxes", parts.len());
    for k in 0..(period / 0.5) as usize {
        let c = m.pose(k as f64 * 0.5).translation.vector;
        for part in parts {
            let local = part.world_from_part.inverse_transform_point(&c.into());
            let outside = (local.coords.abs() - part.half).map(|v| v.max(0.0)).norm();
            assert!(outside >= 3.0, "{outside} m from a box at {k}");
        }
    }
    // The street's geometry as rendered: depth seen from frame k lands on frame k + 2's (to
    // the pixel, so a facade seen at a grazing angle 10-40 m away differs by centimetres).
    for k in [30, 290] {
        let e = reprojection_errors(&g, k, 2);
        assert!(e.len() > 1000, "{} pixels compared at {k}", e.len());
        let m = median(e);
        assert!(m < 0.05, "median depth disagreement {m} m at {k}");
    }
}
