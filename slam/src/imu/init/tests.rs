#![allow(clippy::unwrap_used)]

use dynaflow_base::rng::SplitMix64;
use dynaflow_datasets::synth::{Generator, HANDHELD_REST, Motion, STAMP_BASE, SynthConfig, rig_calibration};
use nalgebra::{UnitQuaternion, Vector3};

use super::*;

struct Truth {
    /// Metres per visual unit.
    scale: f64,
    /// Gravity's direction in the visual map.
    down: Vector3<f64>,
    velocities: Vec<Vector3<f64>>,
}

struct Window {
    keyframes: Vec<InitKeyFrame>,
    preintegrated: Vec<Preintegrated>,
    truth: Truth,
}

/// Noise added to an IMU and to the visual poses.
#[derive(Clone, Copy)]
struct Noise {
    imu: bool,
    gyro_bias: Vector3<f64>,
    accel_bias: Vector3<f64>,
    /// Per-axis standard deviations of the visual poses' errors: rad, metres.
    rotation: f64,
    position: f64,
}

const CLEAN: Noise = Noise {
    imu: false,
    gyro_bias: Vector3::new(0.0, 0.0, 0.0),
    accel_bias: Vector3::new(0.0, 0.0, 0.0),
    rotation: 0.0,
    position: 0.0,
};

/// Key frames at 10 Hz over `seconds` of `synth`'s hand-held motion from when it starts
/// moving, their poses in a visual map whose origin is the first key frame's camera and whose
/// unit is `1 / scale` metres (`scale` 1: a metric map), with the pre-integrations between them.
fn window(seed: u64, seconds: f64, scale: f64, noise: Noise) -> Window {
    window_every(seed, seconds, 0.1, scale, noise)
}

/// As [`window`], key frames every `spacing` seconds.
fn window_every(seed: u64, seconds: f64, spacing: f64, scale: f64, noise: Noise) -> Window {
    let g = Generator::new(SynthConfig { motion: Motion::Handheld, seed, ..SynthConfig::default() });
    let cal = rig_calibration();
    let start = HANDHELD_REST;
    let mut samples = g.imu(&cal, start + seconds + 0.1, noise.imu);
    for s in &mut samples {
        s.gyro += noise.gyro_bias;
        s.accel += noise.accel_bias;
    }
    let times: Vec<f64> = (0..=(seconds / spacing).round() as usize).map(|k| start + k as f64 * spacing).collect();
    let origin = g.config().motion.pose(start).inverse();
    let mut rng = SplitMix64::named(seed, "visual");
    let mut keyframes = Vec::new();
    for &t in &times {
        let mut pose = origin * g.config().motion.pose(t);
        let dr = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * noise.rotation;
        let dp = Vector3::new(rng.normal(), rng.normal(), rng.normal()) * noise.position;
        pose.rotation = UnitQuaternion::from_scaled_axis(dr) * pose.rotation;
        pose.translation.vector = (pose.translation.vector + dp) / scale;
        keyframes.push(InitKeyFrame { stamp: STAMP_BASE + t, world_from_cam: pose });
    }
    let preintegrated = times
        .windows(2)
        .map(|w| {
            let mut p = Preintegrated::new(Bias::default(), &cal);
            p.integrate_span(&samples, STAMP_BASE + w[0], STAMP_BASE + w[1]);
            p
        })
        .collect();
    let truth = Truth {
        scale,
        down: origin.rotation * Vector3::new(0.0, 0.0, -1.0),
        velocities: times.iter().map(|&t| origin.rotation * g.body_velocity(t, &cal)).collect(),
    };
    Window { keyframes, preintegrated, truth }
}

struct Errors {
    scale: f64,
    gravity: f64,
    velocity: f64,
}

fn errors(init: &InertialInit, truth: &Truth) -> Errors {
    let down = init.world_from_gravity * Vector3::new(0.0, 0.0, -1.0);
    Errors {
        scale: (init.scale / truth.scale - 1.0).abs(),
        gravity: down.angle(&truth.down),
        velocity: init.velocities.iter().zip(&truth.velocities).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max),
    }
}

fn run(w: &Window, config: &InitConfig) -> InertialInit {
    initialise(&w.keyframes, &w.preintegrated, &rig_calibration().body_from_cam, rig_calibration().gravity, config)
        .unwrap()
}

#[test]
fn exact_poses_and_a_noise_free_imu_give_back_scale_gravity_and_velocities() {
    // A monocular map 2.5 times too small, and a metric one with the scale held: the solution
    // is the truth to the pre-integration's own error (1e-6 over these spans).
    for (scale, config) in [(2.5, InitConfig::monocular()), (1.0, InitConfig::with_depth())] {
        let w = window(0, 2.0, scale, CLEAN);
        let init = run(&w, &config);
        let e = errors(&init, &w.truth);
        println!(
            "exact, scale {scale}: scale {:.1e}, gravity {:.1e} rad, velocity {:.1e} m/s, biases {:.1e} {:.1e}, {} iterations",
            e.scale,
            e.gravity,
            e.velocity,
            init.bias.gyro.norm(),
            init.bias.accel.norm(),
            init.iterations
        );
        assert!(
            e.scale < 1e-4 && e.gravity < 1e-4 && e.velocity < 1e-3,
            "scale {}, gravity {}, velocity {}",
            e.scale,
            e.gravity,
            e.velocity
        );
        assert!(init.bias.gyro.norm() < 1e-4, "gyro bias {}", init.bias.gyro);
    }
}

#[test]
fn noisy_motion_gives_scale_within_five_percent_after_two_seconds_and_two_after_five() {
    // EuRoC's ADIS16448 noise and bias walks, a constant gyroscope bias of 0.026 rad/s (1.5°/s),
    // a small accelerometer bias, and visual poses off by 1 mrad and 1 mm per axis (a locally
    // bundle-adjusted map), key frames every 0.25 s (ORB-SLAM3's inertial key-frame interval).
    // The poses are held fixed, so their noise enters as errors in the variables: its second
    // difference, σ·√6/Δt², must stay well below the motion's acceleration (about 1 m/s² here);
    // at 10 Hz with 3 mm the scale comes out 55-65 % short (docs/benchmarks.md). As in
    // ORB-SLAM3, the first estimate (2 s) is refined once the key frames span 5 s. Bounds
    // chosen: 5 % and 2 % (the system's target); seeds 1-3, never used for choosing anything.
    let noise = Noise {
        imu: true,
        gyro_bias: Vector3::new(0.01, -0.02, 0.015),
        accel_bias: Vector3::new(0.03, -0.02, 0.02),
        rotation: 1e-3,
        position: 1e-3,
    };
    for seed in 1..=3 {
        for (seconds, config, bound) in
            [(2.0, InitConfig::monocular(), 0.05), (5.0, InitConfig::monocular_refinement(), 0.02)]
        {
            let w = window_every(seed, seconds, 0.25, 2.5, noise);
            let init = run(&w, &config);
            let e = errors(&init, &w.truth);
            let gyro = (init.bias.gyro - noise.gyro_bias).norm();
            println!(
                "{seconds} s, seed {seed}: scale {:.2} % (σ {:.2} %), gravity {:.3}°, velocity {:.3} m/s, gyro bias off by {gyro:.1e} rad/s",
                e.scale * 100.0,
                init.scale_sigma / init.scale * 100.0,
                e.gravity.to_degrees(),
                e.velocity
            );
            assert!(e.scale <= bound, "{seconds} s, seed {seed}: scale error {:.2} %", e.scale * 100.0);
            assert!(e.gravity <= 1f64.to_radians(), "seed {seed}: gravity {:.3}°", e.gravity.to_degrees());
            assert!(gyro <= 2e-3, "seed {seed}: gyro bias {} against {}", init.bias.gyro, noise.gyro_bias);
        }
        // With depth (scale held), two seconds.
        let w = window_every(seed, 2.0, 0.25, 1.0, noise);
        let init = run(&w, &InitConfig::with_depth());
        let e = errors(&init, &w.truth);
        println!(
            "2 s, seed {seed}, with depth: gravity {:.3}°, velocity {:.3} m/s",
            e.gravity.to_degrees(),
            e.velocity
        );
        assert!(
            init.scale == 1.0 && e.gravity <= 1f64.to_radians(),
            "seed {seed} with depth: gravity {:.3}°",
            e.gravity.to_degrees()
        );
        assert!(e.velocity <= 0.05, "seed {seed} with depth: velocity off by {:.3} m/s", e.velocity);
    }
}

#[test]
fn malformed_windows_are_refused() {
    let w = window(0, 0.2, 1.0, CLEAN);
    let cal = rig_calibration();
    let config = InitConfig::monocular();
    let err = initialise(&w.keyframes[..2], &w.preintegrated[..1], &cal.body_from_cam, cal.gravity, &config);
    assert!(matches!(err, Err(InitError::TooFewKeyFrames { keyframes: 2, preintegrated: 1 })), "{err:?}");
    let err = initialise(&w.keyframes, &w.preintegrated[..1], &cal.body_from_cam, cal.gravity, &config);
    assert!(matches!(err, Err(InitError::TooFewKeyFrames { .. })), "{err:?}");
    // A pre-integration that does not span its key frames' interval.
    let mut pre = w.preintegrated.clone();
    pre[1] = Preintegrated::new(Bias::default(), &cal);
    let err = initialise(&w.keyframes, &pre, &cal.body_from_cam, cal.gravity, &config);
    assert!(matches!(err, Err(InitError::BadSpan { index: 1, .. })), "{err:?}");
}

#[test]
fn at_rest_gravity_and_the_gyro_bias_come_from_the_means_and_motion_is_refused() {
    let cal = rig_calibration();
    let bias = Vector3::new(0.004, -0.003, 0.002);
    for seed in 1..=3 {
        let g = Generator::new(SynthConfig { motion: Motion::Handheld, seed, ..SynthConfig::default() });
        let mut samples = g.imu(&cal, 3.0, true);
        for s in &mut samples {
            s.gyro += bias;
        }
        // The rest before the motion eases in.
        let rest: Vec<_> = samples.iter().filter(|s| s.stamp - STAMP_BASE < HANDHELD_REST * 0.9).copied().collect();
        let init = static_initialise(&rest, &cal).unwrap();
        let truth = g.body_pose(0.0, &cal).rotation;
        // The estimate's up axis in the body against the truth's.
        let up = |r: UnitQuaternion<f64>| r.inverse() * Vector3::z();
        let tilt = up(init.gravity_from_body).angle(&up(truth));
        let gyro = (init.gyro_bias - bias).norm();
        println!("seed {seed}: tilt {tilt:.1e} rad, gyro bias off by {gyro:.1e} rad/s, |a| {:.4}", init.accel_norm);
        // The mean of 180 samples: 2e-3 m/s² of white noise against 9.8 (2e-4 rad); the gyro
        // mean 1.8e-4 rad/s per axis.
        assert!(tilt <= 2e-3, "seed {seed}: tilt {tilt}");
        assert!(gyro <= 1e-3, "seed {seed}: gyro bias {}", init.gyro_bias);
        // Two seconds later it moves: refused, naming the sensor.
        let moving: Vec<_> = samples.iter().filter(|s| (2.0..2.5).contains(&(s.stamp - STAMP_BASE))).copied().collect();
        let err = static_initialise(&moving, &cal);
        assert!(matches!(err, Err(InitError::Moving { .. })), "seed {seed}: {err:?}");
    }
    let err = static_initialise(&[], &cal);
    assert!(matches!(err, Err(InitError::TooFewSamples { got: 0, .. })), "{err:?}");
}
