//! IMU-only propagation of a navigation state (pose, velocity, biases) and of its uncertainty:
//! what carries a visual-inertial tracker through frames with too few static points, and what
//! says how far it may have drifted when vision returns.
//!
//! The error state (15: rotation, velocity, position, gyroscope bias, accelerometer bias) is
//! `R = R̂·Exp(δθ)` (right, in the body), `v = v̂ + δv`, `p = p̂ + δp` (world), `b = b̂ + δb`.
//! Over one pre-integrated span (Forster et al., TRO 2017, eqs. 33 and 44, linearised):
//!
//! ```text
//! δθ_j = ΔRᵀ δθ_i + J_R,g δb_g + η_R
//! δv_j = δv_i − R̂_i [Δv]× δθ_i + R̂_i (J_v,g δb_g + J_v,a δb_a + η_v)
//! δp_j = δp_i + Δt δv_i − R̂_i [Δp]× δθ_i + R̂_i (J_p,g δb_g + J_p,a δb_a + η_p)
//! δb_j = δb_i + the random walk over Δt
//! ```
//!
//! with `η` the pre-integration's own noise ([`Preintegrated::covariance`]).

use dynaflow_msg::ImuCalibration;
use nalgebra::{Isometry3, Matrix3, SMatrix, Vector3};

use super::{Bias, Preintegrated};

/// The 15×15 covariance of a navigation state, ordered rotation (body tangent), velocity,
/// position (world), gyroscope bias, accelerometer bias.
pub type Matrix15 = SMatrix<f64, 15, 15>;

/// Where the body is, how fast it moves and what its IMU's biases are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NavState {
    /// The body's pose in the world.
    pub world_from_body: Isometry3<f64>,
    /// The body's velocity in the world, m/s.
    pub velocity: Vector3<f64>,
    /// The IMU's biases.
    pub bias: Bias,
}

impl NavState {
    /// The state at the end of `preintegrated`'s span (its deltas at its bias estimate), with
    /// gravity `gravity_w` in the world; the biases are held.
    pub fn predict(&self, preintegrated: &Preintegrated, gravity_w: &Vector3<f64>) -> NavState {
        let (world_from_body, velocity) = preintegrated.predict(&self.world_from_body, &self.velocity, gravity_w);
        NavState { world_from_body, velocity, bias: self.bias }
    }
}

/// The covariance after `preintegrated`'s span of a state `state` (at the span's start) with
/// covariance `covariance`: the linearised propagation of the module documentation, plus the
/// biases' random walks over the span (`calibration`'s densities² · Δt).
pub fn propagate_covariance(
    state: &NavState,
    covariance: &Matrix15,
    preintegrated: &Preintegrated,
    calibration: &ImuCalibration,
) -> Matrix15 {
    let r = state.world_from_body.rotation.to_rotation_matrix().into_inner();
    let dt = preintegrated.delta_t();
    let dr = preintegrated.delta_rotation().to_rotation_matrix().into_inner();
    let (dv, dp) = (preintegrated.delta_velocity(), preintegrated.delta_position());
    let j = preintegrated.jacobians();
    let mut a = Matrix15::identity();
    let mut set = |row: usize, col: usize, m: Matrix3<f64>| a.fixed_view_mut::<3, 3>(row, col).copy_from(&m);
    set(0, 0, dr.transpose());
    set(0, 9, j.r_g);
    set(3, 0, -r * dv.cross_matrix());
    set(3, 9, r * j.v_g);
    set(3, 12, r * j.v_a);
    set(6, 0, -r * dp.cross_matrix());
    set(6, 3, Matrix3::identity() * dt);
    set(6, 9, r * j.p_g);
    set(6, 12, r * j.p_a);
    // The pre-integration's noise, its velocity and position parts turned into the world.
    let mut b = SMatrix::<f64, 15, 9>::zeros();
    b.fixed_view_mut::<3, 3>(0, 0).copy_from(&Matrix3::identity());
    b.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    b.fixed_view_mut::<3, 3>(6, 6).copy_from(&r);
    let mut out = a * covariance * a.transpose() + b * preintegrated.covariance() * b.transpose();
    for k in 0..3 {
        out[(9 + k, 9 + k)] += calibration.gyro_random_walk.powi(2) * dt;
        out[(12 + k, 12 + k)] += calibration.accel_random_walk.powi(2) * dt;
    }
    out
}

#[cfg(test)]
mod tests;
