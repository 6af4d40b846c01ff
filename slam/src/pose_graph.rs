//! SE(3) pose-graph optimisation: ORB-SLAM2's essential-graph step of loop closing
//! (`Optimizer::OptimizeEssentialGraph`), written for rigid maps (RGB-D, stereo).
//!
//! Nodes are key-frame poses (`world_from_cam`); each edge holds a measured relative pose
//! `a_from_b` between two of them. The residual of an edge is the 6-vector (translation,
//! rotation vector) of `measured^-1 * (T_a^-1 T_b)`, with identity information as ORB-SLAM2's
//! Sim(3) edges; poses move by right-multiplied increments `T exp(delta)`. Levenberg-Marquardt
//! (ORB-SLAM2: 20 iterations); each step's normal equations are solved on their block-sparse
//! structure by conjugate gradients with a block-Jacobi preconditioner, so a map of thousands
//! of key frames costs what its edges cost, not a dense 6n x 6n factorisation.

use dynaflow_vision::geometry::exp_se3;
use nalgebra::{Isometry3, Matrix6, Vector6};

/// A relative-pose measurement between nodes `a` and `b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseEdge {
    /// Index of the first node.
    pub a: usize,
    /// Index of the second node.
    pub b: usize,
    /// Measured `a_from_b` (`T_a^-1 T_b` when the measurement is exact).
    pub a_from_b: Isometry3<f64>,
}

/// What an optimisation did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoseGraphReport {
    /// Sum of squared residuals before.
    pub initial_cost: f64,
    /// And after.
    pub final_cost: f64,
    /// Levenberg-Marquardt iterations run.
    pub iterations: usize,
}

fn residual(edge: &PoseEdge, ta: &Isometry3<f64>, tb: &Isometry3<f64>) -> Vector6<f64> {
    let e = edge.a_from_b.inverse() * (ta.inverse() * tb);
    let t = e.translation.vector;
    let r = e.rotation.scaled_axis();
    Vector6::new(t.x, t.y, t.z, r.x, r.y, r.z)
}

fn cost(poses: &[Isometry3<f64>], edges: &[PoseEdge]) -> f64 {
    edges.iter().map(|e| residual(e, &poses[e.a], &poses[e.b]).norm_squared()).sum()
}

/// Optimise `poses` in place; `fixed[i]` holds node `i` where it is (at least one node should
/// be fixed: the graph is otherwise free to move as a whole). Edges naming a node out of range
/// are ignored.
pub fn optimise(
    poses: &mut [Isometry3<f64>],
    fixed: &[bool],
    edges: &[PoseEdge],
    iterations: usize,
) -> PoseGraphReport {
    let n = poses.len();
    let edges: Vec<PoseEdge> = edges.iter().copied().filter(|e| e.a < n && e.b < n && e.a != e.b).collect();
    let is_fixed = |i: usize| fixed.get(i).copied().unwrap_or(false);
    let mut current = cost(poses, &edges);
    let mut report = PoseGraphReport { initial_cost: current, final_cost: current, iterations: 0 };
    let mut lambda = 1e-4;
    for _ in 0..iterations {
        report.iterations += 1;
        // Normal equations: diagonal blocks per node, one off-diagonal block per edge.
        let mut diag = vec![Matrix6::<f64>::zeros(); n];
        let mut off: Vec<Matrix6<f64>> = Vec::with_capacity(edges.len());
        let mut g = vec![Vector6::<f64>::zeros(); n];
        for e in &edges {
            let r = residual(e, &poses[e.a], &poses[e.b]);
            let (ja, jb) = jacobians(e, &poses[e.a], &poses[e.b]);
            diag[e.a] += ja.transpose() * ja;
            diag[e.b] += jb.transpose() * jb;
            off.push(ja.transpose() * jb);
            g[e.a] += ja.transpose() * r;
            g[e.b] += jb.transpose() * r;
        }
        let mut improved = false;
        for _ in 0..10 {
            let damped: Vec<Matrix6<f64>> = diag
                .iter()
                .enumerate()
                .map(|(i, d)| {
                    if is_fixed(i) {
                        Matrix6::identity()
                    } else {
                        d + Matrix6::from_diagonal(&(d.diagonal() * lambda + Vector6::repeat(1e-9)))
                    }
                })
                .collect();
            let rhs: Vec<Vector6<f64>> =
                g.iter().enumerate().map(|(i, v)| if is_fixed(i) { Vector6::zeros() } else { -v }).collect();
            let step = solve_pcg(&damped, &edges, &off, &rhs, &is_fixed);
            let trial: Vec<Isometry3<f64>> = poses
                .iter()
                .zip(&step)
                .map(|(p, d)| {
                    let mut q = p * exp_se3(d);
                    q.rotation.renormalize();
                    q
                })
                .collect();
            let c = cost(&trial, &edges);
            if c.is_finite() && c < current {
                poses.copy_from_slice(&trial);
                let gain = (current - c) / current.max(1e-300);
                current = c;
                lambda = (lambda / 10.0).max(1e-9);
                improved = gain > 1e-12;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    report.final_cost = current;
    report
}

/// Numeric Jacobians of an edge's residual with respect to right increments of both ends
/// (central differences; the residual is smooth and cheap, and 12 evaluations per edge cost
/// less than the solve).
fn jacobians(e: &PoseEdge, ta: &Isometry3<f64>, tb: &Isometry3<f64>) -> (Matrix6<f64>, Matrix6<f64>) {
    const H: f64 = 1e-6;
    let mut ja = Matrix6::zeros();
    let mut jb = Matrix6::zeros();
    for k in 0..6 {
        let mut d = Vector6::zeros();
        d[k] = H;
        let (plus, minus) = (exp_se3(&d), exp_se3(&-d));
        let col = (residual(e, &(ta * plus), tb) - residual(e, &(ta * minus), tb)) / (2.0 * H);
        ja.set_column(k, &col);
        let col = (residual(e, ta, &(tb * plus)) - residual(e, ta, &(tb * minus))) / (2.0 * H);
        jb.set_column(k, &col);
    }
    (ja, jb)
}

/// Conjugate gradients on the block-sparse system (block-Jacobi preconditioned); fixed nodes
/// stay at zero.
fn solve_pcg(
    diag: &[Matrix6<f64>],
    edges: &[PoseEdge],
    off: &[Matrix6<f64>],
    rhs: &[Vector6<f64>],
    is_fixed: &dyn Fn(usize) -> bool,
) -> Vec<Vector6<f64>> {
    let n = diag.len();
    let matvec = |x: &[Vector6<f64>]| -> Vec<Vector6<f64>> {
        let mut y: Vec<Vector6<f64>> = diag.iter().zip(x).map(|(d, v)| d * v).collect();
        for (e, h) in edges.iter().zip(off) {
            if is_fixed(e.a) || is_fixed(e.b) {
                continue;
            }
            y[e.a] += h * x[e.b];
            y[e.b] += h.transpose() * x[e.a];
        }
        for (i, v) in y.iter_mut().enumerate() {
            if is_fixed(i) {
                *v = Vector6::zeros();
            }
        }
        y
    };
    let inv: Vec<Matrix6<f64>> = diag.iter().map(|d| d.try_inverse().unwrap_or_else(Matrix6::identity)).collect();
    let dot = |a: &[Vector6<f64>], b: &[Vector6<f64>]| a.iter().zip(b).map(|(x, y)| x.dot(y)).sum::<f64>();
    let mut x = vec![Vector6::zeros(); n];
    let mut r: Vec<Vector6<f64>> = rhs.to_vec();
    let mut z: Vec<Vector6<f64>> = inv.iter().zip(&r).map(|(m, v)| m * v).collect();
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let norm0 = dot(&r, &r).sqrt();
    if norm0 == 0.0 {
        return x;
    }
    for _ in 0..(6 * n).min(2000) {
        let ap = matvec(&p);
        let pap = dot(&p, &ap);
        if pap <= 0.0 || !pap.is_finite() {
            break;
        }
        let alpha = rz / pap;
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        if dot(&r, &r).sqrt() <= 1e-10 * norm0 {
            break;
        }
        z = inv.iter().zip(&r).map(|(m, v)| m * v).collect();
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    /// A square path of key frames whose odometry drifts in yaw; a loop edge from the last back
    /// to the first pulls the whole path back onto the truth.
    #[test]
    fn a_loop_edge_removes_accumulated_drift() {
        let truth: Vec<Isometry3<f64>> = (0..20)
            .map(|i| {
                let a = f64::from(i) / 20.0 * std::f64::consts::TAU;
                Isometry3::from_parts(
                    Translation3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.0),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a),
                )
            })
            .collect();
        // Odometry with a yaw error of 0.6 degrees per step and 1 cm of forward error.
        let bias = Isometry3::from_parts(
            Translation3::new(0.01, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.6f64.to_radians()),
        );
        let mut drifted = vec![truth[0]];
        let mut edges = Vec::new();
        for i in 1..truth.len() {
            let odo = truth[i - 1].inverse() * truth[i] * bias;
            drifted.push(drifted[i - 1] * odo);
            edges.push(PoseEdge { a: i - 1, b: i, a_from_b: odo });
        }
        let last = truth.len() - 1;
        let err = |p: &[Isometry3<f64>]| {
            p.iter().zip(&truth).map(|(a, b)| (a.translation.vector - b.translation.vector).norm()).fold(0.0, f64::max)
        };
        let before = err(&drifted);
        assert!(before > 0.3, "the odometry drifts: {before}");
        // The loop: the last pose measured against the first exactly.
        edges.push(PoseEdge { a: 0, b: last, a_from_b: truth[0].inverse() * truth[last] });
        let mut fixed = vec![false; truth.len()];
        fixed[0] = true;
        let mut poses = drifted.clone();
        let report = optimise(&mut poses, &fixed, &edges, 20);
        let after = err(&poses);
        assert!(report.final_cost < 0.01 * report.initial_cost, "{report:?}");
        assert!(after < 0.25 * before, "max error {before:.3} -> {after:.3} m");
        assert_eq!(poses[0], drifted[0], "the fixed node stays");
        // Without the loop edge nothing moves (the odometry is consistent with itself).
        let mut poses = drifted.clone();
        let r = optimise(&mut poses, &fixed, &edges[..edges.len() - 1], 20);
        assert!(r.initial_cost < 1e-20 && (err(&poses) - before).abs() < 1e-9, "{r:?}");
    }
}
