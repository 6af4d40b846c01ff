//! Per-frame cost of the inertial parts, single thread, on synth's hand-held motion with the
//! rig's 200 Hz IMU and a 30 Hz camera: pre-integrating a frame's samples, predicting the
//! state and carrying its covariance (IMU-only propagation), tracking one frame against the
//! last key frame with its observations (beside motion-only BA on the same observations,
//! what a vision-only tracker pays), the one-off inertial initialisation (2 s of key
//! frames every 0.25 s), and the visual-inertial window run at each window key frame (10 key
//! frames 0.25 s apart, 100 observations each; with a single camera's scale free beside it).
//!
//! `cargo bench --bench inertial` (add `-- REPS`, default 200). No peer runs here: the
//! visual-inertial peer (ORB-SLAM3 or another EuRoC-reading system) is the whole-system one
//! and is not built yet.
#![allow(clippy::unwrap_used, clippy::panic)]

#[path = "../slam/src/imu/track/observations.rs"]
mod observations;
#[path = "common/timing.rs"]
mod timing;

use observations::observations;
use timing::median_ms;

use dynaflow_datasets::synth::{FR3, Generator, HANDHELD_REST, Motion, STAMP_BASE, SynthConfig, rig_calibration};
use dynaflow_slam::imu::init::{InitConfig, InitKeyFrame, initialise};
use dynaflow_slam::imu::propagate::{Matrix15, NavState, propagate_covariance};
use dynaflow_slam::imu::track::optimize_inertial_pose;
use dynaflow_slam::imu::window::{WindowKeyFrame, optimize_window};
use dynaflow_slam::imu::{Bias, Preintegrated};
use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{SplitMix64, optimize_pose};
use nalgebra::Vector3;

fn main() {
    let reps: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(200);
    let cal = rig_calibration();
    let g = Generator::new(SynthConfig { motion: Motion::Handheld, ..SynthConfig::default() });
    let samples = g.imu(&cal, 6.0, true);
    let gravity = Vector3::new(0.0, 0.0, -cal.gravity);
    let (ti, tj) = (3.0, 3.0 + 1.0 / 30.0);
    println!("single thread, median of {reps} runs; 200 Hz IMU, 30 Hz camera (6-7 samples a frame)");

    let integrate = median_ms(reps, || {
        let mut p = Preintegrated::new(Bias::default(), &cal);
        p.integrate_span(&samples, STAMP_BASE + ti, STAMP_BASE + tj);
        std::hint::black_box(p.delta_t());
    });
    let mut frame = Preintegrated::new(Bias::default(), &cal);
    frame.integrate_span(&samples, STAMP_BASE + ti, STAMP_BASE + tj);
    let state =
        NavState { world_from_body: g.body_pose(ti, &cal), velocity: g.body_velocity(ti, &cal), bias: Bias::default() };
    let prior = Matrix15::identity() * 1e-4;
    let propagate = median_ms(reps, || {
        let next = state.predict(&frame, &gravity);
        std::hint::black_box((next, propagate_covariance(&state, &prior, &frame, &cal)));
    });

    // Tracking 0.2 s after the last key frame, 100 observations (a tenth outliers).
    let tk = ti + 0.2;
    let mut since_kf = Preintegrated::new(Bias::default(), &cal);
    since_kf.integrate_span(&samples, STAMP_BASE + ti, STAMP_BASE + tk);
    let cam = Pinhole { fx: FR3.fx, fy: FR3.fy, cx: FR3.cx, cy: FR3.cy };
    let world_from_cam = g.body_pose(tk, &cal) * cal.body_from_cam;
    let obs = observations(&world_from_cam, &cam, 100, &mut SplitMix64::new(1));
    let predicted = state.predict(&since_kf, &gravity);
    let track = median_ms(reps, || {
        std::hint::black_box(optimize_inertial_pose(
            &obs,
            &cam,
            0.0,
            &cal.body_from_cam,
            &state,
            &since_kf,
            &gravity,
            &predicted,
            None,
        ));
    });
    let start = (predicted.world_from_body * cal.body_from_cam).inverse();
    let motion_only = median_ms(reps, || {
        std::hint::black_box(optimize_pose(&obs, &cam, 0.0, &start, None));
    });

    // Initialisation: 2 s of key frames every 0.25 s from when the motion starts.
    let times: Vec<f64> = (0..=8).map(|k| HANDHELD_REST + 0.25 * f64::from(k)).collect();
    let origin = Motion::Handheld.pose(HANDHELD_REST).inverse();
    let keyframes: Vec<InitKeyFrame> = times
        .iter()
        .map(|&t| InitKeyFrame { stamp: STAMP_BASE + t, world_from_cam: origin * Motion::Handheld.pose(t) })
        .collect();
    let pre: Vec<Preintegrated> = times
        .windows(2)
        .map(|w| {
            let mut p = Preintegrated::new(Bias::default(), &cal);
            p.integrate_span(&samples, STAMP_BASE + w[0], STAMP_BASE + w[1]);
            p
        })
        .collect();
    let init = median_ms(reps.min(50), || {
        std::hint::black_box(
            initialise(&keyframes, &pre, &cal.body_from_cam, cal.gravity, &InitConfig::monocular()).unwrap(),
        );
    });

    // The visual-inertial window: 10 key frames 0.25 s apart, 100 observations each.
    let wtimes: Vec<f64> = (0..10).map(|k| 2.5 + 0.25 * f64::from(k)).collect();
    let mut rng = SplitMix64::new(2);
    let window: Vec<WindowKeyFrame> = wtimes
        .iter()
        .map(|&t| WindowKeyFrame {
            world_from_body: g.body_pose(t, &cal),
            velocity: g.body_velocity(t, &cal),
            observations: observations(&(g.body_pose(t, &cal) * cal.body_from_cam), &cam, 100, &mut rng),
        })
        .collect();
    let wpre: Vec<Preintegrated> = wtimes
        .windows(2)
        .map(|w| {
            let mut p = Preintegrated::new(Bias::default(), &cal);
            p.integrate_span(&samples, STAMP_BASE + w[0], STAMP_BASE + w[1]);
            p
        })
        .collect();
    let window_ms = |free_scale: bool| {
        median_ms(reps.min(50), || {
            std::hint::black_box(optimize_window(
                &window,
                &wpre,
                &cam,
                0.0,
                &cal,
                &gravity,
                Bias::default(),
                free_scale,
            ));
        })
    };
    let (window_fixed, window_scale) = (window_ms(false), window_ms(true));

    println!("{:<58} {:>10}", "step", "ms");
    println!("{:<58} {:>10.4}", "pre-integrate one frame's samples", integrate);
    println!("{:<58} {:>10.4}", "predict the state and propagate its 15x15 covariance", propagate);
    println!("{:<58} {:>10.4}", "track one frame: pose + velocity, 100 observations + IMU", track);
    println!("{:<58} {:>10.4}", "motion-only BA, the same 100 observations (vision alone)", motion_only);
    println!("{:<58} {:>10.4}", "inertial initialisation, 9 key frames (once)", init);
    println!("{:<58} {:>10.4}", "visual-inertial window, 10 key frames x 100 observations", window_fixed);
    println!("{:<58} {:>10.4}", "the same, a single camera's scale free", window_scale);
    println!("tracking with the IMU / without: {:.2}x", track / motion_only);
}
