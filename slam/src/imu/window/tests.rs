#![allow(clippy::unwrap_used)]

use dynaflow_base::rng::SplitMix64;
use dynaflow_datasets::synth::{FR3, Generator, Motion, STAMP_BASE, SynthConfig, rig_calibration};
use nalgebra::Point3;

use super::*;
use crate::imu::init::{InitConfig, InitKeyFrame, initialise};

/// Ten key frames 0.25 s apart of `synth`'s hand-held motion from `start` (ORB-SLAM3's
/// inertial window), ADIS16448-noisy IMU between them, `n` observations per key frame of
/// points 1.5-4 m in front of the true camera (1 px noise; with depth for `bf > 0`), and the
/// key frames' starting states off by `pose_noise` (rad and metres per axis) and 5 cm/s.
struct Scene {
    kfs: Vec<WindowKeyFrame>,
    truth: Vec<NavState>,
    between: Vec<Preintegrated>,
}

fn scene(seed: u64, start: f64, n: usize, bf: f64, pose_noise: f64) -> Scene {
    let cal = rig_calibration();
    let cam = Pinhole { fx: FR3.fx, fy: FR3.fy, cx: FR3.cx, cy: FR3.cy };
    let g = Generator::new(SynthConfig { motion: Motion::Handheld, seed, ..SynthConfig::default() });
    let times: Vec<f64> = (0..10).map(|k| start + 0.25 * f64::from(k)).collect();
    let samples = g.imu(&cal, times[9] + 0.01, true);
    let mut rng = SplitMix64::named(seed, "window");
    let mut kfs = Vec::new();
    let mut truth = Vec::new();
    for &t in &times {
        let state = NavState {
            world_from_body: g.body_pose(t, &cal),
            velocity: g.body_velocity(t, &cal),
            bias: Bias::default(),
        };
        let world_from_cam = state.world_from_body * cal.body_from_cam;
        let observations = (0..n)
            .map(|_| {
                let (u, v) = (rng.uniform() * 600.0 + 20.0, rng.uniform() * 440.0 + 20.0);
                let z = 1.5 + rng.uniform() * 2.5;
                let pc = Point3::new((u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z);
                // The right image's coordinate with its own 1 px noise, as stereo measures it.
                let uv = [u + rng.normal(), v + rng.normal()];
                let right = u - bf / z + rng.normal();
                PoseObservation {
                    point: world_from_cam * pc,
                    uv,
                    sigma: 1.0,
                    depth: (bf > 0.0).then(|| bf / (uv[0] - right)),
                }
            })
            .collect();
        let mut noisy = state.world_from_body;
        let dr = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * pose_noise;
        let dp = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * pose_noise;
        noisy.rotation = UnitQuaternion::from_scaled_axis(dr) * noisy.rotation;
        noisy.translation.vector += dp;
        let dv = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * 0.05;
        kfs.push(WindowKeyFrame { world_from_body: noisy, velocity: state.velocity + dv, observations });
        truth.push(state);
    }
    let between = times
        .windows(2)
        .map(|w| {
            let mut p = Preintegrated::new(Bias::default(), &cal);
            p.integrate_span(&samples, STAMP_BASE + w[0], STAMP_BASE + w[1]);
            p
        })
        .collect();
    Scene { kfs, truth, between }
}

fn rmse(errors: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = errors.collect();
    (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt()
}

#[test]
fn the_window_recovers_velocities_the_inertial_only_refinement_cannot() {
    // Seeds 1-3, windows starting 2 and 4 s in, key-frame poses 3 mm and 3 mrad off per axis
    // (about what local mapping leaves), 40 observations per key frame, monocular and with
    // depth. The inertial-only refinement (ORB-SLAM3's `InertialOptimization`, poses held,
    // gravity held) from the same poses is the comparison: the window's velocities must be
    // closer to the truth, and its poses closer than where they started.
    let cal = rig_calibration();
    let cam = Pinhole { fx: FR3.fx, fy: FR3.fy, cx: FR3.cx, cy: FR3.cy };
    let gravity = Vector3::new(0.0, 0.0, -cal.gravity);
    for bf in [0.0, 40.0] {
        let (mut v_win, mut v_held, mut p_start, mut p_win) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for seed in 1..=3u64 {
            for start in [2.0, 4.0] {
                let s = scene(seed, start, 40, bf, 3e-3);
                let fit = optimize_window(&s.kfs, &s.between, &cam, bf, &cal, &gravity, Bias::default(), false);
                let held: Vec<InitKeyFrame> = s
                    .kfs
                    .iter()
                    .enumerate()
                    .map(|(k, kf)| InitKeyFrame {
                        stamp: 0.25 * k as f64,
                        world_from_cam: kf.world_from_body * cal.body_from_cam,
                    })
                    .collect();
                let config = InitConfig { gravity: Some(UnitQuaternion::identity()), ..InitConfig::with_depth() };
                let inertial_only = initialise(&held, &s.between, &cal.body_from_cam, cal.gravity, &config).unwrap();
                for (k, t) in s.truth.iter().enumerate() {
                    v_win.push((fit.states[k].velocity - t.velocity).norm());
                    v_held.push((inertial_only.velocities[k] - t.velocity).norm());
                    let p = t.world_from_body.translation.vector;
                    p_start.push((s.kfs[k].world_from_body.translation.vector - p).norm());
                    p_win.push((fit.states[k].world_from_body.translation.vector - p).norm());
                }
                let dropped = fit.inliers.iter().flatten().filter(|i| !**i).count();
                assert!(dropped <= 40, "{dropped} of 400 observations dropped (5 % expected by the chi-square bound)");
            }
        }
        let (v_win, v_held, p_start, p_win) =
            (rmse(v_win.into_iter()), rmse(v_held.into_iter()), rmse(p_start.into_iter()), rmse(p_win.into_iter()));
        println!(
            "bf {bf}: velocity RMSE window {:.1} mm/s, inertial-only (poses held) {:.1} mm/s; position RMSE {:.2} mm from {:.2} mm",
            v_win * 1e3,
            v_held * 1e3,
            p_win * 1e3,
            p_start * 1e3
        );
        assert!(v_win < 0.5 * v_held, "bf {bf}: window {v_win} m/s against poses held {v_held} m/s");
        assert!(p_win < 0.5 * p_start, "bf {bf}: positions {p_win} m from {p_start} m");
    }
}

#[test]
fn a_single_cameras_map_scale_is_found_from_the_imu() {
    // The same windows, monocular, in a map 6 % too large and 6 % too small (points and
    // starting positions divided by the factor; the velocities metric, as the IMU
    // initialisation leaves them): with the scale free the window finds the factor to 1 %;
    // with a metric map it stays within 1 % of one.
    let cal = rig_calibration();
    let cam = Pinhole { fx: FR3.fx, fy: FR3.fy, cx: FR3.cx, cy: FR3.cy };
    let gravity = Vector3::new(0.0, 0.0, -cal.gravity);
    let mut worst: f64 = 0.0;
    for factor in [1.0 / 1.06, 1.0, 1.06] {
        for seed in 1..=3u64 {
            for start in [2.0, 4.0] {
                let mut s = scene(seed, start, 40, 0.0, 1e-3);
                for kf in &mut s.kfs {
                    kf.world_from_body.translation.vector /= factor;
                    for o in &mut kf.observations {
                        o.point = Point3::from(o.point.coords / factor);
                    }
                }
                let fit = optimize_window(&s.kfs, &s.between, &cam, 0.0, &cal, &gravity, Bias::default(), true);
                let error = fit.scale / factor - 1.0;
                println!(
                    "map off by {factor:.4}, seed {seed}, from {start} s: scale {:.4}, error {:+.2} %",
                    fit.scale,
                    100.0 * error
                );
                worst = worst.max(error.abs());
            }
        }
    }
    assert!(worst <= 0.01, "scale error up to {:.2} %", 100.0 * worst);
}
