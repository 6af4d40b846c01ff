//! A tracker's trajectory evaluation, fed by its pose stream: each pose as it was sent and the
//! ground truth of the same frames go in during the run; at the end the online and the final
//! estimate (rebuilt from the key frames) are scored as evo scores them and written as TUM
//! trajectory files. The trackers only feed it, so every tracker (and a new sensor's) is
//! scored the same way.

use std::io::Write;

use dynaflow_engine::op::{Context, OpError};
use dynaflow_slam::eval::{Align, evaluate};
use nalgebra::Isometry3;

use crate::report::{Ate, Rpe, TrackerReport};

/// Timestamped `world_from_cam` poses.
pub(crate) type Poses = Vec<(f64, Isometry3<f64>)>;

/// The poses a tracker sent and the ground truth of its frames.
#[derive(Default)]
pub(crate) struct TrajectoryLog {
    estimate: Poses,
    ground_truth: Poses,
}

impl TrajectoryLog {
    /// A pose the tracker sent.
    pub(crate) fn pose(&mut self, stamp: f64, world_from_cam: Isometry3<f64>) {
        self.estimate.push((stamp, world_from_cam));
    }

    /// The ground truth of a frame.
    pub(crate) fn ground_truth(&mut self, stamp: f64, world_from_cam: Isometry3<f64>) {
        self.ground_truth.push((stamp, world_from_cam));
    }

    /// Scores the online estimate and `final_estimate` into `report` (nothing without ground
    /// truth): evo's association tolerance (10 ms), `align` SE(3) as the RGB-D papers report,
    /// Sim(3) for a single camera (its scale is arbitrary; evo `-as`), RPE over one frame.
    pub(crate) fn score(&self, final_estimate: &[(f64, Isometry3<f64>)], align: Align, report: &mut TrackerReport) {
        if self.ground_truth.is_empty() {
            return;
        }
        let name = match align {
            Align::Sim3 => "sim3",
            Align::Se3 => "se3",
            Align::None => "none",
        };
        let score = |poses: &[(f64, Isometry3<f64>)]| -> Option<Result<(Ate, Rpe), String>> {
            if poses.is_empty() {
                return None;
            }
            Some(match evaluate(&self.ground_truth, poses, 0.01, align, 1) {
                Ok(e) => Ok((Ate::of(&e, name), Rpe::of(&e))),
                Err(e) => Err(e.to_string()),
            })
        };
        match score(&self.estimate) {
            Some(Ok((a, r))) => (report.ate, report.rpe) = (Some(a), Some(r)),
            Some(Err(e)) => report.ate_error = Some(e),
            None => {}
        }
        match score(final_estimate) {
            Some(Ok((a, r))) => (report.ate_final, report.rpe_final) = (Some(a), Some(r)),
            Some(Err(e)) => report.ate_final_error = Some(e),
            None => {}
        }
    }

    /// `<out>/<stem>.<node>.trajectory.txt` (the online estimate), `.final_trajectory.txt`
    /// (`final_estimate`, ORB-SLAM2's `SaveTrajectoryTUM`), and with ground truth the ground
    /// truth of the same frames beside them (`.groundtruth.txt`), all TUM format (`dynaflow
    /// eval`, `dynaflow bench`). The estimates are written even empty (a tracker that never
    /// initialised), so a script finds them.
    pub(crate) fn write(&self, ctx: &Context, final_estimate: &[(f64, Isometry3<f64>)]) -> Result<(), OpError> {
        for (what, poses) in [
            ("trajectory", &self.estimate[..]),
            ("final_trajectory", final_estimate),
            ("groundtruth", &self.ground_truth[..]),
        ] {
            if poses.is_empty() && what == "groundtruth" {
                continue;
            }
            let Some(path) = ctx.output_file(&format!("{what}.txt")) else { return Ok(()) };
            let io = |source| OpError::Io { path: path.clone(), source };
            let mut f = std::io::BufWriter::new(dynaflow_engine::files::create_new(&path).map_err(io)?);
            writeln!(f, "# timestamp tx ty tz qx qy qz qw (world_from_cam, dynaflow {what})").map_err(io)?;
            for (t, p) in poses {
                let (v, q) = (p.translation.vector, p.rotation.coords);
                writeln!(f, "{t:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}", v.x, v.y, v.z, q.x, q.y, q.z, q.w)
                    .map_err(io)?;
            }
            f.flush().map_err(io)?;
        }
        Ok(())
    }
}
