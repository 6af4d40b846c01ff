//! IMU pre-integration on the manifold (Forster, Carlone, Dellaert and Scaramuzza,
//! "On-Manifold Preintegration for Real-Time Visual-Inertial Odometry", IEEE T-RO 2017): the
//! rotation, velocity and position deltas between two key frames from the IMU samples alone,
//! independent of the states they connect, with their covariance and their first-order
//! Jacobians with respect to the gyroscope and accelerometer biases, so that a bias update in
//! an optimisation corrects the deltas without integrating again.
//!
//! The discrete scheme is the paper's (its eqs. 30-31 for the deltas, 62-63 for the
//! covariance, Appendix B for the Jacobians) with one change: over each interval the
//! measurement is held constant (the mean of the two samples around it, as ORB-SLAM3 takes
//! it), and velocity and position advance with the rotation at the middle of the interval
//! rather than at its start (VINS-Mono's mid-point integration), which makes the scheme
//! second order in the interval (tested: the error falls fourfold as the rate doubles); the
//! bias Jacobians are those of exactly this scheme, so a small bias change is followed to
//! second-order accuracy.

use nalgebra::{Isometry3, Matrix3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3};

use dynaflow_msg::{ImuCalibration, ImuSample};

/// The 9×9 covariance of the deltas, ordered rotation (tangent space), velocity, position.
pub type Matrix9 = SMatrix<f64, 9, 9>;

/// Gyroscope and accelerometer biases, rad/s and m/s².
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Bias {
    /// Gyroscope bias, rad/s.
    pub gyro: Vector3<f64>,
    /// Accelerometer bias, m/s².
    pub accel: Vector3<f64>,
}

/// Bias changes beyond which [`Preintegrated::set_bias`] integrates again instead of trusting
/// the first-order correction: VINS-Mono's thresholds (`imu_factor.h`, 0.01 rad/s for the
/// gyroscope, 0.1 m/s² for the accelerometer).
pub const REINTEGRATE_GYRO: f64 = 0.01;
/// See [`REINTEGRATE_GYRO`].
pub const REINTEGRATE_ACCEL: f64 = 0.1;

/// The right Jacobian of SO(3) at `phi` (Forster eq. 8).
pub fn right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let k = phi.cross_matrix();
    if theta < 1e-5 {
        // Taylor expansion: the closed form divides by θ³.
        return Matrix3::identity() - 0.5 * k + k * k / 6.0;
    }
    let t2 = theta * theta;
    Matrix3::identity() - (1.0 - theta.cos()) / t2 * k + (theta - theta.sin()) / (t2 * theta) * k * k
}

/// The inverse of [`right_jacobian`] (Forster eq. 9).
pub fn right_jacobian_inverse(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let k = phi.cross_matrix();
    if theta < 1e-5 {
        return Matrix3::identity() + 0.5 * k + k * k / 12.0;
    }
    let c = 1.0 / (theta * theta) - (1.0 + theta.cos()) / (2.0 * theta * theta.sin());
    Matrix3::identity() + 0.5 * k + c * k * k
}

/// The first-order Jacobians of the deltas with respect to the biases (at the linearisation
/// point): `r_g` = ∂ΔR/∂b_g (tangent), `v_g`, `v_a` = ∂Δv/∂b, `p_g`, `p_a` = ∂Δp/∂b.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BiasJacobians {
    /// ∂ΔR/∂b_g in ΔR's tangent space.
    pub r_g: Matrix3<f64>,
    /// ∂Δv/∂b_g.
    pub v_g: Matrix3<f64>,
    /// ∂Δv/∂b_a.
    pub v_a: Matrix3<f64>,
    /// ∂Δp/∂b_g.
    pub p_g: Matrix3<f64>,
    /// ∂Δp/∂b_a.
    pub p_a: Matrix3<f64>,
}

/// One held measurement, kept for re-integration.
#[derive(Clone, Copy, Debug)]
struct Step {
    gyro: Vector3<f64>,
    accel: Vector3<f64>,
    dt: f64,
}

/// The pre-integrated measurements between two instants.
#[derive(Clone, Debug)]
pub struct Preintegrated {
    /// The bias the deltas were integrated with (the linearisation point).
    linearised: Bias,
    /// The current bias estimate; the deltas at it are the first-order corrections.
    estimate: Bias,
    /// Discrete-time measurement noise densities (gyroscope, accelerometer), squared.
    noise: (f64, f64),
    delta_t: f64,
    delta_r: UnitQuaternion<f64>,
    delta_v: Vector3<f64>,
    delta_p: Vector3<f64>,
    j_r_g: Matrix3<f64>,
    j_v_g: Matrix3<f64>,
    j_v_a: Matrix3<f64>,
    j_p_g: Matrix3<f64>,
    j_p_a: Matrix3<f64>,
    covariance: Matrix9,
    steps: Vec<Step>,
}

impl Preintegrated {
    /// Empty, integrating with `bias`, with the white-noise densities of `calibration`.
    pub fn new(bias: Bias, calibration: &ImuCalibration) -> Self {
        Self::empty(bias, (calibration.gyro_noise_density.powi(2), calibration.accel_noise_density.powi(2)))
    }

    fn empty(bias: Bias, noise: (f64, f64)) -> Self {
        Self {
            linearised: bias,
            estimate: bias,
            noise,
            delta_t: 0.0,
            delta_r: UnitQuaternion::identity(),
            delta_v: Vector3::zeros(),
            delta_p: Vector3::zeros(),
            j_r_g: Matrix3::zeros(),
            j_v_g: Matrix3::zeros(),
            j_v_a: Matrix3::zeros(),
            j_p_g: Matrix3::zeros(),
            j_p_a: Matrix3::zeros(),
            covariance: Matrix9::zeros(),
            steps: Vec::new(),
        }
    }

    /// Integrate the samples between `from` and `to` (seconds; `samples` sorted by stamp and
    /// covering the span): over each interval between two samples the rates are their mean,
    /// and at `from` and `to` the samples are interpolated linearly (ORB-SLAM3's
    /// `PreintegrateIMU`). Samples outside the span are ignored.
    pub fn integrate_span(&mut self, samples: &[ImuSample], from: f64, to: f64) {
        let lerp = |a: &ImuSample, b: &ImuSample, t: f64| {
            let s = if b.stamp > a.stamp { ((t - a.stamp) / (b.stamp - a.stamp)).clamp(0.0, 1.0) } else { 0.0 };
            (a.gyro + (b.gyro - a.gyro) * s, a.accel + (b.accel - a.accel) * s)
        };
        for pair in samples.windows(2) {
            let (a, b) = (&pair[0], &pair[1]);
            let (t0, t1) = (a.stamp.max(from), b.stamp.min(to));
            if t1 <= t0 {
                continue;
            }
            let (g0, a0) = lerp(a, b, t0);
            let (g1, a1) = lerp(a, b, t1);
            self.integrate((g0 + g1) * 0.5, (a0 + a1) * 0.5, t1 - t0);
        }
    }

    /// Integrate one measurement held for `dt` seconds.
    pub fn integrate(&mut self, gyro: Vector3<f64>, accel: Vector3<f64>, dt: f64) {
        self.steps.push(Step { gyro, accel, dt });
        self.step(gyro, accel, dt);
    }

    fn step(&mut self, gyro: Vector3<f64>, accel: Vector3<f64>, dt: f64) {
        let acc = accel - self.linearised.accel;
        let phi = (gyro - self.linearised.gyro) * dt;
        let r = self.delta_r.to_rotation_matrix().into_inner();
        // The rotation at the middle of the interval, and its Jacobian with respect to the
        // gyroscope bias (through ΔR's and through φ's own).
        let half = UnitQuaternion::from_scaled_axis(phi * 0.5).to_rotation_matrix().into_inner();
        let r_mid = r * half;
        let j_mid = half.transpose() * self.j_r_g - right_jacobian(&(phi * 0.5)) * (0.5 * dt);
        let acc_x = acc.cross_matrix();
        let dt2 = dt * dt;
        // Velocity and position advance with the mid-interval rotation (second order).
        self.delta_p += self.delta_v * dt + 0.5 * r_mid * acc * dt2;
        self.delta_v += r_mid * acc * dt;
        // The noise propagation (eq. 62): state (δφ, δv, δp), noise (gyro, accel).
        let mut a = Matrix9::identity();
        let mut b = SMatrix::<f64, 9, 6>::zeros();
        a.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-r_mid * acc_x * half.transpose() * dt));
        a.fixed_view_mut::<3, 3>(6, 0).copy_from(&(-0.5 * r_mid * acc_x * half.transpose() * dt2));
        a.fixed_view_mut::<3, 3>(6, 3).copy_from(&(Matrix3::identity() * dt));
        b.fixed_view_mut::<3, 3>(3, 3).copy_from(&(r_mid * dt));
        b.fixed_view_mut::<3, 3>(6, 3).copy_from(&(0.5 * r_mid * dt2));
        // The bias Jacobians of exactly this scheme (Appendix B with the mid-interval
        // rotation), position first: it reads the old velocity ones.
        self.j_p_a += self.j_v_a * dt - 0.5 * r_mid * dt2;
        self.j_p_g += self.j_v_g * dt - 0.5 * r_mid * acc_x * j_mid * dt2;
        self.j_v_a -= r_mid * dt;
        self.j_v_g -= r_mid * acc_x * j_mid * dt;
        let d_ri = UnitQuaternion::from_scaled_axis(phi);
        let d_ri_t = d_ri.to_rotation_matrix().into_inner().transpose();
        let jr = right_jacobian(&phi);
        a.fixed_view_mut::<3, 3>(0, 0).copy_from(&d_ri_t);
        b.fixed_view_mut::<3, 3>(0, 0).copy_from(&(jr * dt));
        // Discrete noise: the continuous density squared over the interval.
        let mut q = SMatrix::<f64, 6, 6>::zeros();
        for i in 0..3 {
            q[(i, i)] = self.noise.0 / dt;
            q[(i + 3, i + 3)] = self.noise.1 / dt;
        }
        self.covariance = a * self.covariance * a.transpose() + b * q * b.transpose();
        self.j_r_g = d_ri_t * self.j_r_g - jr * dt;
        let mut rotation = self.delta_r * d_ri;
        rotation.renormalize();
        self.delta_r = rotation;
        self.delta_t += dt;
    }

    /// Integrate the held measurements again with `bias` as the linearisation point.
    pub fn reintegrate(&mut self, bias: Bias) {
        let steps = std::mem::take(&mut self.steps);
        *self = Self::empty(bias, self.noise);
        for s in steps {
            self.integrate(s.gyro, s.accel, s.dt);
        }
    }

    /// Set the bias estimate. Beyond [`REINTEGRATE_GYRO`] or [`REINTEGRATE_ACCEL`] from the
    /// linearisation point the samples are integrated again (returns true); within, the
    /// deltas follow it to first order.
    pub fn set_bias(&mut self, bias: Bias) -> bool {
        let far = (bias.gyro - self.linearised.gyro).norm() > REINTEGRATE_GYRO
            || (bias.accel - self.linearised.accel).norm() > REINTEGRATE_ACCEL;
        if far {
            self.reintegrate(bias);
        } else {
            self.estimate = bias;
        }
        far
    }

    /// The integrated time, seconds.
    pub fn delta_t(&self) -> f64 {
        self.delta_t
    }

    /// The bias estimate the deltas below are given at.
    pub fn bias(&self) -> Bias {
        self.estimate
    }

    /// The bias the samples were integrated with.
    pub fn linearised_bias(&self) -> Bias {
        self.linearised
    }

    /// The bias Jacobians at the linearisation point.
    pub fn jacobians(&self) -> BiasJacobians {
        BiasJacobians { r_g: self.j_r_g, v_g: self.j_v_g, v_a: self.j_v_a, p_g: self.j_p_g, p_a: self.j_p_a }
    }

    /// Covariance of (δφ, δv, δp), from the white measurement noise.
    pub fn covariance(&self) -> &Matrix9 {
        &self.covariance
    }

    fn bias_change(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.estimate.gyro - self.linearised.gyro, self.estimate.accel - self.linearised.accel)
    }

    /// ΔR at the bias estimate: ΔR · Exp(J_R,g δb_g) (eq. 44).
    pub fn delta_rotation(&self) -> UnitQuaternion<f64> {
        let (dg, _) = self.bias_change();
        self.delta_r * UnitQuaternion::from_scaled_axis(self.j_r_g * dg)
    }

    /// Δv at the bias estimate.
    pub fn delta_velocity(&self) -> Vector3<f64> {
        let (dg, da) = self.bias_change();
        self.delta_v + self.j_v_g * dg + self.j_v_a * da
    }

    /// Δp at the bias estimate.
    pub fn delta_position(&self) -> Vector3<f64> {
        let (dg, da) = self.bias_change();
        self.delta_p + self.j_p_g * dg + self.j_p_a * da
    }

    /// The inertial residual between the body states at the span's start (`i`) and end (`j`),
    /// each `(R_wb, position, velocity)` in the world (ORB-SLAM3's `EdgeInertial`, Forster eq.
    /// 45): rotation in ΔR's tangent space, velocity and position in body `i`'s frame, zero when
    /// the states agree with the deltas at the bias estimate. Also the rotation error
    /// `ΔRᵀ·R_iᵀ·R_j` whose logarithm is the first part.
    pub fn residual(
        &self,
        i: (&Matrix3<f64>, &Vector3<f64>, &Vector3<f64>),
        j: (&Matrix3<f64>, &Vector3<f64>, &Vector3<f64>),
        gravity_w: &Vector3<f64>,
    ) -> (SVector<f64, 9>, Matrix3<f64>) {
        let ((ri, pi, vi), (rj, pj, vj)) = (i, j);
        let (ri_t, dt) = (ri.transpose(), self.delta_t);
        let e_rot = self.delta_rotation().to_rotation_matrix().into_inner().transpose() * ri_t * rj;
        let e_r = UnitQuaternion::from_matrix(&e_rot).scaled_axis();
        let e_v = ri_t * (vj - vi - gravity_w * dt) - self.delta_velocity();
        let e_p = ri_t * (pj - pi - vi * dt - 0.5 * gravity_w * dt * dt) - self.delta_position();
        let mut r = SVector::<f64, 9>::zeros();
        r.fixed_rows_mut::<3>(0).copy_from(&e_r);
        r.fixed_rows_mut::<3>(3).copy_from(&e_v);
        r.fixed_rows_mut::<3>(6).copy_from(&e_p);
        (r, e_rot)
    }

    /// The state at the end of the span from the state at its start (eq. 33): the body's pose
    /// and velocity in the world, with gravity `gravity_w` (e.g. `(0, 0, -9.81)` for z up).
    pub fn predict(
        &self,
        world_from_body: &Isometry3<f64>,
        velocity: &Vector3<f64>,
        gravity_w: &Vector3<f64>,
    ) -> (Isometry3<f64>, Vector3<f64>) {
        let (r, p, t) = (world_from_body.rotation, world_from_body.translation.vector, self.delta_t);
        let mut rotation = r * self.delta_rotation();
        rotation.renormalize();
        let v = velocity + gravity_w * t + r * self.delta_velocity();
        let p = p + velocity * t + 0.5 * gravity_w * t * t + r * self.delta_position();
        (Isometry3::from_parts(Translation3::from(p), rotation), v)
    }
}

pub mod init;
pub mod propagate;
pub mod track;
pub mod window;

#[cfg(test)]
mod tests;
