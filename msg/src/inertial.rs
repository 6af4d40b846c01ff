//! Inertial measurements: IMU samples and the IMU's calibration (noise model, rate,
//! extrinsic, gravity). Units are SI: rad/s, m/s², seconds.

use nalgebra::{Isometry3, Vector3};

/// One IMU sample: angular rate and specific force (what an accelerometer measures: the
/// acceleration minus gravity) in the IMU's body frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    /// Time, seconds (the sensor clock the camera stamps share).
    pub stamp: f64,
    /// Angular rate, rad/s.
    pub gyro: Vector3<f64>,
    /// Specific force, m/s².
    pub accel: Vector3<f64>,
}

/// The continuous-time noise model of an IMU (as Kalibr and EuRoC's `sensor.yaml` give it)
/// and its mounting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuCalibration {
    /// Gyroscope white noise density, rad/s/√Hz.
    pub gyro_noise_density: f64,
    /// Accelerometer white noise density, m/s²/√Hz.
    pub accel_noise_density: f64,
    /// Gyroscope bias random walk, rad/s²/√Hz.
    pub gyro_random_walk: f64,
    /// Accelerometer bias random walk, m/s³/√Hz.
    pub accel_random_walk: f64,
    /// Sample rate, Hz.
    pub rate_hz: f64,
    /// The camera's pose in the IMU body frame (`T_BS` of EuRoC's camera `sensor.yaml`).
    pub body_from_cam: Isometry3<f64>,
    /// Magnitude of gravity, m/s².
    pub gravity: f64,
}

impl ImuCalibration {
    /// EuRoC MAV's ADIS16448 at 200 Hz, as its `imu0/sensor.yaml` states the noise
    /// (Burri et al., "The EuRoC micro aerial vehicle datasets", IJRR 2016), with the camera
    /// at the IMU (`body_from_cam` identity) and standard gravity.
    pub fn adis16448() -> Self {
        Self {
            gyro_noise_density: 1.6968e-4,
            accel_noise_density: 2.0e-3,
            gyro_random_walk: 1.9393e-5,
            accel_random_walk: 3.0e-3,
            rate_hz: 200.0,
            body_from_cam: Isometry3::identity(),
            gravity: STANDARD_GRAVITY,
        }
    }
}

/// Standard gravity (CGPM 1901), m/s².
pub const STANDARD_GRAVITY: f64 = 9.806_65;
