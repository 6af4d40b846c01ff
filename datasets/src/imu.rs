//! An IMU stream as read from a file, checked, and cut into one batch per camera frame.
//!
//! The rules, applied in file order (each sample carries the line it came from, so every
//! refusal names `file:line`):
//! - a stamp or value that is not finite: refused;
//! - a stamp before the previous one: refused (out of order);
//! - a stamp equal to the previous one: dropped and counted if the values are equal too (a
//!   repeated line), refused otherwise (two readings at one instant);
//! - a gap longer than [`MAX_GAP_PERIODS`] sample periods: refused, naming both lines; shorter
//!   irregular intervals (over 1.5 periods) are integrated through and counted;
//! - a median rate more than [`RATE_TOLERANCE`] away from the stated one: refused.
//!
//! Batches: frame `i` gets the samples stamped in `(t[i-1], t[i]]` (the first frame every
//! sample up to `t[0]`), so each sample reaches exactly one frame.

use std::path::Path;

use dynaflow_msg::ImuSample;

use crate::Error;

/// The longest gap integrated through, in sample periods (chosen: ten periods, 50 ms at
/// 200 Hz; past that, holding the mean of the two samples around the gap is no longer a
/// measurement of the motion in it).
pub const MAX_GAP_PERIODS: f64 = 10.0;

/// How far the median sample rate may be from the stated one (chosen: 10 %, well outside the
/// clock drift of a real IMU and inside any mistake of units or of the wrong file).
pub const RATE_TOLERANCE: f64 = 0.1;

/// A checked IMU stream.
#[derive(Clone, Debug, PartialEq)]
pub struct ImuStream {
    /// The samples, strictly increasing in stamp.
    pub samples: Vec<ImuSample>,
    /// Repeated lines dropped.
    pub duplicates_dropped: usize,
    /// Intervals longer than 1.5 sample periods (integrated through).
    pub irregular_intervals: usize,
    /// The longest interval between two samples, seconds.
    pub longest_interval: f64,
}

/// Check `samples` (each with its 1-based line in `path`) against the stated `rate_hz`.
pub fn check(samples: &[(usize, ImuSample)], rate_hz: f64, path: &Path) -> Result<ImuStream, Error> {
    let refuse = |line: usize, message: String| Error::File { path: path.to_path_buf(), line, message };
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(refuse(0, format!("the stated IMU rate {rate_hz} Hz is not a positive number")));
    }
    let period = 1.0 / rate_hz;
    let mut out: Vec<ImuSample> = Vec::with_capacity(samples.len());
    let mut last_line = 0;
    let (mut duplicates_dropped, mut irregular_intervals, mut longest_interval) = (0, 0, 0.0f64);
    for &(line, s) in samples {
        let finite = s.stamp.is_finite() && s.gyro.iter().chain(s.accel.iter()).all(|v| v.is_finite());
        if !finite {
            return Err(refuse(line, "an IMU sample with a value that is not a finite number".into()));
        }
        if let Some(prev) = out.last() {
            if s.stamp < prev.stamp {
                return Err(refuse(
                    line,
                    format!(
                        "IMU stamp {} s is before the previous sample's {} s (line {last_line}): out of order",
                        s.stamp, prev.stamp
                    ),
                ));
            }
            if s.stamp == prev.stamp {
                if s == *prev {
                    duplicates_dropped += 1;
                    continue;
                }
                return Err(refuse(
                    line,
                    format!("two different IMU readings at {} s (here and line {last_line})", s.stamp),
                ));
            }
            let interval = s.stamp - prev.stamp;
            if interval > MAX_GAP_PERIODS * period {
                return Err(refuse(
                    line,
                    format!(
                        "a gap of {:.1} ms in the IMU stream since line {last_line}: longer than {MAX_GAP_PERIODS} periods at the stated {rate_hz} Hz",
                        interval * 1e3
                    ),
                ));
            }
            irregular_intervals += usize::from(interval > 1.5 * period);
            longest_interval = longest_interval.max(interval);
        }
        out.push(s);
        last_line = line;
    }
    let mut intervals: Vec<f64> = out.windows(2).map(|w| w[1].stamp - w[0].stamp).collect();
    if !intervals.is_empty() {
        intervals.sort_by(f64::total_cmp);
        let measured = 1.0 / intervals[intervals.len() / 2];
        if (measured / rate_hz - 1.0).abs() > RATE_TOLERANCE {
            return Err(refuse(
                0,
                format!("the IMU samples come at {measured:.1} Hz (median), the calibration states {rate_hz} Hz"),
            ));
        }
    }
    Ok(ImuStream { samples: out, duplicates_dropped, irregular_intervals, longest_interval })
}

impl ImuStream {
    /// One batch per frame stamp (sorted): see [`batches`].
    pub fn batches(&self, frame_stamps: &[f64]) -> Vec<Vec<ImuSample>> {
        batches(&self.samples, frame_stamps)
    }
}

/// One batch of `samples` (in stamp order) per frame stamp (sorted): frame `i` gets the
/// samples in `(t[i-1], t[i]]`, the first every sample up to `t[0]`. Samples after the last
/// frame are in no batch.
pub fn batches(samples: &[ImuSample], frame_stamps: &[f64]) -> Vec<Vec<ImuSample>> {
    let mut start = 0;
    frame_stamps
        .iter()
        .map(|&t| {
            let end = start + samples[start..].partition_point(|s| s.stamp <= t);
            let batch = samples[start..end].to_vec();
            start = end;
            batch
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use nalgebra::Vector3;

    use super::*;

    fn sample(stamp: f64, v: f64) -> ImuSample {
        ImuSample { stamp, gyro: Vector3::new(v, 0.0, 0.0), accel: Vector3::new(0.0, 0.0, 9.8) }
    }

    fn stream(stamps: &[f64]) -> Vec<(usize, ImuSample)> {
        stamps.iter().enumerate().map(|(i, &t)| (i + 2, sample(t, t))).collect()
    }

    fn regular(n: usize) -> Vec<f64> {
        (0..n).map(|k| 100.0 + k as f64 * 0.005).collect()
    }

    #[test]
    fn each_sample_reaches_exactly_one_frame() {
        let s = check(&stream(&regular(1000)), 200.0, Path::new("imu.csv")).unwrap();
        // Frames at 30 Hz, one exactly on a sample's stamp, and irregular ones.
        let mut frames: Vec<f64> = (0..140).map(|k| 100.0 + k as f64 / 30.0).collect();
        frames.push(frames.last().unwrap() + 0.0001);
        frames.push(s.samples[999].stamp);
        frames[3] = s.samples[20].stamp;
        let batches = s.batches(&frames);
        let all: Vec<ImuSample> = batches.iter().flatten().copied().collect();
        assert_eq!(all, s.samples, "every sample once, in order");
        // A sample stamped exactly at a frame belongs to that frame, not the next.
        assert_eq!(batches[3].last(), Some(&s.samples[20]));
        assert_eq!(batches[4].first(), Some(&s.samples[21]));
        assert_eq!(batches[140].len(), 0, "no sample between two frames 0.1 ms apart");
    }

    #[test]
    fn bad_streams_are_refused_naming_the_line_and_repeats_are_counted() {
        let path = Path::new("mav0/imu0/data.csv");
        let err = |stamps: &[f64]| check(&stream(stamps), 200.0, path).unwrap_err().to_string();
        let mut t = regular(50);
        t.swap(10, 11);
        assert!(err(&t).starts_with("mav0/imu0/data.csv:13:") && err(&t).contains("out of order"), "{}", err(&t));
        let mut t = regular(50);
        t[20] += 0.2;
        t[21..].iter_mut().for_each(|x| *x += 0.2);
        assert!(err(&t).contains(":22:") && err(&t).contains("gap of 205.0 ms"), "{}", err(&t));
        let mut s = stream(&regular(50));
        s[7].1.gyro.y = f64::NAN;
        let e = check(&s, 200.0, path).unwrap_err().to_string();
        assert!(e.contains(":9:") && e.contains("finite"), "{e}");
        let e = check(&stream(&regular(50)), 100.0, path).unwrap_err().to_string();
        assert!(e.contains("200.0 Hz (median), the calibration states 100 Hz"), "{e}");
        // A repeated line is dropped and counted; two readings at one instant are refused.
        let mut s = stream(&regular(50));
        s.insert(5, s[4]);
        let ok = check(&s, 200.0, path).unwrap();
        assert_eq!((ok.samples.len(), ok.duplicates_dropped), (50, 1));
        s[5].1.gyro.x += 1.0;
        let e = check(&s, 200.0, path).unwrap_err().to_string();
        assert!(e.contains("two different IMU readings"), "{e}");
        // A short irregular interval is integrated through and counted.
        let mut t = regular(50);
        t.remove(30);
        let ok = check(&stream(&t), 200.0, path).unwrap();
        assert_eq!(ok.irregular_intervals, 1);
        assert!((ok.longest_interval - 0.01).abs() < 1e-9);
    }
}
