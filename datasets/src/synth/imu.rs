//! The synthetic camera's IMU: the exact angular rate and specific force of its motion, and
//! a noisy IMU with white noise and bias random walks at a datasheet's densities (EuRoC's
//! ADIS16448 by default: `ImuCalibration::adis16448`).
//!
//! The IMU's body frame is the camera's moved by `calibration.body_from_cam`. The rates come
//! from the motion model by central differences (step [`DIFF_STEP`]: truncation error of
//! order 1e-7 of the motion's own derivatives, far below any IMU's noise). World `z` is up,
//! gravity `-z` at `calibration.gravity`. A kidnap is a jump no IMU can measure: the samples
//! follow the motion model, not the kidnapped camera.

use nalgebra::{Isometry3, Vector3};

use dynaflow_base::rng::SplitMix64;
use dynaflow_msg::{ImuCalibration, ImuSample};

use super::{Generator, STAMP_BASE};

/// Central-difference step, seconds.
pub const DIFF_STEP: f64 = 1e-3;

/// The synthetic rig's IMU: EuRoC's ADIS16448 noise at 200 Hz, the camera mounted as EuRoC's
/// cam0 is, roughly: 7 cm from the IMU and turned a quarter about the IMU's `z`
/// (`T_BS` of EuRoC's `cam0/sensor.yaml` rounded). `dynaflow synth --format euroc` writes it.
pub fn rig_calibration() -> ImuCalibration {
    ImuCalibration {
        body_from_cam: Isometry3::from_parts(
            nalgebra::Translation3::new(-0.02, -0.065, 0.01),
            nalgebra::UnitQuaternion::from_scaled_axis(Vector3::z() * std::f64::consts::FRAC_PI_2),
        ),
        ..ImuCalibration::adis16448()
    }
}

impl Generator {
    /// `world_from_body` at `t` seconds after the start.
    pub fn body_pose(&self, t: f64, calibration: &ImuCalibration) -> Isometry3<f64> {
        self.config.motion.pose(t) * calibration.body_from_cam.inverse()
    }

    /// The body's velocity in the world at `t`, m/s.
    pub fn body_velocity(&self, t: f64, calibration: &ImuCalibration) -> Vector3<f64> {
        let h = DIFF_STEP;
        let p = |t: f64| self.body_pose(t, calibration).translation.vector;
        (p(t + h) - p(t - h)) / (2.0 * h)
    }

    /// The noise-free IMU at `t` seconds after the start (stamped on the sequence's clock).
    pub fn imu_truth(&self, t: f64, calibration: &ImuCalibration) -> ImuSample {
        let h = DIFF_STEP;
        let pose = |t: f64| self.body_pose(t, calibration);
        let (before, now, after) = (pose(t - h), pose(t), pose(t + h));
        let gyro = (before.rotation.inverse() * after.rotation).scaled_axis() / (2.0 * h);
        let accel_w = (after.translation.vector - 2.0 * now.translation.vector + before.translation.vector) / (h * h);
        let gravity = Vector3::new(0.0, 0.0, -calibration.gravity);
        ImuSample { stamp: STAMP_BASE + t, gyro, accel: now.rotation.inverse() * (accel_w - gravity) }
    }

    /// The IMU's samples from the start to `until` seconds (inclusive) at
    /// `calibration.rate_hz`: exact with `noisy` false; otherwise with white noise of
    /// standard deviation `density · √rate` per sample and biases that start at zero and walk
    /// by `random_walk · √dt · N(0, 1)` per sample, drawn from the scene seed's `"imu"` stream.
    pub fn imu(&self, calibration: &ImuCalibration, until: f64, noisy: bool) -> Vec<ImuSample> {
        self.imu_with_biases(calibration, until, noisy).into_iter().map(|(s, _)| s).collect()
    }

    /// [`Generator::imu`] with each sample's true biases (gyroscope, accelerometer): what
    /// EuRoC's ground truth states beside the pose.
    pub fn imu_with_biases(
        &self,
        calibration: &ImuCalibration,
        until: f64,
        noisy: bool,
    ) -> Vec<(ImuSample, [Vector3<f64>; 2])> {
        let rate = calibration.rate_hz;
        let n = (until * rate).floor() as u64;
        let dt = 1.0 / rate;
        let mut rng = SplitMix64::named(self.config.seed, "imu");
        let mut draw = move |sigma: f64| Vector3::new(rng.normal(), rng.normal(), rng.normal()) * sigma;
        let (white_g, white_a) =
            (calibration.gyro_noise_density * rate.sqrt(), calibration.accel_noise_density * rate.sqrt());
        let (walk_g, walk_a) = (calibration.gyro_random_walk * dt.sqrt(), calibration.accel_random_walk * dt.sqrt());
        let (mut bias_g, mut bias_a) = (Vector3::zeros(), Vector3::zeros());
        (0..=n)
            .map(|k| {
                let mut s = self.imu_truth(k as f64 * dt, calibration);
                let biases = [bias_g, bias_a];
                if noisy {
                    s.gyro += bias_g + draw(white_g);
                    s.accel += bias_a + draw(white_a);
                    bias_g += draw(walk_g);
                    bias_a += draw(walk_a);
                }
                (s, biases)
            })
            .collect()
    }
}
