//! `track_*`'s IMU input: the batches it refuses, and the summary's inertial entry.

use dynaflow_engine::msg::ImuSample;
use dynaflow_engine::op::OpError;
use dynaflow_slam::Tracker;

use super::Track;
use crate::report::InertialReport;

/// An IMU batch the tracker can integrate: finite values, stamps strictly increasing from
/// the previous batch's and none after its frame. The sources check their files by the rules
/// of `dynaflow_datasets::imu`; this refuses what reaches a tracker otherwise (a replayed or
/// remote stream), instead of integrating a wrong trajectory.
pub(super) fn check_imu_batch(samples: &[ImuSample], previous: Option<f64>, frame: f64) -> Result<(), OpError> {
    let mut last = previous;
    for s in samples {
        let finite = s.stamp.is_finite() && s.gyro.iter().chain(s.accel.iter()).all(|v| v.is_finite());
        let problem = if !finite {
            Some("a value that is not finite".to_owned())
        } else if let Some(l) = last.filter(|&l| s.stamp <= l) {
            Some(format!("not after the previous sample at {l:.6} s"))
        } else if s.stamp > frame {
            Some(format!("after its frame at {frame:.6} s"))
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(OpError::Input(format!(
                "`imu`: the sample at {:.6} s is {problem}: an inertial tracker integrates every sample in time order",
                s.stamp
            )));
        }
        last = Some(s.stamp);
    }
    Ok(())
}

impl Track {
    /// The IMU's initialisation and its final biases.
    pub(super) fn inertial_report(&self, tracker: &Tracker) -> InertialReport {
        let init = tracker.inertial_init();
        let estimate = tracker.inertial_estimate();
        InertialReport {
            init_method: init.map(|i| {
                match i.method {
                    dynaflow_slam::InitMethod::Static => "static",
                    dynaflow_slam::InitMethod::Map => "map",
                    dynaflow_slam::InitMethod::MapGravityAtRest => "map_gravity_at_rest",
                }
                .to_owned()
            }),
            init_after_s: init.zip(self.first_stamp).map(|(i, t0)| i.stamp - t0),
            init_keyframes: init.map(|i| i.keyframes),
            gyro_bias: estimate.map(|e| e.bias.gyro.into()),
            accel_bias: estimate.map(|e| e.bias.accel.into()),
            gravity: estimate.map(|e| e.gravity_w.into()),
            init_failure: if init.is_none() { tracker.inertial_init_failure().map(str::to_owned) } else { None },
            windows: tracker.inertial_windows(),
            inconsistent: tracker.inertial_inconsistent(),
            scale_refinements: tracker
                .scale_refinements()
                .iter()
                .map(|&(t, scale)| crate::report::ScaleRefinement { after_s: t - self.first_stamp.unwrap_or(t), scale })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn sample(stamp: f64) -> ImuSample {
        ImuSample { stamp, gyro: Vector3::zeros(), accel: Vector3::new(0.0, 0.0, 9.81) }
    }

    #[test]
    fn imu_batches_out_of_order_after_their_frame_or_not_finite_are_refused() {
        let ok = [sample(0.005), sample(0.010)];
        assert!(check_imu_batch(&ok, Some(0.0), 0.01).is_ok());
        let message = |samples: &[ImuSample], previous| match check_imu_batch(samples, previous, 0.02) {
            Err(OpError::Input(m)) => m,
            other => panic!("{other:?}"),
        };
        assert!(message(&ok, Some(0.005)).contains("not after the previous sample at 0.005000 s"));
        assert!(message(&[sample(0.01), sample(0.01)], None).contains("not after the previous sample"));
        assert!(message(&[sample(0.03)], None).contains("after its frame at 0.020000 s"));
        let mut nan = sample(0.015);
        nan.gyro.x = f64::NAN;
        assert!(message(&[nan], None).contains("not finite"));
    }
}
