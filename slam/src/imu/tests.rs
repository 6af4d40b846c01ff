#![allow(clippy::unwrap_used)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::*;

const G: f64 = dynaflow_msg::STANDARD_GRAVITY;

fn gravity() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -G)
}

/// A hand-held-like motion in closed form: `R(t) = Exp(φ(t))`, so the body rate is exactly
/// `Jr(φ) φ̇`; position a sum of sines, so the acceleration is exact too.
struct Motion;

impl Motion {
    fn phi(t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let phi = Vector3::new(0.3 * (1.1 * t).sin(), 0.2 * (0.7 * t).sin() + 0.1, 0.4 * (0.9 * t).sin());
        let dphi = Vector3::new(0.33 * (1.1 * t).cos(), 0.14 * (0.7 * t).cos(), 0.36 * (0.9 * t).cos());
        (phi, dphi)
    }

    fn pose(t: f64) -> Isometry3<f64> {
        let p = Vector3::new(0.5 * (0.8 * t).sin(), 0.3 * (1.3 * t).cos(), 0.2 * (2.0 * t).sin());
        Isometry3::from_parts(Translation3::from(p), UnitQuaternion::from_scaled_axis(Self::phi(t).0))
    }

    fn velocity(t: f64) -> Vector3<f64> {
        Vector3::new(0.4 * (0.8 * t).cos(), -0.39 * (1.3 * t).sin(), 0.4 * (2.0 * t).cos())
    }

    fn acceleration(t: f64) -> Vector3<f64> {
        Vector3::new(-0.32 * (0.8 * t).sin(), -0.507 * (1.3 * t).cos(), -0.8 * (2.0 * t).sin())
    }

    /// The noise-free IMU at time `t` (body = IMU frame).
    fn sample(t: f64) -> ImuSample {
        let (phi, dphi) = Self::phi(t);
        let r = Self::pose(t).rotation;
        ImuSample {
            stamp: t,
            gyro: right_jacobian(&phi) * dphi,
            accel: r.inverse() * (Self::acceleration(t) - gravity()),
        }
    }
}

fn samples(rate: f64, from: f64, to: f64) -> Vec<ImuSample> {
    let n = ((to - from) * rate).round() as usize;
    (0..=n).map(|k| Motion::sample(from + k as f64 / rate)).collect()
}

/// Rotation (rad) and position (m) error of the pre-integrated prediction over `[from, to]`.
fn prediction_error(rate: f64, from: f64, to: f64) -> (f64, f64) {
    let mut p = Preintegrated::new(Bias::default(), &ImuCalibration::adis16448());
    p.integrate_span(&samples(rate, from, to), from, to);
    assert!((p.delta_t() - (to - from)).abs() < 1e-9);
    let (pose, _) = p.predict(&Motion::pose(from), &Motion::velocity(from), &gravity());
    let truth = Motion::pose(to);
    ((pose.rotation.inverse() * truth.rotation).angle(), (pose.translation.vector - truth.translation.vector).norm())
}

#[test]
fn noise_free_samples_reproduce_the_motion_and_the_error_falls_at_second_order() {
    let errors: Vec<(f64, f64)> = [200.0, 400.0, 800.0].iter().map(|&r| prediction_error(r, 0.3, 1.3)).collect();
    println!("rotation and position errors over 1 s at 200, 400, 800 Hz: {errors:?}");
    let (rot, pos) = errors[0];
    assert!(rot <= 1e-3 && pos <= 1e-3, "200 Hz over 1 s: {rot:.2e} rad, {pos:.2e} m");
    for w in errors.windows(2) {
        // Second order: a fourfold drop as the rate doubles.
        let (r, p) = (w[0].0 / w[1].0, w[0].1 / w[1].1);
        assert!((3.5..4.6).contains(&r) && (3.5..4.6).contains(&p), "{errors:?}: ratios {r:.2}, {p:.2}");
    }
}

/// The residuals of the first-order bias correction against integrating again at the new
/// bias, and the sizes of the corrections (rotation rad, velocity m/s, position m).
fn bias_correction_error(scale: f64) -> ([f64; 3], [f64; 3]) {
    let s = samples(200.0, 0.0, 1.0);
    let mut first = Preintegrated::new(Bias::default(), &ImuCalibration::adis16448());
    first.integrate_span(&s, 0.0, 1.0);
    let before = (first.delta_rotation(), first.delta_velocity(), first.delta_position());
    let bias =
        Bias { gyro: Vector3::new(0.003, -0.002, 0.004) * scale, accel: Vector3::new(0.03, 0.02, -0.04) * scale };
    assert!(!first.set_bias(bias), "within the re-integration thresholds");
    let mut again = Preintegrated::new(bias, &ImuCalibration::adis16448());
    again.integrate_span(&s, 0.0, 1.0);
    let residual = [
        (first.delta_rotation().inverse() * again.delta_rotation()).angle(),
        (first.delta_velocity() - again.delta_velocity()).norm(),
        (first.delta_position() - again.delta_position()).norm(),
    ];
    let correction = [
        (before.0.inverse() * first.delta_rotation()).angle(),
        (first.delta_velocity() - before.1).norm(),
        (first.delta_position() - before.2).norm(),
    ];
    (residual, correction)
}

#[test]
fn the_first_order_bias_update_agrees_with_reintegration_to_second_order() {
    // A first-order expansion leaves a remainder quadratic in the change: a quarter when the
    // change halves, and small beside the correction itself (its ratio to it shrinks with
    // the change; at these changes, up to half of VINS-Mono's re-integration thresholds,
    // under 1 %).
    let (big, correction) = bias_correction_error(1.0);
    let (small, _) = bias_correction_error(0.5);
    for (i, name) in ["rotation", "velocity", "position"].iter().enumerate() {
        let (b, s, c) = (big[i], small[i], correction[i]);
        println!("{name}: correction {c:.3e}, residual {b:.3e} (half the change: {s:.3e})");
        assert!((3.5..4.5).contains(&(b / s)), "{name}: {b:.3e} at the full change, {s:.3e} at half");
        assert!(b <= 0.01 * c, "{name}: residual {b:.3e} against a correction of {c:.3e}");
    }
}

#[test]
fn a_bias_beyond_the_thresholds_is_integrated_again() {
    let s = samples(200.0, 0.0, 0.5);
    let mut p = Preintegrated::new(Bias::default(), &ImuCalibration::adis16448());
    p.integrate_span(&s, 0.0, 0.5);
    let bias = Bias { gyro: Vector3::new(0.02, 0.0, 0.0), accel: Vector3::zeros() };
    assert!(p.set_bias(bias));
    assert_eq!(p.linearised_bias(), bias);
    let mut direct = Preintegrated::new(bias, &ImuCalibration::adis16448());
    direct.integrate_span(&s, 0.0, 0.5);
    assert_eq!(p.delta_rotation(), direct.delta_rotation());
    assert_eq!(p.delta_position(), direct.delta_position());
}

#[test]
fn the_propagated_covariance_matches_monte_carlo() {
    // White noise at the ADIS16448's densities, held over each 5 ms interval (variance
    // density² / dt), integrated 2000 times: the sample covariance of the deltas against the
    // propagated one, block by block (rotation, velocity, position), within 10 %.
    let calibration = ImuCalibration::adis16448();
    let dt = 1.0 / calibration.rate_hz;
    let truth: Vec<ImuSample> = (0..200).map(|k| Motion::sample(k as f64 * dt)).collect();
    let mut nominal = Preintegrated::new(Bias::default(), &calibration);
    for s in &truth {
        nominal.integrate(s.gyro, s.accel, dt);
    }
    let (sg, sa) = (calibration.gyro_noise_density / dt.sqrt(), calibration.accel_noise_density / dt.sqrt());
    let mut rng = dynaflow_base::rng::SplitMix64::new(7);
    let mut normal = move || rng.normal();
    let runs = 2000;
    let mut sum = Matrix9::zeros();
    for _ in 0..runs {
        let mut p = Preintegrated::new(Bias::default(), &calibration);
        for s in &truth {
            let ng = Vector3::new(normal(), normal(), normal()) * sg;
            let na = Vector3::new(normal(), normal(), normal()) * sa;
            p.integrate(s.gyro + ng, s.accel + na, dt);
        }
        // The error in the tangent space of ΔR, and of Δv and Δp (the covariance's order).
        let e_r = (nominal.delta_rotation().inverse() * p.delta_rotation()).scaled_axis();
        let (e_v, e_p) = (p.delta_velocity() - nominal.delta_velocity(), p.delta_position() - nominal.delta_position());
        let e = nalgebra::SVector::<f64, 9>::from_iterator(e_r.iter().chain(e_v.iter()).chain(e_p.iter()).copied());
        sum += e * e.transpose();
    }
    let sample = sum / f64::from(runs);
    let c = nominal.covariance();
    for (name, i) in [("rotation", 0), ("velocity", 3), ("position", 6)] {
        let (a, b) = (sample.fixed_view::<3, 3>(i, i).trace(), c.fixed_view::<3, 3>(i, i).trace());
        println!("{name}: Monte Carlo {a:.3e}, propagated {b:.3e} ({:+.1} %)", (a / b - 1.0) * 100.0);
        assert!((a / b - 1.0).abs() < 0.1, "{name}: Monte Carlo {a:.3e}, propagated {b:.3e}");
    }
}

#[test]
fn the_synthetic_noise_free_imu_reproduces_the_generators_relative_poses() {
    // `synth`'s IMU (rates by central differences of its motion model) pre-integrated over
    // 1 s at 200 Hz, from the generator's body pose and velocity: its pose 1 s later.
    use dynaflow_datasets::synth::{Generator, Motion, STAMP_BASE, SynthConfig};
    let calibration = ImuCalibration::adis16448();
    let mut worst = (0.0f64, 0.0f64);
    for motion in [Motion::Xyz, Motion::Halfsphere, Motion::Loop, Motion::Handheld] {
        let g = Generator::new(SynthConfig { motion, ..SynthConfig::default() });
        let samples = g.imu(&calibration, 12.0, false);
        for start in [0.5, 3.0, 7.25, 10.0] {
            let (from, to) = (STAMP_BASE + start, STAMP_BASE + start + 1.0);
            let mut p = Preintegrated::new(Bias::default(), &calibration);
            p.integrate_span(&samples, from, to);
            let (pose, _) = p.predict(
                &g.body_pose(start, &calibration),
                &g.body_velocity(start, &calibration),
                &Vector3::new(0.0, 0.0, -calibration.gravity),
            );
            let truth = g.body_pose(start + 1.0, &calibration);
            let rot = (pose.rotation.inverse() * truth.rotation).angle();
            let pos = (pose.translation.vector - truth.translation.vector).norm();
            assert!(rot <= 1e-3 && pos <= 1e-3, "{motion:?} from {start} s: {rot:.2e} rad, {pos:.2e} m");
            worst = (worst.0.max(rot), worst.1.max(pos));
        }
    }
    println!("synth IMU, 200 Hz, 1 s: worst {:.2e} rad, {:.2e} m", worst.0, worst.1);
}
