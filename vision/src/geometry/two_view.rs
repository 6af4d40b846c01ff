//! Monocular initialisation from two views, as ORB-SLAM2's `Initializer` does it (Mur-Artal et
//! al., "ORB-SLAM: a Versatile and Accurate Monocular SLAM System", T-RO 2015, section IV):
//! a homography and a fundamental matrix are fitted to the same matches, the homography is
//! chosen when `R_H = S_H / (S_H + S_F) > 0.40` (a plane, or too little parallax for F), and
//! the chosen model is decomposed into its motion hypotheses (four from the essential matrix,
//! eight from the homography by Faugeras and Lustman's method). Each hypothesis triangulates
//! the inliers; a point counts when it lies in front of both cameras (unless its rays are
//! parallel) and reprojects within `4 sigma^2` in both; the initialisation is accepted only
//! when one hypothesis explains at least 90 % of the inliers and at least 50 points, clearly
//! beats the others, and sees the scene under at least one degree of parallax. Otherwise it
//! is refused with the reason ([`InitFailure`]): never a pose from an ambiguous pair.
//!
//! Deviation: the models come from this crate's RANSAC (7-point F with local optimisation,
//! 4-point homography by PROSAC with uniform quality) instead of ORB-SLAM2's 200 shared
//! 8-point sets; the scores and the choice are ORB-SLAM2's.

use nalgebra::{Isometry3, Matrix3, Matrix4, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::model_selection::{CHI2_1DOF, CHI2_2DOF, HOMOGRAPHY_RATIO, fundamental_score, homography_score};
use super::{Mat3, RansacConfig, SplitMix64, epipolar_distance, fit_fundamental, fit_homography_prosac, transfer};
use crate::camera::Pinhole;

/// ORB-SLAM2's initialisation settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwoViewConfig {
    /// Image noise, pixels (ORB-SLAM2: 1.0).
    pub sigma: f64,
    /// Least parallax of the scene, degrees (ORB-SLAM2: 1.0).
    pub min_parallax_deg: f64,
    /// Least triangulated points (ORB-SLAM2: 50).
    pub min_triangulated: usize,
    /// RANSAC samples at most, per model (ORB-SLAM2: 200).
    pub max_iterations: usize,
}

impl Default for TwoViewConfig {
    fn default() -> Self {
        Self { sigma: 1.0, min_parallax_deg: 1.0, min_triangulated: 50, max_iterations: 200 }
    }
}

/// Which model the pair was reconstructed from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TwoViewModel {
    /// A homography (a planar scene or a rotation).
    Homography,
    /// A fundamental matrix.
    Fundamental,
}

/// A successful initialisation.
#[derive(Clone, Debug, PartialEq)]
pub struct TwoViewInit {
    /// `cam2_from_cam1`, translation of unit length (the scale is unknown).
    pub cam2_from_cam1: Isometry3<f64>,
    /// Per match: its point in the first camera's frame, if triangulated with parallax.
    pub points: Vec<Option<Point3<f64>>>,
    /// The model it came from.
    pub model: TwoViewModel,
    /// `R_H`, the homography's share of the two scores (ORB-SLAM2's model selection).
    pub ratio: f64,
    /// The scene's parallax, degrees (the 50th largest of the points', as ORB-SLAM2).
    pub parallax_deg: f64,
}

/// Why two views do not initialise.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InitFailure {
    /// Too few matches to try.
    #[error("{matches} matches; initialisation needs at least {needed}")]
    TooFewMatches {
        /// Matches given.
        matches: usize,
        /// Matches needed.
        needed: usize,
    },
    /// Neither model could be fitted.
    #[error("neither a homography nor a fundamental matrix fits the matches")]
    NoModel,
    /// The best hypothesis triangulates too few points.
    #[error(
        "the best motion hypothesis ({model:?}) triangulates {good} of {inliers} inliers ({needed} needed): not enough parallax or too many outliers"
    )]
    TooFewPoints {
        /// The model chosen.
        model: TwoViewModel,
        /// Points triangulated in front of both cameras with parallax.
        good: usize,
        /// The model's inliers.
        inliers: usize,
        /// Points needed.
        needed: usize,
    },
    /// Several hypotheses explain the matches about as well.
    #[error("{model:?}: {similar} motion hypotheses explain the matches about as well: ambiguous")]
    Ambiguous {
        /// The model chosen.
        model: TwoViewModel,
        /// Hypotheses about as good as the best.
        similar: usize,
    },
    /// Too little parallax.
    #[error("parallax {parallax_deg:.2} deg is below {min_deg} deg (the camera barely translated)")]
    LowParallax {
        /// The scene's parallax, degrees.
        parallax_deg: f64,
        /// The least accepted, degrees.
        min_deg: f64,
    },
}

fn k_matrix(cam: &Pinhole) -> Mat3 {
    Matrix3::new(cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0)
}

/// Linear (DLT) triangulation of one match from two `cam_from_world` poses; the point in
/// the world frame, `None` when degenerate.
pub fn triangulate(
    cam: &Pinhole,
    cam1_from_world: &Isometry3<f64>,
    cam2_from_world: &Isometry3<f64>,
    uv1: [f64; 2],
    uv2: [f64; 2],
) -> Option<Point3<f64>> {
    let k = k_matrix(cam);
    let row = |pose: &Isometry3<f64>| k * pose.to_matrix().fixed_view::<3, 4>(0, 0);
    let (p1, p2) = (row(cam1_from_world), row(cam2_from_world));
    let mut a = Matrix4::zeros();
    for (r, (p, uv)) in [(&p1, uv1), (&p2, uv2)].into_iter().enumerate() {
        a.set_row(2 * r, &(uv[0] * p.row(2) - p.row(0)));
        a.set_row(2 * r + 1, &(uv[1] * p.row(2) - p.row(1)));
    }
    let svd = a.svd(false, true);
    let vt = svd.v_t?;
    let (i, _) = svd.singular_values.argmin();
    let x = vt.row(i);
    if x[3].abs() < 1e-12 {
        return None;
    }
    let p = Point3::new(x[0] / x[3], x[1] / x[3], x[2] / x[3]);
    p.coords.iter().all(|v| v.is_finite()).then_some(p)
}

fn isometry(r: &Mat3, t: &Vector3<f64>) -> Option<Isometry3<f64>> {
    let rot = Rotation3::from_matrix_eps(r, 1e-9, 100, Rotation3::identity());
    if (rot.matrix() - r).abs().max() > 1e-6 {
        return None;
    }
    Some(Isometry3::from_parts(Translation3::from(*t), UnitQuaternion::from_rotation_matrix(&rot)))
}

/// The four `(R, t)` of an essential matrix (`t` of unit length).
pub fn decompose_essential(e: &Mat3) -> Vec<Isometry3<f64>> {
    let svd = e.svd(true, true);
    let (Some(mut u), Some(mut vt)) = (svd.u, svd.v_t) else { return Vec::new() };
    // Order the singular values descending: the null direction is the last column.
    let (i, _) = svd.singular_values.argmin();
    if i != 2 {
        u.swap_columns(i, 2);
        vt.swap_rows(i, 2);
    }
    let t = u.column(2).normalize();
    let w = Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let fix = |r: Mat3| if r.determinant() < 0.0 { -r } else { r };
    let (r1, r2) = (fix(u * w * vt), fix(u * w.transpose() * vt));
    [(r1, t), (r1, -t), (r2, t), (r2, -t)].iter().filter_map(|(r, t)| isometry(r, t)).collect()
}

/// The eight motion hypotheses `(R, t)` of a homography between calibrated views (Faugeras
/// and Lustman 1988), `t` of unit length; empty when two singular values coincide (no
/// unique decomposition).
pub fn decompose_homography(h: &Mat3, cam: &Pinhole) -> Vec<Isometry3<f64>> {
    let k = k_matrix(cam);
    let Some(kinv) = k.try_inverse() else { return Vec::new() };
    let a = kinv * h * k;
    let svd = a.svd(true, true);
    let (Some(u0), Some(vt0)) = (svd.u, svd.v_t) else { return Vec::new() };
    // Sort descending.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&x, &y| svd.singular_values[y].total_cmp(&svd.singular_values[x]));
    let (mut u, mut vt) = (Mat3::zeros(), Mat3::zeros());
    for (j, &o) in order.iter().enumerate() {
        u.set_column(j, &u0.column(o));
        vt.set_row(j, &vt0.row(o));
    }
    let d: Vec<f64> = order.iter().map(|&o| svd.singular_values[o]).collect();
    let (d1, d2, d3) = (d[0], d[1], d[2]);
    if d2 <= 0.0 || d1 / d2 < 1.00001 || d2 / d3.max(f64::MIN_POSITIVE) < 1.00001 {
        return Vec::new();
    }
    let s = u.determinant() * vt.determinant();
    let (a1, a3) =
        (((d1 * d1 - d2 * d2) / (d1 * d1 - d3 * d3)).sqrt(), ((d2 * d2 - d3 * d3) / (d1 * d1 - d3 * d3)).sqrt());
    let x1 = [a1, a1, -a1, -a1];
    let x3 = [a3, -a3, a3, -a3];
    let root = ((d1 * d1 - d2 * d2) * (d2 * d2 - d3 * d3)).sqrt();
    let mut out = Vec::with_capacity(8);
    // d' = d2.
    let st = root / ((d1 + d3) * d2);
    let ct = (d2 * d2 + d1 * d3) / ((d1 + d3) * d2);
    for (i, sgn) in [1.0, -1.0, -1.0, 1.0].iter().enumerate() {
        let sth = sgn * st;
        let rp = Matrix3::new(ct, 0.0, -sth, 0.0, 1.0, 0.0, sth, 0.0, ct);
        let r = s * u * rp * vt;
        let t = u * Vector3::new(x1[i], 0.0, -x3[i]) * (d1 - d3);
        if let Some(p) = isometry(&r, &t.normalize()) {
            out.push(p);
        }
    }
    // d' = -d2.
    let sp = root / ((d1 - d3) * d2);
    let cp = (d1 * d3 - d2 * d2) / ((d1 - d3) * d2);
    for (i, sgn) in [1.0, -1.0, -1.0, 1.0].iter().enumerate() {
        let sph = sgn * sp;
        let rp = Matrix3::new(cp, 0.0, sph, 0.0, -1.0, 0.0, sph, 0.0, -cp);
        let r = s * u * rp * vt;
        let t = u * Vector3::new(x1[i], 0.0, x3[i]) * (d1 + d3);
        if let Some(p) = isometry(&r, &t.normalize()) {
            out.push(p);
        }
    }
    out
}

/// A hypothesis checked: good points, parallax (degrees), the points, the motion.
type Checked = (usize, f64, Vec<Option<Point3<f64>>>, Isometry3<f64>);

/// ORB-SLAM2's `CheckRT`: triangulate the inliers under one hypothesis; `(good, parallax in
/// degrees, points)`.
fn check_motion(
    cam: &Pinhole,
    cam2_from_cam1: &Isometry3<f64>,
    p1: &[[f64; 2]],
    p2: &[[f64; 2]],
    inliers: &[bool],
    th2: f64,
) -> (usize, f64, Vec<Option<Point3<f64>>>) {
    let id = Isometry3::identity();
    let o2 = cam2_from_cam1.inverse().translation.vector;
    let mut points = vec![None; p1.len()];
    let mut cos_parallax = Vec::new();
    for i in (0..p1.len()).filter(|&i| inliers[i]) {
        let Some(x) = triangulate(cam, &id, cam2_from_cam1, p1[i], p2[i]) else { continue };
        let (n1, n2) = (x.coords, x.coords - o2);
        let cos = n1.dot(&n2) / (n1.norm() * n2.norm());
        let x2 = cam2_from_cam1 * x;
        if (x.z <= 0.0 || x2.z <= 0.0) && cos < 0.99998 {
            continue;
        }
        let err = |pc: &Point3<f64>, uv: [f64; 2]| {
            cam.project(pc).map_or(f64::INFINITY, |q| (q[0] - uv[0]).powi(2) + (q[1] - uv[1]).powi(2))
        };
        if err(&x, p1[i]) > th2 || err(&x2, p2[i]) > th2 {
            continue;
        }
        cos_parallax.push(cos);
        if cos < 0.99998 {
            points[i] = Some(x);
        }
    }
    let good = cos_parallax.len();
    if good == 0 {
        return (0, 0.0, points);
    }
    cos_parallax.sort_by(f64::total_cmp);
    let c = cos_parallax[50.min(good - 1)];
    (good, c.clamp(-1.0, 1.0).acos().to_degrees(), points)
}

/// Initialise from matched pixels `p1[i] <-> p2[i]` of two views of camera `cam`.
pub fn initialise(
    p1: &[[f64; 2]],
    p2: &[[f64; 2]],
    cam: &Pinhole,
    config: &TwoViewConfig,
    rng: &mut SplitMix64,
) -> Result<TwoViewInit, InitFailure> {
    let needed = config.min_triangulated.max(8);
    if p1.len() < needed || p2.len() != p1.len() {
        return Err(InitFailure::TooFewMatches { matches: p1.len().min(p2.len()), needed });
    }
    let s2 = config.sigma * config.sigma;
    let rc = RansacConfig {
        threshold: (CHI2_1DOF * s2).sqrt(),
        confidence: 0.99,
        max_iterations: config.max_iterations,
        local_optimisation: true,
    };
    let f = fit_fundamental(p1, p2, &rc, rng).map(|f| f.f);
    let quality = vec![1.0; p1.len()];
    let rh = RansacConfig { threshold: (CHI2_2DOF * s2).sqrt(), local_optimisation: false, ..rc };
    let h = fit_homography_prosac(p1, p2, &quality, &rh, rng).map(|h| h.h);
    let (sh, sf) = (
        h.as_ref().map_or(0.0, |h| homography_score(h, p1, p2)),
        f.as_ref().map_or(0.0, |f| fundamental_score(f, p1, p2)),
    );
    if sh + sf <= 0.0 {
        return Err(InitFailure::NoModel);
    }
    let ratio = sh / (sh + sf);
    let th2 = 4.0 * s2;
    let (model, hypotheses, inliers) = match (ratio > HOMOGRAPHY_RATIO, h, f) {
        (true, Some(h), _) | (false, Some(h), None) => {
            let hinv = h.try_inverse().unwrap_or_else(Mat3::zeros);
            let e2 = |m: &Mat3, a: [f64; 2], b: [f64; 2]| {
                let q = transfer(m, a);
                (q[0] - b[0]).powi(2) + (q[1] - b[1]).powi(2)
            };
            let inl: Vec<bool> = p1
                .iter()
                .zip(p2)
                .map(|(a, b)| e2(&h, *a, *b) <= CHI2_2DOF * s2 && e2(&hinv, *b, *a) <= CHI2_2DOF * s2)
                .collect();
            (TwoViewModel::Homography, decompose_homography(&h, cam), inl)
        }
        (_, _, Some(f)) => {
            let ft = f.transpose();
            let inl: Vec<bool> = p1
                .iter()
                .zip(p2)
                .map(|(a, b)| {
                    epipolar_distance(&f, *a, *b).powi(2) <= CHI2_1DOF * s2
                        && epipolar_distance(&ft, *b, *a).powi(2) <= CHI2_1DOF * s2
                })
                .collect();
            let k = k_matrix(cam);
            (TwoViewModel::Fundamental, decompose_essential(&(k.transpose() * f * k)), inl)
        }
        _ => return Err(InitFailure::NoModel),
    };
    if model == TwoViewModel::Homography && hypotheses.is_empty() {
        // Coinciding singular values: H = K R K^-1, a rotation about the centre, no parallax.
        return Err(InitFailure::LowParallax { parallax_deg: 0.0, min_deg: config.min_parallax_deg });
    }
    let n = inliers.iter().filter(|&&b| b).count();
    let mut checked: Vec<Checked> = hypotheses
        .iter()
        .map(|m| {
            let (g, par, pts) = check_motion(cam, m, p1, p2, &inliers, th2);
            (g, par, pts, *m)
        })
        .collect();
    let Some(best_i) = (0..checked.len()).max_by_key(|&i| (checked[i].0, std::cmp::Reverse(i))) else {
        return Err(InitFailure::NoModel);
    };
    let best = checked[best_i].0;
    let min_good = ((0.9 * n as f64).ceil() as usize).max(config.min_triangulated);
    if best < min_good {
        return Err(InitFailure::TooFewPoints { model, good: best, inliers: n, needed: min_good });
    }
    // ORB-SLAM2: for F no other hypothesis above 0.7 of the best; for H the second below 0.75.
    let share = if model == TwoViewModel::Fundamental { 0.7 } else { 0.75 };
    let similar = checked.iter().filter(|c| c.0 as f64 > share * best as f64).count();
    if similar > 1 {
        return Err(InitFailure::Ambiguous { model, similar });
    }
    let (_, parallax_deg, points, motion) = checked.swap_remove(best_i);
    if parallax_deg < config.min_parallax_deg {
        return Err(InitFailure::LowParallax { parallax_deg, min_deg: config.min_parallax_deg });
    }
    Ok(TwoViewInit { cam2_from_cam1: motion, points, model, ratio, parallax_deg })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Pinhole {
        Pinhole { fx: 500.0, fy: 500.0, cx: 320.0, cy: 240.0 }
    }

    /// Points seen from the origin and from `cam2_from_cam1`; `plane`: all on z = 4.
    fn scene(motion: &Isometry3<f64>, plane: bool, n: usize, seed: u64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let mut rng = SplitMix64::new(seed);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        while a.len() < n {
            let z = if plane { 4.0 } else { 2.0 + 4.0 * rng.uniform() };
            let x = Point3::new((rng.uniform() - 0.5) * z, (rng.uniform() - 0.5) * 0.75 * z, z);
            let (Some(u1), Some(u2)) = (cam().project(&x), cam().project(&(motion * x))) else { continue };
            if u2[0] < 0.0 || u2[0] > 640.0 || u2[1] < 0.0 || u2[1] > 480.0 {
                continue;
            }
            a.push(u1);
            b.push(u2);
        }
        (a, b)
    }

    fn motion(t: [f64; 3], axis: [f64; 3]) -> Isometry3<f64> {
        Isometry3::new(Vector3::from(t), Vector3::from(axis))
    }

    fn assert_recovers(truth: &Isometry3<f64>, got: &TwoViewInit) {
        let dr = (truth.rotation.inverse() * got.cam2_from_cam1.rotation).angle().to_degrees();
        let dt = truth.translation.vector.normalize().dot(&got.cam2_from_cam1.translation.vector).acos().to_degrees();
        assert!(dr < 0.1 && dt < 1.0, "rotation off by {dr:.3} deg, translation direction by {dt:.3} deg");
    }

    #[test]
    fn a_general_scene_initialises_from_the_fundamental_matrix() {
        let truth = motion([0.3, 0.05, 0.1], [0.01, -0.05, 0.02]);
        let (a, b) = scene(&truth, false, 300, 1);
        let init = initialise(&a, &b, &cam(), &TwoViewConfig::default(), &mut SplitMix64::new(3)).unwrap();
        assert_eq!(init.model, TwoViewModel::Fundamental, "R_H {}", init.ratio);
        assert_recovers(&truth, &init);
        // The triangulated points are the scene up to the unit-baseline scale.
        let scale = truth.translation.vector.norm();
        let tri = init.points.iter().flatten().count();
        assert!(tri >= 270, "{tri} of 300 triangulated");
        for (p, uv) in init.points.iter().zip(&a) {
            if let Some(p) = p {
                let q = cam().project(&Point3::from(p.coords * scale)).unwrap();
                assert!((q[0] - uv[0]).abs() < 1e-6 && (q[1] - uv[1]).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn a_plane_initialises_from_the_homography() {
        let truth = motion([0.4, -0.1, 0.05], [0.02, 0.04, -0.01]);
        let (a, b) = scene(&truth, true, 300, 2);
        let init = initialise(&a, &b, &cam(), &TwoViewConfig::default(), &mut SplitMix64::new(4)).unwrap();
        assert_eq!(init.model, TwoViewModel::Homography, "R_H {}", init.ratio);
        assert_recovers(&truth, &init);
    }

    #[test]
    fn a_rotation_without_translation_is_refused() {
        let truth = motion([0.0, 0.0, 0.0], [0.02, 0.08, 0.0]);
        let (a, b) = scene(&truth, false, 300, 5);
        let e = initialise(&a, &b, &cam(), &TwoViewConfig::default(), &mut SplitMix64::new(6)).unwrap_err();
        assert!(matches!(e, InitFailure::LowParallax { .. }), "{e}");
        // Too few matches: said so.
        let e = initialise(&a[..20], &b[..20], &cam(), &TwoViewConfig::default(), &mut SplitMix64::new(6)).unwrap_err();
        assert_eq!(e, InitFailure::TooFewMatches { matches: 20, needed: 50 });
    }
}
