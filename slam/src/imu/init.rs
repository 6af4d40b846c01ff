//! Inertial initialisation: where gravity points, how large the visual map is (monocular
//! scale), the key frames' velocities and the IMU biases.
//!
//! - [`initialise`]: ORB-SLAM3's inertial-only maximum-a-posteriori initialisation (Campos,
//!   Montiel and Tardós, "Inertial-Only Optimization for Visual-Inertial Initialization", ICRA
//!   2020): the visual key-frame poses are held fixed (up to scale), and scale, the gravity
//!   direction (two degrees of freedom: yaw is not observable), one velocity per key frame and
//!   constant biases are found by minimising the pre-integrated inertial residuals between
//!   consecutive key frames, weighted by their covariance, plus priors on the biases.
//! - [`static_initialise`]: a device at rest: gravity from the accelerometer mean, the
//!   gyroscope bias from the gyroscope mean, when both sensors' spread is that of their noise.
//!
//! One departure from ORB-SLAM3: the camera-to-IMU lever arm is metric while a monocular map
//! is not, so a body position is `s·c + R_wc·t_cb` (scale on the camera centre only), where
//! ORB-SLAM3 scales the sum; exact for any lever arm.

use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};

use dynaflow_msg::ImuSample;

use super::{Bias, Preintegrated, right_jacobian, right_jacobian_inverse};

/// A key frame as initialisation sees it: its time and its pose from vision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitKeyFrame {
    /// Time, seconds.
    pub stamp: f64,
    /// `world_from_cam` from tracking (the visual map's frame and scale).
    pub world_from_cam: Isometry3<f64>,
}

/// Settings of [`initialise`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitConfig {
    /// The map's scale is known (stereo, RGB-D): only gravity, velocities and biases are found.
    pub fix_scale: bool,
    /// Information (1/σ², (rad/s)⁻²) of the prior that the gyroscope bias is zero.
    pub gyro_prior: f64,
    /// Information ((m/s²)⁻²) of the prior that the accelerometer bias is zero.
    pub accel_prior: f64,
    /// Levenberg-Marquardt iterations at most.
    pub max_iterations: usize,
    /// Hold gravity at this `R_wg` instead of estimating its direction: a refinement of
    /// velocities and biases over a window of an initialised map.
    pub gravity: Option<UnitQuaternion<f64>>,
}

impl InitConfig {
    /// ORB-SLAM3's first initialisation of a monocular map (`LocalMapping::InitializeIMU(1e2,
    /// 1e10)`: the accelerometer bias held at zero; two seconds of motion cannot tell it from a
    /// tilt of gravity).
    pub fn monocular() -> Self {
        Self { fix_scale: false, gyro_prior: 1e2, accel_prior: 1e10, max_iterations: 200, gravity: None }
    }

    /// ORB-SLAM3's first refinement of a monocular map, once its key frames span 5 s
    /// (`InitializeIMU(1.0, 1e5)`): looser bias priors, the accelerometer bias now estimated.
    pub fn monocular_refinement() -> Self {
        Self { gyro_prior: 1.0, accel_prior: 1e5, ..Self::monocular() }
    }

    /// ORB-SLAM3's first initialisation with depth (`InitializeIMU(1e2, 1e5)`), scale fixed.
    pub fn with_depth() -> Self {
        Self { fix_scale: true, accel_prior: 1e5, ..Self::monocular() }
    }
}

/// What [`initialise`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct InertialInit {
    /// Metres per unit of the visual map (1 with [`InitConfig::fix_scale`]).
    pub scale: f64,
    /// `R_wg`: the rotation from a gravity-aligned frame (`z` up, gravity `-z`) into the visual
    /// map's frame, with zero yaw about gravity relative to the map.
    pub world_from_gravity: UnitQuaternion<f64>,
    /// The biases, constant over the window.
    pub bias: Bias,
    /// Per key frame, the body's velocity in the visual map's frame, m/s (metric).
    pub velocities: Vec<Vector3<f64>>,
    /// Standard deviations from the inverse Hessian at the solution (poses taken as exact, so
    /// a lower bound): scale (relative) and gravity direction (rad).
    pub scale_sigma: f64,
    /// See [`InertialInit::scale_sigma`].
    pub gravity_sigma: f64,
    /// The weighted squared residual at the solution, and Levenberg-Marquardt's iterations.
    pub cost: f64,
    /// See [`InertialInit::cost`].
    pub iterations: usize,
}

impl InertialInit {
    /// The similarity that takes a point of the visual map into the gravity-aligned metric
    /// frame: `x_g = R_gw · (s · x_w)` (rotation, scale).
    pub fn gravity_from_world(&self, x_w: &Vector3<f64>) -> Vector3<f64> {
        self.world_from_gravity.inverse() * (x_w * self.scale)
    }
}

/// Why [`initialise`] or [`static_initialise`] gave no answer.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InitError {
    /// Fewer than three key frames, or pre-integrations that do not match them.
    #[error(
        "inertial initialisation needs at least 3 key frames with one pre-integration between each pair; got {keyframes} key frames and {preintegrated} pre-integrations"
    )]
    TooFewKeyFrames {
        /// Key frames given.
        keyframes: usize,
        /// Pre-integrations given.
        preintegrated: usize,
    },
    /// A pre-integration spans no time, or not its key frames' interval.
    #[error("the pre-integration between key frames {index} and {} spans {span:.4} s, their stamps {expected:.4} s", .index + 1)]
    BadSpan {
        /// Index of the first key frame.
        index: usize,
        /// Integrated time.
        span: f64,
        /// Time between the key frames.
        expected: f64,
    },
    /// The optimisation did not give a usable answer (a scale that is not positive and
    /// finite, a singular system).
    #[error("inertial initialisation diverged: {0}")]
    Diverged(String),
    /// The device is not at rest: a sensor's spread exceeds its noise.
    #[error("not at rest: {sensor} spread {spread:.3e} above the limit {limit:.3e} (3x the datasheet's white noise)")]
    Moving {
        /// `"gyroscope"` or `"accelerometer"`.
        sensor: &'static str,
        /// Largest per-axis sample standard deviation.
        spread: f64,
        /// The limit.
        limit: f64,
    },
    /// Too few samples for a static initialisation.
    #[error("static initialisation needs at least {needed} samples, got {got}")]
    TooFewSamples {
        /// Needed.
        needed: usize,
        /// Given.
        got: usize,
    },
}

/// Number of parameters before the velocities: gravity direction (2), log-scale (1), gyroscope
/// bias (3), accelerometer bias (3).
const GLOBAL: usize = 9;

/// One inertial edge, linearised.
struct Edge {
    residual: SVector<f64, 9>,
    /// Jacobian with respect to (δθ_g (2), δσ, δb_g, δb_a) — [`GLOBAL`] columns.
    global: SMatrix<f64, 9, GLOBAL>,
    /// Jacobians with respect to the first and second key frame's velocity.
    v_i: SMatrix<f64, 9, 3>,
    v_j: SMatrix<f64, 9, 3>,
}

/// The state being estimated.
#[derive(Clone)]
struct State {
    r_wg: UnitQuaternion<f64>,
    scale: f64,
    bias: Bias,
    velocities: Vec<Vector3<f64>>,
}

/// ORB-SLAM3's inertial-only initialisation (see the module documentation). `preintegrated[i]`
/// spans `keyframes[i]` to `keyframes[i + 1]`; it is cloned, so the caller's keep their
/// linearisation point. `body_from_cam` is the camera's pose in the IMU frame, `gravity` the
/// magnitude of gravity.
pub fn initialise(
    keyframes: &[InitKeyFrame],
    preintegrated: &[Preintegrated],
    body_from_cam: &Isometry3<f64>,
    gravity: f64,
    config: &InitConfig,
) -> Result<InertialInit, InitError> {
    let n = keyframes.len();
    if n < 3 || preintegrated.len() + 1 != n {
        return Err(InitError::TooFewKeyFrames { keyframes: n, preintegrated: preintegrated.len() });
    }
    for (i, (p, w)) in preintegrated.iter().zip(keyframes.windows(2)).enumerate() {
        let expected = w[1].stamp - w[0].stamp;
        if p.delta_t() <= 0.0 || (p.delta_t() - expected).abs() > 1e-6 * expected.abs().max(1.0) {
            return Err(InitError::BadSpan { index: i, span: p.delta_t(), expected });
        }
    }
    let mut pre: Vec<Preintegrated> = preintegrated.to_vec();
    let cam_from_body = body_from_cam.inverse();
    // Body rotations (fixed) and the two parts of body positions: camera centre (scaled) and
    // the metric lever arm.
    let rotations: Vec<Matrix3<f64>> = keyframes
        .iter()
        .map(|k| (k.world_from_cam.rotation * cam_from_body.rotation).to_rotation_matrix().into_inner())
        .collect();
    let centres: Vec<Vector3<f64>> = keyframes.iter().map(|k| k.world_from_cam.translation.vector).collect();
    let levers: Vec<Vector3<f64>> =
        keyframes.iter().map(|k| k.world_from_cam.rotation * cam_from_body.translation.vector).collect();
    let info: Vec<SMatrix<f64, 9, 9>> = pre
        .iter()
        .map(|p| {
            p.covariance()
                .try_inverse()
                .ok_or_else(|| InitError::Diverged("a pre-integration covariance is singular".into()))
        })
        .collect::<Result<_, _>>()?;

    // Initial guess (ORB-SLAM3's): gravity against the sum of the rotated velocity deltas,
    // velocities from the visual positions, zero biases, scale 1.
    let mut down = Vector3::zeros();
    for (i, p) in pre.iter().enumerate() {
        down -= rotations[i] * p.delta_velocity();
    }
    let g_dir = Vector3::new(0.0, 0.0, -1.0);
    let r_wg = UnitQuaternion::rotation_between(&g_dir, &down).unwrap_or_else(UnitQuaternion::identity);
    let velocities = (0..n)
        .map(|i| {
            let (a, b) = if i + 1 < n { (i, i + 1) } else { (i - 1, i) };
            (centres[b] + levers[b] - centres[a] - levers[a]) / (keyframes[b].stamp - keyframes[a].stamp)
        })
        .collect();
    let r_wg = config.gravity.unwrap_or(r_wg);
    let mut state = State { r_wg, scale: 1.0, bias: Bias::default(), velocities };

    let dim = GLOBAL + 3 * n;
    let evaluate = |state: &State, pre: &mut [Preintegrated]| -> (f64, Vec<Edge>) {
        let mut cost = 0.0;
        let mut edges = Vec::with_capacity(n - 1);
        let g_w = state.r_wg * (g_dir * gravity);
        // dg/dδθ for δθ about the gravity frame's x and y.
        let dg = -(state.r_wg.to_rotation_matrix().into_inner() * (g_dir * gravity).cross_matrix());
        for (i, p) in pre.iter_mut().enumerate() {
            p.set_bias(state.bias);
            let dt = p.delta_t();
            let (ri_t, rj) = (rotations[i].transpose(), rotations[i + 1]);
            let (vi, vj) = (state.velocities[i], state.velocities[i + 1]);
            let pi = centres[i] * state.scale + levers[i];
            let pj = centres[i + 1] * state.scale + levers[i + 1];
            let (residual, e_r_rot) = p.residual((&rotations[i], &pi, &vi), (&rj, &pj, &vj), &g_w);
            let e_r: Vector3<f64> = residual.fixed_rows::<3>(0).into();
            let j = p.jacobians();
            let dbg = p.bias().gyro - p.linearised_bias().gyro;
            let mut global = SMatrix::<f64, 9, GLOBAL>::zeros();
            let dg2 = dg.fixed_columns::<2>(0);
            global.fixed_view_mut::<3, 2>(3, 0).copy_from(&(-ri_t * dg2 * dt));
            global.fixed_view_mut::<3, 2>(6, 0).copy_from(&(-0.5 * ri_t * dg2 * dt * dt));
            global.fixed_view_mut::<3, 1>(6, 2).copy_from(&(ri_t * (centres[i + 1] - centres[i]) * state.scale));
            let de_r_dbg = -right_jacobian_inverse(&e_r) * e_r_rot.transpose() * right_jacobian(&(j.r_g * dbg)) * j.r_g;
            global.fixed_view_mut::<3, 3>(0, 3).copy_from(&de_r_dbg);
            global.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-j.v_g));
            global.fixed_view_mut::<3, 3>(6, 3).copy_from(&(-j.p_g));
            global.fixed_view_mut::<3, 3>(3, 6).copy_from(&(-j.v_a));
            global.fixed_view_mut::<3, 3>(6, 6).copy_from(&(-j.p_a));
            let mut v_i = SMatrix::<f64, 9, 3>::zeros();
            let mut v_j = SMatrix::<f64, 9, 3>::zeros();
            v_i.fixed_view_mut::<3, 3>(3, 0).copy_from(&-ri_t);
            v_i.fixed_view_mut::<3, 3>(6, 0).copy_from(&(-ri_t * dt));
            v_j.fixed_view_mut::<3, 3>(3, 0).copy_from(&ri_t);
            cost += (residual.transpose() * info[i] * residual)[(0, 0)];
            edges.push(Edge { residual, global, v_i, v_j });
        }
        cost +=
            config.gyro_prior * state.bias.gyro.norm_squared() + config.accel_prior * state.bias.accel.norm_squared();
        (cost, edges)
    };

    let (mut cost, mut edges) = evaluate(&state, &mut pre);
    let mut lambda = 1e-4;
    let mut iterations = 0;
    let mut hessian = DMatrix::zeros(dim, dim);
    while iterations < config.max_iterations {
        iterations += 1;
        // Normal equations.
        let mut h = DMatrix::<f64>::zeros(dim, dim);
        let mut b = DVector::<f64>::zeros(dim);
        for (i, e) in edges.iter().enumerate() {
            let blocks: [(usize, DMatrix<f64>); 3] = [
                (0, DMatrix::from_column_slice(9, GLOBAL, e.global.as_slice())),
                (GLOBAL + 3 * i, DMatrix::from_column_slice(9, 3, e.v_i.as_slice())),
                (GLOBAL + 3 * (i + 1), DMatrix::from_column_slice(9, 3, e.v_j.as_slice())),
            ];
            let omega = DMatrix::from_column_slice(9, 9, info[i].as_slice());
            let r = DVector::from_column_slice(e.residual.as_slice());
            for (ca, ja) in &blocks {
                let jt_omega = ja.transpose() * &omega;
                let mut seg = b.rows_mut(*ca, ja.ncols());
                seg += &jt_omega * &r;
                for (cb, jb) in &blocks {
                    let mut block = h.view_mut((*ca, *cb), (ja.ncols(), jb.ncols()));
                    block += &jt_omega * jb;
                }
            }
        }
        for k in 0..3 {
            h[(3 + k, 3 + k)] += config.gyro_prior;
            b[3 + k] += config.gyro_prior * state.bias.gyro[k];
            h[(6 + k, 6 + k)] += config.accel_prior;
            b[6 + k] += config.accel_prior * state.bias.accel[k];
        }
        // Held parameters: their rows and columns out, a unit diagonal, no step.
        let held = [(2, config.fix_scale), (0, config.gravity.is_some()), (1, config.gravity.is_some())];
        for (p, _) in held.iter().filter(|(_, hold)| *hold) {
            for k in 0..dim {
                h[(*p, k)] = 0.0;
                h[(k, *p)] = 0.0;
            }
            h[(*p, *p)] = 1.0;
            b[*p] = 0.0;
        }
        hessian = h.clone();
        // Levenberg-Marquardt: damp, solve, accept if the cost falls.
        let mut improved = false;
        for _ in 0..10 {
            let mut damped = h.clone();
            for k in 0..dim {
                damped[(k, k)] += lambda * h[(k, k)].max(1e-12);
            }
            let Some(chol) = damped.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let delta = chol.solve(&(-&b));
            let mut next = state.clone();
            next.r_wg = state.r_wg * UnitQuaternion::from_scaled_axis(Vector3::new(delta[0], delta[1], 0.0));
            next.scale = state.scale * delta[2].exp();
            next.bias.gyro += delta.fixed_rows::<3>(3);
            next.bias.accel += delta.fixed_rows::<3>(6);
            for (i, v) in next.velocities.iter_mut().enumerate() {
                *v += delta.fixed_rows::<3>(GLOBAL + 3 * i);
            }
            let mut trial = pre.clone();
            let (next_cost, next_edges) = evaluate(&next, &mut trial);
            if next_cost.is_finite() && next_cost < cost {
                let converged = (cost - next_cost) <= 1e-12 * cost.max(1e-300) || delta.norm() < 1e-12;
                (state, cost, edges, pre) = (next, next_cost, next_edges, trial);
                lambda = (lambda / 10.0).max(1e-12);
                improved = !converged;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    if !(state.scale.is_finite() && state.scale > 0.0) {
        return Err(InitError::Diverged(format!("scale {}", state.scale)));
    }
    let covariance = hessian
        .cholesky()
        .map(|c| c.inverse())
        .ok_or_else(|| InitError::Diverged("the information matrix at the solution is singular".into()))?;
    let scale_sigma = if config.fix_scale { 0.0 } else { covariance[(2, 2)].max(0.0).sqrt() };
    let gravity_sigma =
        if config.gravity.is_some() { 0.0 } else { (covariance[(0, 0)] + covariance[(1, 1)]).max(0.0).sqrt() };
    Ok(InertialInit {
        scale: state.scale,
        world_from_gravity: state.r_wg,
        bias: state.bias,
        velocities: state.velocities,
        scale_sigma,
        gravity_sigma,
        cost,
        iterations,
    })
}

/// What [`static_initialise`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StaticInit {
    /// `R_gb`: the body's orientation in a gravity-aligned frame (`z` up): the smallest rotation
    /// that takes the measured up axis to `z` (yaw is not observable).
    pub gravity_from_body: UnitQuaternion<f64>,
    /// The gyroscope bias (the mean rate at rest), rad/s.
    pub gyro_bias: Vector3<f64>,
    /// The mean specific force's magnitude, m/s² (gravity plus the accelerometer bias's
    /// component along it, which rest cannot separate).
    pub accel_norm: f64,
}

/// The spread of a sensor at rest may be this many times its datasheet white noise (per-sample
/// standard deviation `density · √rate`) on every axis. Chosen: three standard deviations.
pub const REST_NOISE_FACTOR: f64 = 3.0;
/// A static initialisation wants at least this many samples (a quarter second at 200 Hz).
/// Chosen: the mean of 50 samples has a seventh of one sample's noise.
pub const REST_MIN_SAMPLES: usize = 50;

/// Initialise from samples taken at rest: gravity from the accelerometer mean, the gyroscope
/// bias from the gyroscope mean. Refused when either sensor's per-axis sample standard deviation
/// exceeds [`REST_NOISE_FACTOR`] times its white noise at the calibration's rate (the device
/// moves), or with fewer than [`REST_MIN_SAMPLES`] samples.
pub fn static_initialise(
    samples: &[ImuSample],
    calibration: &dynaflow_msg::ImuCalibration,
) -> Result<StaticInit, InitError> {
    if samples.len() < REST_MIN_SAMPLES {
        return Err(InitError::TooFewSamples { needed: REST_MIN_SAMPLES, got: samples.len() });
    }
    let n = samples.len() as f64;
    let mean = |f: &dyn Fn(&ImuSample) -> Vector3<f64>| samples.iter().map(f).sum::<Vector3<f64>>() / n;
    let spread = |f: &dyn Fn(&ImuSample) -> Vector3<f64>, m: &Vector3<f64>| {
        let var = samples.iter().map(|s| (f(s) - m).component_mul(&(f(s) - m))).sum::<Vector3<f64>>() / (n - 1.0);
        var.max().sqrt()
    };
    let (gyro, accel) = (mean(&|s| s.gyro), mean(&|s| s.accel));
    let root_rate = calibration.rate_hz.sqrt();
    for (sensor, m, f, density) in [
        (
            "gyroscope",
            gyro,
            (&|s: &ImuSample| s.gyro) as &dyn Fn(&ImuSample) -> Vector3<f64>,
            calibration.gyro_noise_density,
        ),
        ("accelerometer", accel, &|s: &ImuSample| s.accel, calibration.accel_noise_density),
    ] {
        let (spread, limit) = (spread(f, &m), REST_NOISE_FACTOR * density * root_rate);
        if spread > limit {
            return Err(InitError::Moving { sensor, spread, limit });
        }
    }
    // At rest the accelerometer reads +g along the world's up axis.
    let gravity_from_body =
        UnitQuaternion::rotation_between(&accel, &Vector3::z()).unwrap_or_else(UnitQuaternion::identity);
    Ok(StaticInit { gravity_from_body, gyro_bias: gyro, accel_norm: accel.norm() })
}

#[cfg(test)]
mod tests;
