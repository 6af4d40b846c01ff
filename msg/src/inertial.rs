//! Inertial measurements: IMU samples and the IMU's calibration (noise model, rate,
//! extrinsic, gravity). Units are SI: rad/s, m/s², seconds.

use nalgebra::{Isometry3, Vector3};

use super::Digest;

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

/// What an `imu` port carries per frame: the IMU samples stamped after the previous frame up
/// to this one (each sample in exactly one batch), and the IMU's calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct ImuBatch {
    /// The samples, strictly increasing in stamp.
    pub samples: Vec<ImuSample>,
    /// The IMU's noise model, rate, mounting and gravity.
    pub calibration: ImuCalibration,
}

impl ImuBatch {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        let c = &self.calibration;
        for v in
            [c.gyro_noise_density, c.accel_noise_density, c.gyro_random_walk, c.accel_random_walk, c.rate_hz, c.gravity]
        {
            d.f64(v);
        }
        let t = c.body_from_cam.translation.vector;
        let q = c.body_from_cam.rotation.coords;
        for v in t.iter().chain(q.iter()) {
            d.f64(*v);
        }
        d.u64(self.samples.len() as u64);
        for s in &self.samples {
            d.f64(s.stamp);
            for v in s.gyro.iter().chain(s.accel.iter()) {
                d.f64(*v);
            }
        }
    }
}
