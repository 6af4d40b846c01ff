#![allow(clippy::unwrap_used)]

use dynaflow_base::rng::SplitMix64;
use dynaflow_datasets::synth::{Generator, Motion, STAMP_BASE, SynthConfig, rig_calibration};
use nalgebra::{SVector, UnitQuaternion};

use super::*;

#[test]
fn the_propagated_state_covariance_matches_monte_carlo() {
    // Half a second of synth's hand-held motion at 200 Hz: a state known to (2 mrad, 2 cm/s,
    // 1 cm, 5e-3 rad/s, 5e-2 m/s²) per axis, and EuRoC's ADIS16448 white noise on every sample
    // (no bias walk, so the truth's bias stays zero), propagated 2000 times: the sample
    // covariance of the error against `propagate_covariance`, block by block, within 10 % (the
    // sampling error of a variance from 2000 runs is about 3 %).
    let cal = ImuCalibration { gyro_random_walk: 0.0, accel_random_walk: 0.0, ..rig_calibration() };
    let g = Generator::new(SynthConfig { motion: Motion::Handheld, ..SynthConfig::default() });
    let (ti, tj) = (2.0, 2.5);
    let samples = g.imu(&cal, tj + 0.01, false);
    let gravity = Vector3::new(0.0, 0.0, -cal.gravity);
    let truth_i =
        NavState { world_from_body: g.body_pose(ti, &cal), velocity: g.body_velocity(ti, &cal), bias: Bias::default() };
    let (pose_j, vel_j) = (g.body_pose(tj, &cal), g.body_velocity(tj, &cal));
    let sigma = [2e-3, 2e-2, 1e-2, 5e-3, 5e-2];
    let mut prior = Matrix15::zeros();
    for (block, s) in sigma.iter().enumerate() {
        for k in 0..3 {
            prior[(3 * block + k, 3 * block + k)] = s * s;
        }
    }
    let mut nominal = Preintegrated::new(Bias::default(), &cal);
    nominal.integrate_span(&samples, STAMP_BASE + ti, STAMP_BASE + tj);
    let predicted = propagate_covariance(&truth_i, &prior, &nominal, &cal);

    let mut rng = SplitMix64::named(5, "propagate");
    let mut draw = |s: f64| Vector3::new(rng.normal(), rng.normal(), rng.normal()) * s;
    let (white_g, white_a) =
        (cal.gyro_noise_density * cal.rate_hz.sqrt(), cal.accel_noise_density * cal.rate_hz.sqrt());
    let runs = 2000;
    let mut sum = Matrix15::zeros();
    for _ in 0..runs {
        let (dth, dv, dp, dbg, dba) = (draw(sigma[0]), draw(sigma[1]), draw(sigma[2]), draw(sigma[3]), draw(sigma[4]));
        let mut pose = truth_i.world_from_body;
        pose.rotation *= UnitQuaternion::from_scaled_axis(dth);
        pose.translation.vector += dp;
        let estimate =
            NavState { world_from_body: pose, velocity: truth_i.velocity + dv, bias: Bias { gyro: dbg, accel: dba } };
        let noisy: Vec<_> = samples
            .iter()
            .map(|s| dynaflow_msg::ImuSample { gyro: s.gyro + draw(white_g), accel: s.accel + draw(white_a), ..*s })
            .collect();
        let mut p = Preintegrated::new(estimate.bias, &cal);
        p.integrate_span(&noisy, STAMP_BASE + ti, STAMP_BASE + tj);
        let next = estimate.predict(&p, &gravity);
        let e_r = (pose_j.rotation.inverse() * next.world_from_body.rotation).scaled_axis();
        let (e_v, e_p) = (next.velocity - vel_j, next.world_from_body.translation.vector - pose_j.translation.vector);
        let e = SVector::<f64, 15>::from_iterator(
            e_r.iter().chain(e_v.iter()).chain(e_p.iter()).chain(dbg.iter()).chain(dba.iter()).copied(),
        );
        sum += e * e.transpose();
    }
    let sample = sum / f64::from(runs);
    for (name, i) in [("rotation", 0), ("velocity", 3), ("position", 6)] {
        let (a, b) = (sample.fixed_view::<3, 3>(i, i).trace(), predicted.fixed_view::<3, 3>(i, i).trace());
        println!("{name}: Monte Carlo {a:.3e}, propagated {b:.3e} ({:+.1} %)", (a / b - 1.0) * 100.0);
        assert!((a / b - 1.0).abs() < 0.1, "{name}: Monte Carlo {a:.3e}, propagated {b:.3e}");
    }
    // The couplings, as correlations (a cross block's trace sums terms of both signs, so its
    // relative error means little): within 0.05, about twice the sampling error of a
    // correlation from 2000 runs (1/√2000).
    for (name, i, j) in [("position-velocity", 6, 3), ("velocity-rotation", 3, 0)] {
        let norm = (predicted.fixed_view::<3, 3>(i, i).trace() * predicted.fixed_view::<3, 3>(j, j).trace()).sqrt();
        let (a, b) =
            (sample.fixed_view::<3, 3>(i, j).trace() / norm, predicted.fixed_view::<3, 3>(i, j).trace() / norm);
        println!("{name}: Monte Carlo {a:+.3}, propagated {b:+.3}");
        assert!((a - b).abs() < 0.05, "{name}: Monte Carlo {a:+.3}, propagated {b:+.3}");
        assert!(b.abs() > 0.05, "{name}: a coupling the test can see");
    }
    // Without the prior the error is the pre-integration's own, grown: far smaller.
    let alone = propagate_covariance(&truth_i, &Matrix15::zeros(), &nominal, &cal);
    assert!(alone.fixed_view::<3, 3>(6, 6).trace() < 0.01 * predicted.fixed_view::<3, 3>(6, 6).trace());
}

#[test]
fn the_bias_walk_grows_the_bias_variance_linearly_in_time() {
    let cal = rig_calibration();
    let g = Generator::new(SynthConfig { motion: Motion::Handheld, ..SynthConfig::default() });
    let samples = g.imu(&cal, 3.0, false);
    let state = NavState {
        world_from_body: g.body_pose(2.0, &cal),
        velocity: g.body_velocity(2.0, &cal),
        bias: Bias::default(),
    };
    let mut p = Preintegrated::new(Bias::default(), &cal);
    p.integrate_span(&samples, STAMP_BASE + 2.0, STAMP_BASE + 2.8);
    let c = propagate_covariance(&state, &Matrix15::zeros(), &p, &cal);
    assert!((c[(9, 9)] - cal.gyro_random_walk.powi(2) * 0.8).abs() < 1e-15);
    assert!((c[(14, 14)] - cal.accel_random_walk.powi(2) * 0.8).abs() < 1e-12);
}
