//! Pose-graph optimisation: ORB-SLAM2's essential-graph step of loop closing
//! (`Optimizer::OptimizeEssentialGraph`), in SE(3) for rigid maps (RGB-D, stereo), in Sim(3)
//! for a single camera's, whose scale drifts ([`optimise_sim3`]), and in 4 degrees of freedom
//! (yaw about gravity and position) for a visual-inertial map, whose roll and pitch gravity
//! fixes ([`optimise_4dof`]: ORB-SLAM3's `OptimizeEssentialGraph4DoF`, VINS-Fusion's pose graph).
//!
//! Nodes are key-frame poses (`world_from_cam`); each edge holds a measured relative pose
//! `a_from_b` between two of them. The residual of an edge is the vector (translation,
//! rotation vector, and in Sim(3) the scale's logarithm) of `measured^-1 * (T_a^-1 T_b)`, with
//! identity information as ORB-SLAM2's Sim(3) edges; poses move by right-multiplied
//! increments `T exp(delta)`. Levenberg-Marquardt (ORB-SLAM2: 20 iterations); each step's
//! normal equations are solved on their block-sparse structure by conjugate gradients with a
//! block-Jacobi preconditioner, so a map of thousands of key frames costs what its edges cost,
//! not a dense factorisation.

use dynaflow_vision::geometry::exp_se3;
use nalgebra::{Isometry3, SMatrix, SVector, Translation3, Unit, UnitQuaternion, Vector3, Vector4, Vector6};

use crate::sim3::Sim3;

/// A relative-pose measurement between nodes `a` and `b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge<P> {
    /// Index of the first node.
    pub a: usize,
    /// Index of the second node.
    pub b: usize,
    /// Measured `a_from_b` (`T_a^-1 T_b` when the measurement is exact).
    pub a_from_b: P,
}

/// An SE(3) edge.
pub type PoseEdge = Edge<Isometry3<f64>>;
/// A Sim(3) edge.
pub type Sim3Edge = Edge<Sim3>;

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

/// A pose the graph moves: a group with `D` degrees of freedom.
trait Node<const D: usize>: Copy {
    /// The residual of `measured` between `a` and `b`: zero when `a^-1 b == measured`.
    fn residual(measured: &Self, a: &Self, b: &Self) -> SVector<f64, D>;
    /// `self * exp(d)`.
    fn retract(&self, d: &SVector<f64, D>) -> Self;
}

impl Node<6> for Isometry3<f64> {
    fn residual(measured: &Self, a: &Self, b: &Self) -> Vector6<f64> {
        let e = measured.inverse() * (a.inverse() * b);
        let (t, r) = (e.translation.vector, e.rotation.scaled_axis());
        Vector6::new(t.x, t.y, t.z, r.x, r.y, r.z)
    }
    fn retract(&self, d: &Vector6<f64>) -> Self {
        let mut q = self * exp_se3(d);
        q.rotation.renormalize();
        q
    }
}

impl Node<7> for Sim3 {
    fn residual(measured: &Self, a: &Self, b: &Self) -> SVector<f64, 7> {
        (measured.inverse() * (a.inverse() * *b)).log7()
    }
    fn retract(&self, d: &SVector<f64, 7>) -> Self {
        *self * Sim3::exp7(d)
    }
}

/// A pose of a visual-inertial map: it moves in yaw about the world's `up` axis and in
/// position; its roll and pitch (gravity's direction in the camera) are held.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Upright {
    pose: Isometry3<f64>,
    up: Unit<Vector3<f64>>,
}

impl Node<4> for Upright {
    /// The relative pose error's translation and its rotation about `up` (as seen in `b`'s
    /// frame): VINS-Fusion's four residuals. Its roll and pitch no node can change.
    fn residual(measured: &Self, a: &Self, b: &Self) -> Vector4<f64> {
        let e = measured.pose.inverse() * (a.pose.inverse() * b.pose);
        let (t, r) = (e.translation.vector, e.rotation.scaled_axis());
        let up_b = b.pose.rotation.inverse() * b.up.into_inner();
        Vector4::new(t.x, t.y, t.z, r.dot(&up_b))
    }
    /// `d`: the position's step in the world (3) and a turn about `up` (1).
    fn retract(&self, d: &Vector4<f64>) -> Self {
        let turn = UnitQuaternion::from_axis_angle(&self.up, d[3]);
        let mut rotation = turn * self.pose.rotation;
        rotation.renormalize();
        let t = self.pose.translation.vector + Vector3::new(d[0], d[1], d[2]);
        Self { pose: Isometry3::from_parts(Translation3::from(t), rotation), up: self.up }
    }
}

fn cost<P: Node<D>, const D: usize>(poses: &[P], edges: &[Edge<P>]) -> f64 {
    edges.iter().map(|e| P::residual(&e.a_from_b, &poses[e.a], &poses[e.b]).norm_squared()).sum()
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
    optimise_graph(poses, fixed, edges, iterations)
}

/// [`optimise`] in Sim(3): the essential graph of a monocular map, where a loop's correction
/// also corrects the scale drift accumulated along it (ORB-SLAM2's `OptimizeEssentialGraph`).
pub fn optimise_sim3(poses: &mut [Sim3], fixed: &[bool], edges: &[Sim3Edge], iterations: usize) -> PoseGraphReport {
    optimise_graph(poses, fixed, edges, iterations)
}

/// [`optimise`] in 4 degrees of freedom, for a map whose gravity is known: `up` is the world's
/// up axis (against gravity); each pose moves in yaw about it and in position, and keeps its
/// roll and pitch (ORB-SLAM3's `OptimizeEssentialGraph4DoF`; VINS-Fusion's 4-DoF pose graph).
/// The edges' roll and pitch disagreements stay as they are: no node can take them up.
pub fn optimise_4dof(
    poses: &mut [Isometry3<f64>],
    up: &Unit<Vector3<f64>>,
    fixed: &[bool],
    edges: &[PoseEdge],
    iterations: usize,
) -> PoseGraphReport {
    let mut nodes: Vec<Upright> = poses.iter().map(|&pose| Upright { pose, up: *up }).collect();
    let edges: Vec<Edge<Upright>> =
        edges.iter().map(|e| Edge { a: e.a, b: e.b, a_from_b: Upright { pose: e.a_from_b, up: *up } }).collect();
    let report = optimise_graph(&mut nodes, fixed, &edges, iterations);
    for (p, n) in poses.iter_mut().zip(&nodes) {
        *p = n.pose;
    }
    report
}

fn optimise_graph<P: Node<D>, const D: usize>(
    poses: &mut [P],
    fixed: &[bool],
    edges: &[Edge<P>],
    iterations: usize,
) -> PoseGraphReport {
    let n = poses.len();
    let edges: Vec<Edge<P>> = edges.iter().copied().filter(|e| e.a < n && e.b < n && e.a != e.b).collect();
    let is_fixed = |i: usize| fixed.get(i).copied().unwrap_or(false);
    let mut current = cost(poses, &edges);
    let mut report = PoseGraphReport { initial_cost: current, final_cost: current, iterations: 0 };
    let mut lambda = 1e-4;
    for _ in 0..iterations {
        report.iterations += 1;
        // Normal equations: diagonal blocks per node, one off-diagonal block per edge.
        let mut diag = vec![SMatrix::<f64, D, D>::zeros(); n];
        let mut off: Vec<SMatrix<f64, D, D>> = Vec::with_capacity(edges.len());
        let mut g = vec![SVector::<f64, D>::zeros(); n];
        for e in &edges {
            let r = P::residual(&e.a_from_b, &poses[e.a], &poses[e.b]);
            let (ja, jb) = jacobians(e, &poses[e.a], &poses[e.b]);
            diag[e.a] += ja.transpose() * ja;
            diag[e.b] += jb.transpose() * jb;
            off.push(ja.transpose() * jb);
            g[e.a] += ja.transpose() * r;
            g[e.b] += jb.transpose() * r;
        }
        let mut improved = false;
        for _ in 0..10 {
            let damped: Vec<SMatrix<f64, D, D>> = diag
                .iter()
                .enumerate()
                .map(|(i, d)| {
                    if is_fixed(i) {
                        SMatrix::identity()
                    } else {
                        d + SMatrix::from_diagonal(&(d.diagonal() * lambda + SVector::repeat(1e-9)))
                    }
                })
                .collect();
            let rhs: Vec<SVector<f64, D>> =
                g.iter().enumerate().map(|(i, v)| if is_fixed(i) { SVector::zeros() } else { -v }).collect();
            let step = solve_pcg(&damped, &edges, &off, &rhs, &is_fixed);
            let trial: Vec<P> = poses.iter().zip(&step).map(|(p, d)| p.retract(d)).collect();
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
/// (central differences; the residual is smooth and cheap, and 2D evaluations per edge cost
/// less than the solve).
fn jacobians<P: Node<D>, const D: usize>(e: &Edge<P>, ta: &P, tb: &P) -> (SMatrix<f64, D, D>, SMatrix<f64, D, D>) {
    const H: f64 = 1e-6;
    let mut ja = SMatrix::<f64, D, D>::zeros();
    let mut jb = SMatrix::<f64, D, D>::zeros();
    for k in 0..D {
        let mut d = SVector::<f64, D>::zeros();
        d[k] = H;
        let m = &e.a_from_b;
        let col = (P::residual(m, &ta.retract(&d), tb) - P::residual(m, &ta.retract(&-d), tb)) / (2.0 * H);
        ja.set_column(k, &col);
        let col = (P::residual(m, ta, &tb.retract(&d)) - P::residual(m, ta, &tb.retract(&-d))) / (2.0 * H);
        jb.set_column(k, &col);
    }
    (ja, jb)
}

/// Conjugate gradients on the block-sparse system (block-Jacobi preconditioned); fixed nodes
/// stay at zero.
fn solve_pcg<P, const D: usize>(
    diag: &[SMatrix<f64, D, D>],
    edges: &[Edge<P>],
    off: &[SMatrix<f64, D, D>],
    rhs: &[SVector<f64, D>],
    is_fixed: &dyn Fn(usize) -> bool,
) -> Vec<SVector<f64, D>> {
    let n = diag.len();
    let matvec = |x: &[SVector<f64, D>]| -> Vec<SVector<f64, D>> {
        let mut y: Vec<SVector<f64, D>> = diag.iter().zip(x).map(|(d, v)| d * v).collect();
        for (e, h) in edges.iter().zip(off) {
            if is_fixed(e.a) || is_fixed(e.b) {
                continue;
            }
            y[e.a] += h * x[e.b];
            y[e.b] += h.transpose() * x[e.a];
        }
        for (i, v) in y.iter_mut().enumerate() {
            if is_fixed(i) {
                *v = SVector::zeros();
            }
        }
        y
    };
    let inv: Vec<SMatrix<f64, D, D>> = diag.iter().map(|d| d.try_inverse().unwrap_or_else(SMatrix::identity)).collect();
    let dot = |a: &[SVector<f64, D>], b: &[SVector<f64, D>]| a.iter().zip(b).map(|(x, y)| x.dot(y)).sum::<f64>();
    let mut x = vec![SVector::zeros(); n];
    let mut r: Vec<SVector<f64, D>> = rhs.to_vec();
    let mut z: Vec<SVector<f64, D>> = inv.iter().zip(&r).map(|(m, v)| m * v).collect();
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let norm0 = dot(&r, &r).sqrt();
    if norm0 == 0.0 {
        return x;
    }
    for _ in 0..(D * n).min(2000) {
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
    /// A monocular path whose scale drifts 1.5 % a step (step i measured 1.015^i too long) with
    /// a small yaw error; the SE(3) graph cannot remove a drift in scale, the Sim(3) graph with one
    /// loop edge does, and the end key frame's scale comes back to the loop's.
    #[test]
    fn a_sim3_loop_edge_removes_scale_drift() {
        use crate::sim3::Sim3;
        let n = 24;
        let truth: Vec<Isometry3<f64>> = (0..n)
            .map(|i| {
                let a = f64::from(i) / f64::from(n) * std::f64::consts::TAU;
                Isometry3::from_parts(
                    Translation3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.0),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a),
                )
            })
            .collect();
        let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3f64.to_radians());
        // Odometry in the drifting map: step i's translation in a scale 1.015^i times the truth's.
        let mut drifted = vec![Sim3::from_isometry(&truth[0])];
        let mut edges = Vec::new();
        let mut scale = 1.0;
        for i in 1..truth.len() {
            let step = truth[i - 1].inverse() * truth[i];
            scale *= 1.015;
            let odo = Sim3 { rotation: step.rotation * yaw, translation: step.translation.vector * scale, scale: 1.0 };
            drifted.push(drifted[i - 1] * odo);
            edges.push(Edge { a: i - 1, b: i, a_from_b: odo });
        }
        let last = truth.len() - 1;
        let err = |p: &[Sim3]| {
            p.iter().zip(&truth).map(|(a, b)| (a.translation - b.translation.vector).norm()).fold(0.0, f64::max)
        };
        let before = err(&drifted);
        assert!(before > 0.3, "the odometry drifts: {before}");
        // The loop, measured as a Sim(3) solver does: the first key frame against the last,
        // with the scale between their maps (the last one's map is `scale` times too large).
        let loop_from_last = Sim3 { scale: 1.0 / scale, ..Sim3::from_isometry(&(truth[0].inverse() * truth[last])) };
        edges.push(Edge { a: 0, b: last, a_from_b: loop_from_last });
        let mut fixed = vec![false; truth.len()];
        fixed[0] = true;
        let mut poses = drifted.clone();
        let report = optimise_sim3(&mut poses, &fixed, &edges, 20);
        let after = err(&poses);
        assert!(report.final_cost < 0.01 * report.initial_cost, "{report:?}");
        assert!(after < 0.2 * before, "max error {before:.3} -> {after:.3} m");
        assert!((poses[last].scale * scale - 1.0).abs() < 0.05, "end scale {} (drift {scale})", poses[last].scale);
        // The same graph in SE(3) (the loop without its scale) keeps more of the error.
        let mut rigid: Vec<Isometry3<f64>> = drifted.iter().map(Sim3::rigid).collect();
        let mut se3_edges: Vec<PoseEdge> =
            edges.iter().map(|e| Edge { a: e.a, b: e.b, a_from_b: e.a_from_b.rigid() }).collect();
        se3_edges.last_mut().unwrap().a_from_b = truth[0].inverse() * truth[last];
        optimise(&mut rigid, &fixed, &se3_edges, 20);
        let se3_err = rigid
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a.translation.vector - b.translation.vector).norm())
            .fold(0.0, f64::max);
        assert!(after < 0.5 * se3_err, "Sim(3) {after:.3} m against SE(3) {se3_err:.3} m");
    }
    /// A path that drifts in yaw and position only (as a visual-inertial map does: gravity
    /// holds roll and pitch) with a loop edge that also carries a small roll error: the 4-DoF
    /// graph takes the drift down as far as the SE(3) graph does and leaves every pose's roll and
    /// pitch exactly as they were, where the SE(3) graph spreads the loop's roll error over the
    /// path.
    #[test]
    fn a_4dof_graph_removes_yaw_drift_and_keeps_gravity() {
        let up = Vector3::z_axis();
        let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.3);
        let truth: Vec<Isometry3<f64>> = (0..20)
            .map(|i| {
                let a = f64::from(i) / 20.0 * std::f64::consts::TAU;
                Isometry3::from_parts(
                    Translation3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.1 * a.sin()),
                    UnitQuaternion::from_axis_angle(&up, a) * tilt,
                )
            })
            .collect();
        // Odometry drifting 0.6 degrees of yaw (about the world's up) and 1 cm a step.
        let mut drifted = vec![truth[0]];
        let mut edges = Vec::new();
        for i in 1..truth.len() {
            let yaw = UnitQuaternion::from_axis_angle(&up, 0.6f64.to_radians() * f64::from(i as u32));
            let p = Isometry3::from_parts(
                Translation3::from(
                    yaw * truth[i].translation.vector + Vector3::new(0.01, 0.0, 0.0) * f64::from(i as u32),
                ),
                yaw * truth[i].rotation,
            );
            edges.push(PoseEdge { a: i - 1, b: i, a_from_b: drifted[i - 1].inverse() * p });
            drifted.push(p);
        }
        let last = truth.len() - 1;
        // The loop edge measured with a 1-degree roll error.
        let roll = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 1f64.to_radians()),
        );
        edges.push(PoseEdge { a: 0, b: last, a_from_b: truth[0].inverse() * truth[last] * roll });
        let mut fixed = vec![false; truth.len()];
        fixed[0] = true;
        let err = |p: &[Isometry3<f64>]| {
            p.iter().zip(&truth).map(|(a, b)| (a.translation.vector - b.translation.vector).norm()).fold(0.0, f64::max)
        };
        // Gravity's direction in each camera: the angle between before and after.
        let gravity_change = |p: &[Isometry3<f64>]| {
            p.iter()
                .zip(&drifted)
                .map(|(a, b)| (a.rotation.inverse() * up.into_inner()).angle(&(b.rotation.inverse() * up.into_inner())))
                .fold(0.0, f64::max)
        };
        let before = err(&drifted);
        let mut poses = drifted.clone();
        let report = optimise_4dof(&mut poses, &up, &fixed, &edges, 20);
        let after = err(&poses);
        assert!(before > 0.3, "the odometry drifts: {before}");
        assert!(report.final_cost < 0.05 * report.initial_cost, "{report:?}");
        assert!(gravity_change(&poses) < 1e-9, "roll/pitch moved by {} rad", gravity_change(&poses));
        let mut rigid = drifted.clone();
        optimise(&mut rigid, &fixed, &edges, 20);
        let moved = gravity_change(&rigid);
        assert!(moved > 1e-3, "the SE(3) graph tilts the path by the loop's roll error: {moved} rad");
        // The drift goes as far as the SE(3) graph takes it (which spreads it over every edge).
        let rigid_after = err(&rigid);
        println!("max error {before:.3} m -> 4 DoF {after:.3} m, SE(3) {rigid_after:.3} m");
        assert!(
            after < 0.5 * before && after <= 1.05 * rigid_after,
            "{before:.3} -> {after:.3} m (SE(3): {rigid_after:.3})"
        );
    }
}
