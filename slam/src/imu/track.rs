//! Visual-inertial tracking of one frame (ORB-SLAM3's `PoseInertialOptimizationLastKeyFrame`):
//! the frame's body pose and velocity from its map-point observations and the pre-integrated
//! IMU since the last key frame, whose state is held fixed.
//!
//! As in ORB-SLAM3, the inertial residual uses the last key frame's biases and the frame's own
//! biases are tied to them by the random-walk edges alone, which leaves them where they are:
//! the frame keeps the key frame's biases (the visual-inertial local bundle adjustment
//! refines biases). With no observation at all (a covered camera) the result is the IMU's
//! prediction.
//!
//! Parameters: `R = R̂·Exp(δθ)`, `p = p̂ + R̂·δp` (body), `v = v̂ + δv` (world). Visual
//! residuals as `optimize_pose`'s (pixel, and the virtual right coordinate with depth),
//! Huber at the chi-square 95 % bounds, four rounds of ten Levenberg-Marquardt iterations
//! with the observations re-classified after each; the inertial residual (rotation, velocity,
//! position) whitened by the pre-integration's covariance.

use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{CHI2_2DOF_95, CHI2_3DOF_95, LmDamping, PoseObservation, huber, observation_jacobian};
use nalgebra::{Isometry3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3};

use super::propagate::NavState;
use super::{Preintegrated, right_jacobian_inverse};

/// What [`optimize_inertial_pose`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct InertialFit {
    /// The frame's state (its biases: the last key frame's).
    pub state: NavState,
    /// Per observation: within its chi-square bound at the end.
    pub inliers: Vec<bool>,
    /// The inertial residual's squared Mahalanobis norm at the end (9 degrees of freedom).
    pub inertial_chi2: f64,
}

type Vector9 = SVector<f64, 9>;
type Matrix9 = SMatrix<f64, 9, 9>;

/// Track one frame against the last key frame: see the module documentation. `preintegrated`
/// spans the last key frame to this frame at `last.bias`; `initial` is the starting guess
/// (the IMU's prediction); `body_from_cam` the camera's pose in the body.
#[allow(clippy::too_many_arguments)]
pub fn optimize_inertial_pose(
    obs: &[PoseObservation],
    cam: &Pinhole,
    bf: f64,
    body_from_cam: &Isometry3<f64>,
    last: &NavState,
    preintegrated: &Preintegrated,
    gravity_w: &Vector3<f64>,
    initial: &NavState,
    inliers: Option<Vec<bool>>,
) -> InertialFit {
    let n = obs.len();
    let mut inlier = inliers.filter(|v| v.len() == n).unwrap_or_else(|| vec![true; n]);
    let cam_from_body = body_from_cam.inverse();
    let r_cb = cam_from_body.rotation.to_rotation_matrix().into_inner();
    let bound = |o: &PoseObservation| if o.depth.is_some() && bf > 0.0 { CHI2_3DOF_95 } else { CHI2_2DOF_95 };
    let info = preintegrated.covariance().try_inverse().unwrap_or_else(Matrix9::zeros);
    let ri = last.world_from_body.rotation.to_rotation_matrix().into_inner();
    let ri_t = ri.transpose();
    let (pi, vi) = (last.world_from_body.translation.vector, last.velocity);

    // The inertial residual and its Jacobian with respect to (δθ, δp, δv).
    let inertial = |s: &NavState| -> (Vector9, Matrix9) {
        let rj = s.world_from_body.rotation.to_rotation_matrix().into_inner();
        let pj = s.world_from_body.translation.vector;
        let (r, _) = preintegrated.residual((&ri, &pi, &vi), (&rj, &pj, &s.velocity), gravity_w);
        let mut j = Matrix9::zeros();
        j.fixed_view_mut::<3, 3>(0, 0).copy_from(&right_jacobian_inverse(&r.fixed_rows::<3>(0).into()));
        j.fixed_view_mut::<3, 3>(3, 6).copy_from(&ri_t);
        j.fixed_view_mut::<3, 3>(6, 3).copy_from(&(ri_t * rj));
        (r, j)
    };
    let camera_point = |s: &NavState, o: &PoseObservation| -> (Vector3<f64>, nalgebra::Point3<f64>) {
        let pb = s.world_from_body.inverse_transform_point(&o.point).coords;
        (pb, cam_from_body * nalgebra::Point3::from(pb))
    };
    let chi2 = |s: &NavState, o: &PoseObservation| -> Option<f64> {
        let (_, pc) = camera_point(s, o);
        let (r, _) = observation_jacobian(cam, bf, &pc, o)?;
        Some(r.norm_squared() / (o.sigma * o.sigma))
    };
    let cost_of = |s: &NavState, mask: &[bool]| -> f64 {
        let (r, _) = inertial(s);
        let visual: f64 = obs
            .iter()
            .zip(mask)
            .filter(|(_, m)| **m)
            .map(|(o, _)| chi2(s, o).map_or(0.0, |c| huber(c, bound(o).sqrt()).0))
            .sum();
        visual + (r.transpose() * info * r)[(0, 0)]
    };
    let apply = |s: &NavState, d: &Vector9| -> NavState {
        let (r, p) = (s.world_from_body.rotation, s.world_from_body.translation.vector);
        let mut rotation = r * UnitQuaternion::from_scaled_axis(Vector3::new(d[0], d[1], d[2]));
        rotation.renormalize();
        let p = p + r * Vector3::new(d[3], d[4], d[5]);
        NavState {
            world_from_body: Isometry3::from_parts(Translation3::from(p), rotation),
            velocity: s.velocity + Vector3::new(d[6], d[7], d[8]),
            bias: last.bias,
        }
    };

    let mut state = NavState { bias: last.bias, ..*initial };
    for _round in 0..4 {
        let mut lm = LmDamping::default();
        let mut cost = cost_of(&state, &inlier);
        for _ in 0..10 {
            let (r, j) = inertial(&state);
            let jt_info = j.transpose() * info;
            let mut h = jt_info * j;
            let mut g = jt_info * r;
            for (o, _) in obs.iter().zip(&inlier).filter(|(_, m)| **m) {
                let (pb, pc) = camera_point(&state, o);
                let Some((res, jac)) = observation_jacobian(cam, bf, &pc, o) else { continue };
                let w_info = 1.0 / (o.sigma * o.sigma);
                let (_, w) = huber(res.norm_squared() * w_info, bound(o).sqrt());
                // ∂r/∂pc (the first block of the left-perturbation Jacobian), through the body.
                let dpc = jac.fixed_view::<3, 3>(0, 0) * r_cb;
                let mut jb = SMatrix::<f64, 3, 9>::zeros();
                jb.fixed_view_mut::<3, 3>(0, 0).copy_from(&(dpc * pb.cross_matrix()));
                jb.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-dpc));
                h += (w * w_info) * (jb.transpose() * jb);
                g += (w * w_info) * (jb.transpose() * res);
            }
            let Some(step) = lm.damped(&h).cholesky().map(|c| c.solve(&(-g))) else { break };
            let candidate = apply(&state, &step);
            let new_cost = cost_of(&candidate, &inlier);
            let accepted = new_cost < cost;
            if accepted {
                state = candidate;
                cost = new_cost;
            }
            if !lm.next(accepted, step.norm(), 1e-12) {
                break;
            }
        }
        for (flag, o) in inlier.iter_mut().zip(obs) {
            *flag = chi2(&state, o).is_some_and(|c| c <= bound(o));
        }
    }
    let (r, _) = inertial(&state);
    let inertial_chi2 = (r.transpose() * info * r)[(0, 0)];
    InertialFit { state, inliers: inlier, inertial_chi2 }
}

#[cfg(test)]
mod observations;
#[cfg(test)]
mod tests;
