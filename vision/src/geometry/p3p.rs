//! The minimal absolute-pose problem (P3P) in the manner of Lambda Twist (Persson and
//! Nordberg, ECCV 2018): the three distance constraints on the unknown depths are two
//! homogeneous conics, a degenerate member of their pencil (one root of a cubic) splits into
//! two lines, and each line meets the conics in at most two points; the depths are then
//! polished by Gauss-Newton and the pose follows from the three camera-frame points.
//! Up to four solutions, no trigonometry, no quartic.

use super::fundamental::real_roots_cubic;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Homogeneous roots `(a, b)` of `A a^2 + B a b + C b^2 = 0`.
fn homogeneous_quadratic_roots(qa: f64, qb: f64, qc: f64) -> Vec<(f64, f64)> {
    let disc = qb * qb - 4.0 * qa * qc;
    if disc < 0.0 {
        return Vec::new();
    }
    let s = disc.sqrt();
    if qa.abs() >= qc.abs() {
        if qa == 0.0 {
            return Vec::new();
        }
        // a / b = (-B +- s) / 2A.
        vec![((-qb + s) / (2.0 * qa), 1.0), ((-qb - s) / (2.0 * qa), 1.0)]
    } else {
        // b / a = (-B +- s) / 2C.
        vec![(1.0, (-qb + s) / (2.0 * qc)), (1.0, (-qb - s) / (2.0 * qc))]
    }
}

/// Every `cam_from_world` that maps the three world points onto the three bearing vectors
/// (any length; they are normalised), at most four. Empty for degenerate input (collinear
/// or coincident points, parallel bearings).
pub fn p3p(world: &[Point3<f64>; 3], bearings: &[Vector3<f64>; 3]) -> Vec<Isometry3<f64>> {
    let mut y = [Vector3::zeros(); 3];
    for (yi, b) in y.iter_mut().zip(bearings) {
        let n = b.norm();
        if !(n > 1e-12 && n.is_finite()) {
            return Vec::new();
        }
        *yi = b / n;
    }
    let (x1, x2, x3) = (world[0].coords, world[1].coords, world[2].coords);
    let (d12, d13, d23) = ((x1 - x2).norm_squared(), (x1 - x3).norm_squared(), (x2 - x3).norm_squared());
    let (b12, b13, b23) = (y[0].dot(&y[1]), y[0].dot(&y[2]), y[1].dot(&y[2]));
    let scale = d12.max(d13).max(d23);
    if !(d12.min(d13).min(d23) > 1e-12 * scale && scale.is_finite()) {
        return Vec::new();
    }
    // Lambda^T M_ij Lambda = d_ij: |l_i y_i - l_j y_j|^2 = d_ij.
    let m12 = Matrix3::new(1.0, -b12, 0.0, -b12, 1.0, 0.0, 0.0, 0.0, 0.0);
    let m13 = Matrix3::new(1.0, 0.0, -b13, 0.0, 0.0, 0.0, -b13, 0.0, 1.0);
    let m23 = Matrix3::new(0.0, 0.0, 0.0, 0.0, 1.0, -b23, 0.0, -b23, 1.0);
    // Two homogeneous conics through the solutions (right-hand sides eliminated).
    let k1 = d13 * m12 - d12 * m13;
    let k2 = d23 * m13 - d13 * m23;
    // det(k1 + g k2) as a cubic in g, column by column.
    let det3 = |a: Vector3<f64>, b: Vector3<f64>, c: Vector3<f64>| a.dot(&b.cross(&c));
    let (a1, a2, a3) = (k1.column(0).into_owned(), k1.column(1).into_owned(), k1.column(2).into_owned());
    let (e1, e2, e3) = (k2.column(0).into_owned(), k2.column(1).into_owned(), k2.column(2).into_owned());
    let c3 = det3(e1, e2, e3);
    let c2 = det3(a1, e2, e3) + det3(e1, a2, e3) + det3(e1, e2, a3);
    let c1 = det3(e1, a2, a3) + det3(a1, e2, a3) + det3(a1, a2, e3);
    let c0 = det3(a1, a2, a3);
    let mut gammas = real_roots_cubic(c3, c2, c1, c0);
    // Largest root first (Lambda Twist's choice: best conditioned in practice).
    gammas.sort_by(|a, b| b.total_cmp(a));
    let mut lambdas: Vec<Vector3<f64>> = Vec::new();
    for g in gammas {
        let d0 = k1 + g * k2;
        let eig = d0.symmetric_eigen();
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| eig.eigenvalues[j].abs().total_cmp(&eig.eigenvalues[i].abs()));
        let (sa, sb) = (eig.eigenvalues[order[0]], eig.eigenvalues[order[1]]);
        if sa * sb >= 0.0 || sa.is_nan() || sb.is_nan() {
            continue;
        }
        let (ea, eb) = (eig.eigenvectors.column(order[0]).into_owned(), eig.eigenvectors.column(order[1]).into_owned());
        let s = (-sb / sa).sqrt();
        for normal in [ea - s * eb, ea + s * eb] {
            // Span of the line {Lambda : normal . Lambda = 0}.
            let axis = if normal.x.abs() <= normal.y.abs() && normal.x.abs() <= normal.z.abs() {
                Vector3::x()
            } else if normal.y.abs() <= normal.z.abs() {
                Vector3::y()
            } else {
                Vector3::z()
            };
            let u = normal.cross(&axis);
            let v = normal.cross(&u);
            if !(u.norm() > 1e-12 && v.norm() > 1e-12) {
                continue;
            }
            // Meet the line with conic k1 (k2 where k1 vanishes on it).
            let conic = if (u.dot(&(k1 * u))).abs() + (v.dot(&(k1 * v))).abs() > 1e-12 * scale { k1 } else { k2 };
            let qa = u.dot(&(conic * u));
            let qb = 2.0 * u.dot(&(conic * v));
            let qc = v.dot(&(conic * v));
            for (a, b) in homogeneous_quadratic_roots(qa, qb, qc) {
                let w = a * u + b * v;
                // Scale from the first constraint (or the one best conditioned).
                let (den, d) = [(w.dot(&(m12 * w)), d12), (w.dot(&(m13 * w)), d13), (w.dot(&(m23 * w)), d23)]
                    .into_iter()
                    .max_by(|p, q| p.0.total_cmp(&q.0))
                    .unwrap_or((0.0, 0.0));
                if den <= 1e-15 || den.is_nan() {
                    continue;
                }
                let mut l = w * (d / den).sqrt();
                if l.x < 0.0 && l.y < 0.0 && l.z < 0.0 {
                    l = -l;
                }
                if !(l.x > 0.0 && l.y > 0.0 && l.z > 0.0) {
                    continue;
                }
                lambdas.push(refine_depths(l, [b12, b13, b23], [d12, d13, d23]));
            }
        }
        if !lambdas.is_empty() {
            break;
        }
    }
    let mut poses: Vec<Isometry3<f64>> = Vec::new();
    for l in lambdas {
        let p = [l.x * y[0], l.y * y[1], l.z * y[2]];
        let (xa, xb) = (x1 - x2, x1 - x3);
        let (pa, pb) = (p[0] - p[1], p[0] - p[2]);
        let xm = Matrix3::from_columns(&[xa, xb, xa.cross(&xb)]);
        let pm = Matrix3::from_columns(&[pa, pb, pa.cross(&pb)]);
        let Some(xi) = xm.try_inverse() else { continue };
        // The nearest rotation (SVD), exact up to rounding when the depths are exact.
        let svd = (pm * xi).svd(true, true);
        let (Some(u), Some(vt)) = (svd.u, svd.v_t) else { continue };
        let mut d = Matrix3::identity();
        d[(2, 2)] = (u * vt).determinant().signum();
        let r = Rotation3::from_matrix_unchecked(u * d * vt);
        let t = p[0] - r * x1;
        let q = UnitQuaternion::new_normalize(*UnitQuaternion::from_rotation_matrix(&r).quaternion());
        let pose = Isometry3::from_parts(Translation3::from(t), q);
        let dup = poses.iter().any(|q| {
            (q.translation.vector - pose.translation.vector).norm() < 1e-9 * (1.0 + t.norm())
                && q.rotation.angle_to(&pose.rotation) < 1e-9
        });
        if !dup && t.iter().all(|v| v.is_finite()) {
            poses.push(pose);
        }
    }
    poses
}

/// A few Gauss-Newton steps on the three distance equations.
fn refine_depths(mut l: Vector3<f64>, b: [f64; 3], d: [f64; 3]) -> Vector3<f64> {
    let [b12, b13, b23] = b;
    for _ in 0..5 {
        let f = Vector3::new(
            l.x * l.x + l.y * l.y - 2.0 * b12 * l.x * l.y - d[0],
            l.x * l.x + l.z * l.z - 2.0 * b13 * l.x * l.z - d[1],
            l.y * l.y + l.z * l.z - 2.0 * b23 * l.y * l.z - d[2],
        );
        if f.norm() < 1e-15 * (d[0] + d[1] + d[2]) {
            break;
        }
        let j = Matrix3::new(
            2.0 * (l.x - b12 * l.y),
            2.0 * (l.y - b12 * l.x),
            0.0,
            2.0 * (l.x - b13 * l.z),
            0.0,
            2.0 * (l.z - b13 * l.x),
            0.0,
            2.0 * (l.y - b23 * l.z),
            2.0 * (l.z - b23 * l.y),
        );
        let Some(step) = j.lu().solve(&f) else { break };
        let next = l - step;
        if !next.iter().all(|v| v.is_finite()) {
            break;
        }
        l = next;
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::SplitMix64;

    #[test]
    fn recovers_random_poses_among_its_solutions() {
        let mut rng = SplitMix64::new(11);
        let mut found = 0;
        let trials = 2000;
        for _ in 0..trials {
            let truth = Isometry3::from_parts(
                Translation3::new(rng.uniform() - 0.5, rng.uniform() - 0.5, rng.uniform() - 0.5),
                UnitQuaternion::from_euler_angles(rng.uniform() - 0.5, rng.uniform() - 0.5, 2.0 * rng.uniform() - 1.0),
            );
            let inv = truth.inverse();
            let mut world = [Point3::origin(); 3];
            let mut bearings = [Vector3::zeros(); 3];
            for k in 0..3 {
                let pc = Point3::new(2.0 * rng.uniform() - 1.0, 2.0 * rng.uniform() - 1.0, 1.0 + 4.0 * rng.uniform());
                world[k] = inv * pc;
                bearings[k] = pc.coords * (0.5 + rng.uniform());
            }
            let sols = p3p(&world, &bearings);
            assert!(sols.len() <= 4);
            if sols.iter().any(|s| {
                (s.translation.vector - truth.translation.vector).norm() < 1e-6
                    && s.rotation.angle_to(&truth.rotation) < 1e-6
            }) {
                found += 1;
            }
            // Every solution maps the points onto the bearings.
            for s in &sols {
                for k in 0..3 {
                    let pc = s * world[k];
                    assert!(pc.coords.normalize().dot(&bearings[k].normalize()) > 1.0 - 1e-6);
                }
            }
        }
        // Near-degenerate random draws may lose precision; nearly all must be exact.
        assert!(found as f64 >= 0.995 * f64::from(trials), "{found}/{trials}");
    }

    #[test]
    fn degenerate_triples_give_nothing_and_no_panic() {
        let b = [Vector3::new(0.0, 0.0, 1.0), Vector3::new(0.1, 0.0, 1.0), Vector3::new(0.0, 0.1, 1.0)];
        let same = [Point3::new(1.0, 2.0, 3.0); 3];
        assert!(p3p(&same, &b).is_empty());
        let w = [Point3::new(0.0, 0.0, 1.0), Point3::new(1.0, 0.0, 1.0), Point3::new(0.0, 1.0, 1.0)];
        assert!(p3p(&w, &[Vector3::zeros(); 3]).is_empty());
        let nan = [Point3::new(f64::NAN, 0.0, 1.0), Point3::new(1.0, 0.0, 1.0), Point3::new(0.0, 1.0, 1.0)];
        assert!(p3p(&nan, &b).is_empty());
    }
}
