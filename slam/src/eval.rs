//! Trajectory evaluation as the TUM benchmark tools and evo compute it: timestamp
//! association (evo's nearest-stamp matching), Umeyama alignment (SE(3) or Sim(3)), the
//! absolute trajectory error (ATE) and the relative pose error (RPE). The numbers match
//! `evo_ape` / `evo_rpe` with the same settings (`tests/eval.rs` checks it to 1e-6).

use nalgebra::{Isometry3, Matrix3, UnitQuaternion, Vector3};

/// A pose at a time: `world_from_cam`, TUM's `T_world_camera`.
pub type Stamped = (f64, Isometry3<f64>);

/// How the estimate is aligned to the ground truth before the ATE.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Align {
    /// As estimated.
    None,
    /// Rotation and translation (evo `-a`).
    Se3,
    /// Rotation, translation and scale (evo `-as`), for monocular estimates.
    Sim3,
}

/// Error statistics, as evo prints them.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Stats {
    /// Root mean square.
    pub rmse: f64,
    /// Mean.
    pub mean: f64,
    /// Median (mean of the two middle values for an even count).
    pub median: f64,
    /// Population standard deviation.
    pub std: f64,
    /// Smallest.
    pub min: f64,
    /// Largest.
    pub max: f64,
    /// Sum of squares.
    pub sse: f64,
    /// Number of values.
    pub count: usize,
}

impl Stats {
    /// Statistics of `v` (all zero when empty).
    pub fn of(v: &[f64]) -> Self {
        if v.is_empty() {
            return Self::default();
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let sse = v.iter().map(|x| x * x).sum::<f64>();
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let median = if s.len() % 2 == 1 { s[s.len() / 2] } else { (s[s.len() / 2 - 1] + s[s.len() / 2]) / 2.0 };
        Self {
            rmse: (sse / n).sqrt(),
            mean,
            median,
            std: (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt(),
            min: s[0],
            max: s[s.len() - 1],
            sse,
            count: v.len(),
        }
    }
}

/// Why two trajectories cannot be compared.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum EvalError {
    /// No timestamps matched within the tolerance.
    #[error("no timestamps of the estimate match the ground truth within {max_diff} s")]
    NoMatches {
        /// The tolerance.
        max_diff: f64,
    },
    /// Too few matched poses for the requested alignment.
    #[error("{matched} matched poses are too few to align ({needed} needed)")]
    TooFew {
        /// Poses matched.
        matched: usize,
        /// Poses needed.
        needed: usize,
    },
    /// The estimate's matched positions do not spread, so no Sim(3) scale fits them (evo:
    /// "degenerate covariance rank").
    #[error(
        "the estimate does not move: its {matched} matched positions lie within {spread:.1e} m of one point, so no Sim(3) scale can be fitted to them; evaluate it with `--align se3` or `--align none`"
    )]
    Motionless {
        /// Poses matched.
        matched: usize,
        /// Largest distance of a matched position from their mean, metres.
        spread: f64,
    },
}

/// Everything `dynaflow eval` reports.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Evaluation {
    /// Poses associated.
    pub matched: usize,
    /// Poses of the ground truth and the estimate.
    pub poses: [usize; 2],
    /// Alignment used.
    pub align: Align,
    /// Scale applied to the estimate (1 unless Sim(3)).
    pub scale: f64,
    /// ATE: distance between ground-truth and aligned estimated positions, metres.
    pub ate: Stats,
    /// RPE translation over `rpe_delta` frames, metres.
    pub rpe_translation: Stats,
    /// RPE rotation over `rpe_delta` frames, degrees.
    pub rpe_rotation_deg: Stats,
    /// RPE step in frames (0 when the step is a distance).
    pub rpe_delta: usize,
    /// RPE step in metres, when it is a distance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rpe_delta_m: Option<f64>,
    /// Per associated pose: ground-truth stamp, ground-truth position, aligned estimated
    /// position, ATE (for plots; not serialised).
    #[serde(skip)]
    pub series: Vec<(f64, Vector3<f64>, Vector3<f64>, f64)>,
}

/// evo's association (`sync.associate_trajectories`, nearest time): every pose of the shorter
/// trajectory takes the nearest stamp of the longer one within `max_diff` (ties: the earlier
/// stamp), indices returned as (first, second).
pub fn associate(first: &[f64], second: &[f64], max_diff: f64) -> (Vec<usize>, Vec<usize>) {
    let second_longer = second.len() > first.len();
    let (short, long) = if second_longer { (first, second) } else { (second, first) };
    let sorted = long.windows(2).all(|w| w[1] >= w[0]);
    let (mut is, mut il) = (Vec::new(), Vec::new());
    for (i, &s) in short.iter().enumerate() {
        let best = if sorted {
            let (Some(&lo), Some(&hi)) = (long.first(), long.last()) else { break };
            if s < lo - max_diff || s > hi + max_diff {
                continue;
            }
            // Insertion point after equal stamps (numpy's searchsorted, side="right").
            let mut j = long.partition_point(|&x| x <= s);
            if j >= long.len() {
                j = long.len() - 1;
            }
            let diff_ub = long[j] - s;
            let diff_lb = if j > 0 { s - long[j - 1] } else { f64::INFINITY };
            if diff_ub <= max_diff && diff_ub < diff_lb {
                Some(j)
            } else if diff_lb <= max_diff && diff_lb <= diff_ub {
                Some(j - 1)
            } else {
                None
            }
        } else {
            long.iter()
                .enumerate()
                .map(|(j, &x)| (j, (x - s).abs()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .filter(|(_, d)| *d <= max_diff)
                .map(|(j, _)| j)
        };
        if let Some(j) = best {
            is.push(i);
            il.push(j);
        }
    }
    if second_longer { (is, il) } else { (il, is) }
}

/// Umeyama's least-squares similarity taking `x` onto `y`: `y ~ c R x + t`.
pub fn umeyama(x: &[Vector3<f64>], y: &[Vector3<f64>], with_scale: bool) -> Option<(Matrix3<f64>, Vector3<f64>, f64)> {
    let n = x.len();
    if n == 0 || y.len() != n {
        return None;
    }
    let nf = n as f64;
    let mx = x.iter().sum::<Vector3<f64>>() / nf;
    let my = y.iter().sum::<Vector3<f64>>() / nf;
    let sigma_x = x.iter().map(|p| (p - mx).norm_squared()).sum::<f64>() / nf;
    let mut cov = Matrix3::zeros();
    for (p, q) in x.iter().zip(y) {
        cov += (q - my) * (p - mx).transpose();
    }
    cov /= nf;
    let svd = cov.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut s = Matrix3::identity();
    if u.determinant() * v_t.determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let r = u * s * v_t;
    let c = if with_scale {
        if sigma_x <= 0.0 {
            return None;
        }
        (Matrix3::from_diagonal(&svd.singular_values) * s).trace() / sigma_x
    } else {
        1.0
    };
    let t = my - c * (r * mx);
    Some((r, t, c))
}

fn rotation_angle_deg(r: &Matrix3<f64>) -> f64 {
    // Bounded iterations: nalgebra's `from_matrix` loops until convergence, forever on NaN.
    UnitQuaternion::from_matrix_eps(r, f64::EPSILON, 100, UnitQuaternion::identity()).angle().to_degrees()
}

/// The RPE step: a number of frames, or a travelled distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RpeDelta {
    /// Consecutive pairs `n` frames apart (evo `--delta n --delta_unit f`).
    Frames(usize),
    /// Consecutive pairs at least this many metres apart along the aligned estimate's path
    /// (evo `--delta d --delta_unit m`, its default consecutive-pairs mode).
    Meters(f64),
}

/// Evaluate `est` against `gt`, RPE over `rpe_delta` frames.
pub fn evaluate(
    gt: &[Stamped],
    est: &[Stamped],
    max_diff: f64,
    align: Align,
    rpe_delta: usize,
) -> Result<Evaluation, EvalError> {
    evaluate_with(gt, est, max_diff, align, RpeDelta::Frames(rpe_delta))
}

/// Evaluate `est` against `gt` with any RPE step.
pub fn evaluate_with(
    gt: &[Stamped],
    est: &[Stamped],
    max_diff: f64,
    align: Align,
    rpe: RpeDelta,
) -> Result<Evaluation, EvalError> {
    let gt_t: Vec<f64> = gt.iter().map(|p| p.0).collect();
    let est_t: Vec<f64> = est.iter().map(|p| p.0).collect();
    let (ig, ie) = associate(&gt_t, &est_t, max_diff);
    if ig.is_empty() {
        return Err(EvalError::NoMatches { max_diff });
    }
    let g: Vec<Isometry3<f64>> = ig.iter().map(|&i| gt[i].1).collect();
    let e: Vec<Isometry3<f64>> = ie.iter().map(|&i| est[i].1).collect();
    let gp: Vec<Vector3<f64>> = g.iter().map(|p| p.translation.vector).collect();
    let ep: Vec<Vector3<f64>> = e.iter().map(|p| p.translation.vector).collect();
    let (r, t, c) = match align {
        Align::None => (Matrix3::identity(), Vector3::zeros(), 1.0),
        Align::Se3 | Align::Sim3 => {
            let needed = 3;
            if ig.len() < needed {
                return Err(EvalError::TooFew { matched: ig.len(), needed });
            }
            let mean = ep.iter().sum::<Vector3<f64>>() / ep.len() as f64;
            let spread = ep.iter().map(|p| (p - mean).norm()).fold(0.0, f64::max);
            // A scale needs motion: spread at rounding level of the positions is none.
            let motionless = spread <= 1e-9 * mean.norm().max(1.0);
            if align == Align::Sim3 && motionless {
                return Err(EvalError::Motionless { matched: ig.len(), spread });
            }
            umeyama(&ep, &gp, align == Align::Sim3).ok_or(EvalError::Motionless { matched: ig.len(), spread })?
        }
    };
    // The aligned estimate: positions c R p + t, orientations R q (evo's `align`).
    let aligned: Vec<(Matrix3<f64>, Vector3<f64>)> = e
        .iter()
        .map(|p| (r * p.rotation.to_rotation_matrix().into_inner(), c * (r * p.translation.vector) + t))
        .collect();
    let ate: Vec<f64> = aligned.iter().zip(&gp).map(|((_, p), q)| (p - q).norm()).collect();
    // RPE over consecutive pairs `delta` apart (evo's default, not all pairs).
    let (delta, ids): (usize, Vec<usize>) = match rpe {
        RpeDelta::Frames(d) => (d.max(1), (0..g.len()).step_by(d.max(1)).collect()),
        RpeDelta::Meters(m) => {
            // evo's `filter_pairs_by_path`: the first pose, then each pose where the path
            // travelled since the last chosen one reaches `m`.
            let mut ids = vec![0];
            let mut path = 0.0;
            for i in 1..aligned.len() {
                path += (aligned[i].1 - aligned[i - 1].1).norm();
                if path >= m {
                    ids.push(i);
                    path = 0.0;
                }
            }
            (0, ids)
        }
    };
    let (mut rt, mut rr) = (Vec::new(), Vec::new());
    for w in ids.windows(2) {
        let (i, j) = (w[0], w[1]);
        let q_i = (g[i].rotation.to_rotation_matrix().into_inner(), g[i].translation.vector);
        let q_j = (g[j].rotation.to_rotation_matrix().into_inner(), g[j].translation.vector);
        let (p_i, p_j) = (aligned[i], aligned[j]);
        // rel(A, B) = A^-1 B; E = rel(Q_i, Q_j)^-1 rel(P_i, P_j).
        let rel = |a: (Matrix3<f64>, Vector3<f64>), b: (Matrix3<f64>, Vector3<f64>)| {
            (a.0.transpose() * b.0, a.0.transpose() * (b.1 - a.1))
        };
        let (q, p) = (rel(q_i, q_j), rel(p_i, p_j));
        let e_rot = q.0.transpose() * p.0;
        let e_t = q.0.transpose() * (p.1 - q.1);
        rt.push(e_t.norm());
        rr.push(rotation_angle_deg(&e_rot));
    }
    Ok(Evaluation {
        matched: ig.len(),
        poses: [gt.len(), est.len()],
        align,
        scale: c,
        ate: Stats::of(&ate),
        rpe_translation: Stats::of(&rt),
        rpe_rotation_deg: Stats::of(&rr),
        rpe_delta: delta,
        rpe_delta_m: match rpe {
            RpeDelta::Meters(m) => Some(m),
            RpeDelta::Frames(_) => None,
        },
        series: ig
            .iter()
            .zip(&gp)
            .zip(&aligned)
            .zip(&ate)
            .map(|(((&i, g), (_, e)), &d)| (gt[i].0, *g, *e, d))
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_match_numpy_conventions() {
        let s = Stats::of(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(s.median, 2.5);
        assert!((s.std - 1.118_033_988_749_895).abs() < 1e-12);
        assert!((s.rmse - 7.5f64.sqrt()).abs() < 1e-12);
        assert_eq!((s.min, s.max, s.sse), (1.0, 4.0, 30.0));
    }

    #[test]
    fn association_takes_the_nearest_stamp_within_the_tolerance() {
        let a = [0.0, 1.0, 2.0, 3.0];
        let b = [0.004, 0.996, 2.02, 2.999, 3.5];
        let (ia, ib) = associate(&a, &b, 0.01);
        assert_eq!((ia, ib), (vec![0, 1, 3], vec![0, 1, 3]));
    }

    #[test]
    fn sim3_alignment_recovers_scale_and_pose() {
        let x: Vec<Vector3<f64>> =
            (0..20).map(|i| Vector3::new(f64::from(i).sin(), f64::from(i) * 0.1, f64::from(i).cos())).collect();
        let r = nalgebra::Rotation3::from_euler_angles(0.1, 0.2, 0.3).into_inner();
        let y: Vec<Vector3<f64>> = x.iter().map(|p| 2.5 * (r * p) + Vector3::new(1.0, -2.0, 0.5)).collect();
        let (re, t, c) = umeyama(&x, &y, true).unwrap();
        assert!((c - 2.5).abs() < 1e-9 && (re - r).norm() < 1e-9 && (t - Vector3::new(1.0, -2.0, 0.5)).norm() < 1e-9);
    }
}
