//! A bag's IMU for a visual-inertial run: the `sensor_msgs/Imu` topic's samples (header stamps)
//! checked by the rules a EuRoC folder's `imu0` follows ([`dynaflow_datasets::imu`]: out of
//! order or two readings at one instant refused, repeats dropped and counted, gaps over ten
//! periods refused), cut into one batch per frame (frame `i` gets the samples in
//! `(t[i-1], t[i]]`), with the calibration. A bag holds no noise figures, so they are given
//! (`imu_noise`, Kalibr's four numbers); the mounting comes from the tf tree (the IMU's frame
//! to the camera's) or is given (`imu_extrinsic`).

use std::collections::HashMap;
use std::path::Path;

use dynaflow_datasets::intrinsics::numbers_of;
use dynaflow_msg::{ImuCalibration, ImuSample, STANDARD_GRAVITY};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

use crate::tf::TfTree;

/// What the bag cannot say about its IMU.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImuOptions {
    /// `[gyroscope noise density (rad/s/√Hz), accelerometer noise density (m/s²/√Hz),
    /// gyroscope random walk (rad/s²/√Hz), accelerometer random walk (m/s³/√Hz)]`, Kalibr's
    /// `imu.yaml` order. Without it the IMU is not read.
    pub noise: Option<[f64; 4]>,
    /// The camera's pose in the IMU frame; `None` looks it up in the tf tree.
    pub body_from_cam: Option<Isometry3<f64>>,
}

impl ImuOptions {
    /// `GYRO_ND,ACCEL_ND,GYRO_RW,ACCEL_RW` (empty: none).
    pub fn parse_noise(text: &str) -> Result<Option<[f64; 4]>, String> {
        let v = numbers_of(text)?;
        match v[..] {
            [] => Ok(None),
            [a, b, c, d] if v.iter().all(|x| *x > 0.0 && x.is_finite()) => Ok(Some([a, b, c, d])),
            _ => Err(format!(
                "`{text}`: expected four positive numbers GYRO_NOISE,ACCEL_NOISE,GYRO_WALK,ACCEL_WALK (Kalibr's imu.yaml: gyroscope_noise_density, accelerometer_noise_density, gyroscope_random_walk, accelerometer_random_walk)"
            )),
        }
    }

    /// `TX,TY,TZ,QX,QY,QZ,QW`: the camera's pose in the IMU frame (empty: from tf).
    pub fn parse_extrinsic(text: &str) -> Result<Option<Isometry3<f64>>, String> {
        let v = numbers_of(text)?;
        match v[..] {
            [] => Ok(None),
            [tx, ty, tz, qx, qy, qz, qw] => {
                let q = Quaternion::new(qw, qx, qy, qz);
                if (q.norm() - 1.0).abs() > 1e-3 {
                    return Err(format!("`{text}`: the quaternion's norm is {}, not 1", q.norm()));
                }
                Ok(Some(Isometry3::from_parts(Translation3::new(tx, ty, tz), UnitQuaternion::from_quaternion(q))))
            }
            _ => Err(format!("`{text}`: expected TX,TY,TZ,QX,QY,QZ,QW (the camera's pose in the IMU frame)")),
        }
    }
}

/// The first pass's samples of every IMU topic, in record order, with the first frame id.
#[derive(Default)]
pub(super) struct Collected {
    pub(super) topics: HashMap<String, (Vec<ImuSample>, String, Option<String>)>,
}

impl Collected {
    pub(super) fn add(&mut self, topic: &str, sample: Result<(ImuSample, String), String>) {
        let entry = self.topics.entry(topic.to_string()).or_insert_with(|| (Vec::new(), String::new(), None));
        match sample {
            Ok((s, frame)) => {
                if entry.0.is_empty() {
                    entry.1 = frame;
                }
                entry.0.push(s);
            }
            Err(e) => {
                entry.2.get_or_insert(e);
            }
        }
    }
}

/// A run's IMU: its batches and calibration.
#[derive(Clone, Debug)]
pub(super) struct Plan {
    pub(super) topic: String,
    pub(super) batches: Vec<Vec<ImuSample>>,
    pub(super) calibration: ImuCalibration,
    /// Samples after the last frame (in no batch).
    pub(super) after_last: u64,
    /// Repeated samples dropped.
    pub(super) repeats: u64,
}

/// Checks `topic`'s samples and cuts them at `frame_stamps`; the mounting is `options`' or
/// the tf tree's `imu frame <- camera frame` at the first frame.
pub(super) fn plan(
    bag: &Path,
    topic: &str,
    collected: &mut Collected,
    camera_frame: &str,
    tf: &TfTree,
    options: &ImuOptions,
    frame_stamps: &[(f64, i64)],
) -> Result<Plan, String> {
    let Some(noise) = options.noise else {
        return Err(format!(
            "topic {topic} (`imu`): a bag does not hold the IMU's noise figures; give `imu_noise: GYRO_NOISE,ACCEL_NOISE,GYRO_WALK,ACCEL_WALK` (Kalibr's imu.yaml), or `topics: imu=none`"
        ));
    };
    let (samples, imu_frame, error) = collected.topics.remove(topic).unwrap_or_default();
    if let Some(e) = error {
        return Err(format!("topic {topic}: {e}"));
    }
    if samples.len() < 2 {
        return Err(format!("topic {topic}: {} IMU samples; a visual-inertial run needs a stream", samples.len()));
    }
    let body_from_cam = match options.body_from_cam {
        Some(t) => t,
        None => {
            let at = frame_stamps.first().map_or(0, |f| f.1);
            tf.lookup(&imu_frame, camera_frame, at).map_err(|e| {
                format!(
                    "topic {topic}: the camera's pose in the IMU frame: no transform `{imu_frame}` <- `{camera_frame}` in /tf_static or /tf ({e}); give `imu_extrinsic: TX,TY,TZ,QX,QY,QZ,QW`"
                )
            })?
        }
    };
    // The rate the stream has (median interval): a bag states none.
    let mut intervals: Vec<f64> = samples.windows(2).map(|w| w[1].stamp - w[0].stamp).filter(|d| *d > 0.0).collect();
    intervals.sort_by(f64::total_cmp);
    let Some(&median) = intervals.get(intervals.len() / 2) else {
        return Err(format!("topic {topic}: every IMU sample has one stamp"));
    };
    let rate_hz = 1.0 / median;
    let numbered: Vec<(usize, ImuSample)> = samples.into_iter().enumerate().map(|(i, s)| (i + 1, s)).collect();
    let label = format!("{} topic {topic}, message", bag.display());
    let stream = dynaflow_datasets::imu::check(&numbered, rate_hz, Path::new(&label)).map_err(|e| e.to_string())?;
    let stamps: Vec<f64> = frame_stamps.iter().map(|f| f.0).collect();
    let batches = stream.batches(&stamps);
    let used: usize = batches.iter().map(Vec::len).sum();
    let [gyro_noise_density, accel_noise_density, gyro_random_walk, accel_random_walk] = noise;
    Ok(Plan {
        topic: topic.to_string(),
        after_last: (stream.samples.len() - used) as u64,
        repeats: stream.duplicates_dropped as u64,
        batches,
        calibration: ImuCalibration {
            gyro_noise_density,
            accel_noise_density,
            gyro_random_walk,
            accel_random_walk,
            rate_hz,
            body_from_cam,
            gravity: STANDARD_GRAVITY,
        },
    })
}
