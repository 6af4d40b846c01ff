//! Observations for exercising [`super::optimize_inertial_pose`]: the unit tests and
//! `benches/inertial.rs` (which includes this file by path) draw the same ones.

use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{PoseObservation, SplitMix64};
use nalgebra::{Isometry3, Point3};

/// `n` points 1.5-4 m in front of the camera at `world_from_cam`, seen with 1 px noise;
/// every tenth 30 px off.
pub fn observations(
    world_from_cam: &Isometry3<f64>,
    cam: &Pinhole,
    n: usize,
    rng: &mut SplitMix64,
) -> Vec<PoseObservation> {
    (0..n)
        .map(|k| {
            let (u, v) = (rng.uniform() * 600.0 + 20.0, rng.uniform() * 440.0 + 20.0);
            let z = 1.5 + rng.uniform() * 2.5;
            let pc = Point3::new((u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z);
            let off = if k % 10 == 9 { 30.0 } else { 0.0 };
            PoseObservation {
                point: world_from_cam * pc,
                uv: [u + rng.normal() + off, v + rng.normal()],
                sigma: 1.0,
                depth: None,
            }
        })
        .collect()
}
