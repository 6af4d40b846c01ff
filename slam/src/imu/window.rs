//! Visual-inertial optimisation of the newest key frames (after ORB-SLAM3's `LocalInertialBA`),
//! with the map points held: each window key frame's body pose and velocity and the window's
//! biases from the key frames' observations of the map and the pre-integrated IMU between
//! consecutive key frames.
//!
//! Local mapping owns the points and refines them with the key-frame poses (visual BA); this
//! optimisation gives the tracker what the inertial-only refinement cannot: velocities that
//! agree with poses the IMU agrees with too. With the poses held (the inertial-only
//! refinement), their noise turns into velocity error that the pre-integration's tight
//! covariance then trusts; here a pose moves where its observations allow and the velocity
//! follows both.
//!
//! Departures from ORB-SLAM3: the points are held (ORB-SLAM3 optimises them with the window);
//! one bias for the window (ORB-SLAM3 keeps one per key frame, tied by random-walk edges) with
//! a prior centred on the current estimate whose information is the random walk's over the
//! window's span (ORB-SLAM3's chain of random-walk edges to the fixed key frame before the
//! window has the same strength).
//!
//! Parameters per key frame: `R = R̂·Exp(δθ)`, `p = p̂ + R̂·δp` (body), `v = v̂ + δv` (world);
//! the bias additively. Visual residuals as [`super::track::optimize_inertial_pose`]'s (Huber at
//! the chi-square 95 % bounds, observations re-classified after each round); the inertial
//! residuals whitened by each span's covariance, their Jacobians by central differences.

use dynaflow_msg::ImuCalibration;
use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{CHI2_2DOF_95, CHI2_3DOF_95, LmDamping, PoseObservation, huber, observation_jacobian};
use nalgebra::{DMatrix, DVector, Isometry3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3};

use super::propagate::NavState;
use super::{Bias, Preintegrated};

/// One key frame of the window.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowKeyFrame {
    /// Its body state to start from (the biases are the window's).
    pub world_from_body: Isometry3<f64>,
    /// Its velocity to start from, world, m/s.
    pub velocity: Vector3<f64>,
    /// Its observations of map points (held).
    pub observations: Vec<PoseObservation>,
}

/// What [`optimize_window`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct WindowFit {
    /// Each key frame's state, with the window's bias.
    pub states: Vec<NavState>,
    /// The window's bias.
    pub bias: Bias,
    /// Per key frame and observation: within its chi-square bound at the end.
    pub inliers: Vec<Vec<bool>>,
    /// The inertial residuals' summed squared Mahalanobis norm at the end.
    pub inertial_chi2: f64,
    /// With the scale free: metres per unit of the map the points are in (1 when held). The
    /// states are metric: a point `X` of the map is at `scale · X`.
    pub scale: f64,
}

/// Rounds of Levenberg-Marquardt iterations, observations re-classified after each (ORB-SLAM3's
/// local BA: two rounds, outliers dropped after the first).
const ROUNDS: usize = 2;
/// Iterations per round (ORB-SLAM3's `LocalInertialBA` runs 10).
const ITERATIONS: usize = 10;

/// Optimise the window: see the module documentation. `between[k]` spans key frames `k` and
/// `k + 1`; `bias` is the current estimate (the prior's centre); `calibration` gives the
/// camera's pose in the body and the biases' random walks. With `free_scale` (a single camera's
/// map) the points' scale about the world's origin is a variable too (`s = exp(σ)`): the IMU
/// then tells how far off the map's scale is, with the points' shape held.
#[allow(clippy::too_many_arguments)]
pub fn optimize_window(
    kfs: &[WindowKeyFrame],
    between: &[Preintegrated],
    cam: &Pinhole,
    bf: f64,
    calibration: &ImuCalibration,
    gravity_w: &Vector3<f64>,
    bias: Bias,
    free_scale: bool,
) -> WindowFit {
    let n = kfs.len();
    assert_eq!(between.len() + 1, n.max(1), "one pre-integration between each pair of key frames");
    let dim = 9 * n + 6 + usize::from(free_scale);
    let sigma_at = 9 * n + 6;
    let span: f64 = between.iter().map(Preintegrated::delta_t).sum::<f64>().max(1e-3);
    // The random walk's information over the window (its variance grows as density² · time).
    let prior_g = 1.0 / (calibration.gyro_random_walk.powi(2) * span).max(1e-18);
    let prior_a = 1.0 / (calibration.accel_random_walk.powi(2) * span).max(1e-18);
    let cam_from_body = calibration.body_from_cam.inverse();
    let r_cb = cam_from_body.rotation.to_rotation_matrix().into_inner();
    let bound = |o: &PoseObservation| if o.depth.is_some() && bf > 0.0 { CHI2_3DOF_95 } else { CHI2_2DOF_95 };
    let infos: Vec<SMatrix<f64, 9, 9>> =
        between.iter().map(|p| p.covariance().try_inverse().unwrap_or_else(SMatrix::zeros)).collect();

    #[derive(Clone)]
    struct State {
        poses: Vec<Isometry3<f64>>,
        velocities: Vec<Vector3<f64>>,
        bias: Bias,
        /// log of the points' scale.
        sigma: f64,
    }
    let camera_point = |pose: &Isometry3<f64>, sigma: f64, o: &PoseObservation| {
        let pb = pose.inverse_transform_point(&nalgebra::Point3::from(o.point.coords * sigma.exp())).coords;
        (pb, cam_from_body * nalgebra::Point3::from(pb))
    };
    let chi2 = |pose: &Isometry3<f64>, sigma: f64, o: &PoseObservation| -> Option<f64> {
        let (_, pc) = camera_point(pose, sigma, o);
        let (r, _) = observation_jacobian(cam, bf, &pc, o)?;
        Some(r.norm_squared() / (o.sigma * o.sigma))
    };
    // The inertial residual of span `k` at the state (the pre-integration at the state's bias).
    let inertial = |s: &State, k: usize, pre: &Preintegrated| -> SVector<f64, 9> {
        let (ri, rj) = (
            s.poses[k].rotation.to_rotation_matrix().into_inner(),
            s.poses[k + 1].rotation.to_rotation_matrix().into_inner(),
        );
        let (pi, pj) = (s.poses[k].translation.vector, s.poses[k + 1].translation.vector);
        pre.residual((&ri, &pi, &s.velocities[k]), (&rj, &pj, &s.velocities[k + 1]), gravity_w).0
    };
    // Its squared Mahalanobis norm.
    let whitened = |s: &State, k: usize, pre: &Preintegrated| -> f64 {
        let r = inertial(s, k, pre);
        (r.transpose() * infos[k] * r)[(0, 0)]
    };
    let with_bias = |s: &State| -> Vec<Preintegrated> {
        between
            .iter()
            .map(|p| {
                let mut p = p.clone();
                p.set_bias(s.bias);
                p
            })
            .collect()
    };
    let bias_delta = |s: &State| -> SVector<f64, 6> {
        let (g, a) = (s.bias.gyro - bias.gyro, s.bias.accel - bias.accel);
        SVector::<f64, 6>::new(g.x, g.y, g.z, a.x, a.y, a.z)
    };
    let cost_of = |s: &State, mask: &[Vec<bool>]| -> f64 {
        let pres = with_bias(s);
        let mut cost = 0.0;
        for (k, kf) in kfs.iter().enumerate() {
            for (o, m) in kf.observations.iter().zip(&mask[k]) {
                if *m {
                    cost += chi2(&s.poses[k], s.sigma, o).map_or(0.0, |c| huber(c, bound(o).sqrt()).0);
                }
            }
        }
        cost += pres.iter().enumerate().map(|(k, pre)| whitened(s, k, pre)).sum::<f64>();
        let d = bias_delta(s);
        cost + prior_g * d.fixed_rows::<3>(0).norm_squared() + prior_a * d.fixed_rows::<3>(3).norm_squared()
    };
    let apply = |s: &State, d: &DVector<f64>| -> State {
        let mut out = s.clone();
        for k in 0..n {
            let b = 9 * k;
            let (r, p) = (s.poses[k].rotation, s.poses[k].translation.vector);
            let mut rotation = r * UnitQuaternion::from_scaled_axis(Vector3::new(d[b], d[b + 1], d[b + 2]));
            rotation.renormalize();
            let p = p + r * Vector3::new(d[b + 3], d[b + 4], d[b + 5]);
            out.poses[k] = Isometry3::from_parts(Translation3::from(p), rotation);
            out.velocities[k] = s.velocities[k] + Vector3::new(d[b + 6], d[b + 7], d[b + 8]);
        }
        let b = 9 * n;
        out.bias.gyro += Vector3::new(d[b], d[b + 1], d[b + 2]);
        out.bias.accel += Vector3::new(d[b + 3], d[b + 4], d[b + 5]);
        if free_scale {
            out.sigma += d[sigma_at];
        }
        out
    };

    let mut state = State {
        poses: kfs.iter().map(|k| k.world_from_body).collect(),
        velocities: kfs.iter().map(|k| k.velocity).collect(),
        bias,
        sigma: 0.0,
    };
    let mut inlier: Vec<Vec<bool>> = kfs.iter().map(|k| vec![true; k.observations.len()]).collect();
    for _round in 0..ROUNDS {
        let mut lm = LmDamping::default();
        let mut cost = cost_of(&state, &inlier);
        for _ in 0..ITERATIONS {
            let mut h = DMatrix::<f64>::zeros(dim, dim);
            let mut g = DVector::<f64>::zeros(dim);
            // Visual: each key frame's pose block.
            for (k, kf) in kfs.iter().enumerate() {
                let b = 9 * k;
                for (o, _) in kf.observations.iter().zip(&inlier[k]).filter(|(_, m)| **m) {
                    let (pb, pc) = camera_point(&state.poses[k], state.sigma, o);
                    let Some((res, jac)) = observation_jacobian(cam, bf, &pc, o) else { continue };
                    let w_info = 1.0 / (o.sigma * o.sigma);
                    let (_, w) = huber(res.norm_squared() * w_info, bound(o).sqrt());
                    let dpc = jac.fixed_view::<3, 3>(0, 0) * r_cb;
                    let mut jb = SMatrix::<f64, 3, 6>::zeros();
                    jb.fixed_view_mut::<3, 3>(0, 0).copy_from(&(dpc * pb.cross_matrix()));
                    jb.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-dpc));
                    let wi = w * w_info;
                    let mut hb = h.view_mut((b, b), (6, 6));
                    hb += wi * (jb.transpose() * jb);
                    let mut gb = g.rows_mut(b, 6);
                    gb += wi * (jb.transpose() * res);
                    if free_scale {
                        // ∂pb/∂σ = R_wbᵀ · (s·X).
                        let r_wb = state.poses[k].rotation.to_rotation_matrix().into_inner();
                        let js = dpc * (r_wb.transpose() * (o.point.coords * state.sigma.exp()));
                        let cross = jb.transpose() * js;
                        for a in 0..6 {
                            h[(b + a, sigma_at)] += wi * cross[a];
                            h[(sigma_at, b + a)] += wi * cross[a];
                        }
                        h[(sigma_at, sigma_at)] += wi * js.norm_squared();
                        g[sigma_at] += wi * js.dot(&res);
                    }
                }
            }
            // Inertial: key frames k and k + 1 and the bias, by central differences.
            let pres = with_bias(&state);
            for (k, pre) in pres.iter().enumerate() {
                let r0 = inertial(&state, k, pre);
                let cols: Vec<usize> = (9 * k..9 * k + 18).chain(9 * n..9 * n + 6).collect();
                let mut j = DMatrix::<f64>::zeros(9, cols.len());
                for (c, &col) in cols.iter().enumerate() {
                    let eps = 1e-6;
                    let mut d = DVector::<f64>::zeros(dim);
                    d[col] = eps;
                    let plus = apply(&state, &d);
                    d[col] = -eps;
                    let minus = apply(&state, &d);
                    let (rp, rm) = if col >= 9 * n {
                        let (mut pp, mut pm) = (between[k].clone(), between[k].clone());
                        pp.set_bias(plus.bias);
                        pm.set_bias(minus.bias);
                        (inertial(&plus, k, &pp), inertial(&minus, k, &pm))
                    } else {
                        (inertial(&plus, k, pre), inertial(&minus, k, pre))
                    };
                    j.set_column(c, &((rp - rm) / (2.0 * eps)));
                }
                let info = DMatrix::from_column_slice(9, 9, infos[k].as_slice());
                let jt_info = j.transpose() * &info;
                let hk = &jt_info * &j;
                let gk = &jt_info * DVector::from_column_slice(r0.as_slice());
                for (a, &ca) in cols.iter().enumerate() {
                    g[ca] += gk[a];
                    for (b, &cb) in cols.iter().enumerate() {
                        h[(ca, cb)] += hk[(a, b)];
                    }
                }
            }
            // The bias prior.
            let d = bias_delta(&state);
            for a in 0..6 {
                let w = if a < 3 { prior_g } else { prior_a };
                h[(9 * n + a, 9 * n + a)] += w;
                g[9 * n + a] += w * d[a];
            }
            let Some(step) = lm.damped(&h).cholesky().map(|c| c.solve(&(-&g))) else { break };
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
        for (k, kf) in kfs.iter().enumerate() {
            for (flag, o) in inlier[k].iter_mut().zip(&kf.observations) {
                *flag = chi2(&state.poses[k], state.sigma, o).is_some_and(|c| c <= bound(o));
            }
        }
    }
    let pres = with_bias(&state);
    let inertial_chi2 = pres.iter().enumerate().map(|(k, pre)| whitened(&state, k, pre)).sum();
    WindowFit {
        states: (0..n)
            .map(|k| NavState { world_from_body: state.poses[k], velocity: state.velocities[k], bias: state.bias })
            .collect(),
        bias: state.bias,
        inliers: inlier,
        inertial_chi2,
        scale: state.sigma.exp(),
    }
}

#[cfg(test)]
mod tests;
