//! ORB-SLAM2's choice between a homography and a fundamental matrix (its monocular
//! initialiser, `Initializer::CheckHomography` / `CheckFundamental` and the ratio in
//! `Initialize`): each model is scored over the correspondences by how far inside a chi-square
//! bound each residual lies, with image noise sigma = 1 px; `R_H = S_H / (S_H + S_F)` above
//! 0.40 means the pair has too little parallax for F (a rotation, a plane, or a short
//! baseline), so a homography explains it.

use super::Mat3;
use super::{epipolar_distance, transfer};

/// ORB-SLAM2's bound for residuals with two degrees of freedom (chi-square, 95 %): the
/// homography's transfer errors, and the score every model's inliers are counted against.
pub const CHI2_2DOF: f64 = 5.991;
/// ORB-SLAM2's bound for residuals with one degree of freedom (a point's distance from its
/// epipolar line), chi-square 95 %.
pub const CHI2_1DOF: f64 = 3.841;
/// ORB-SLAM2's threshold on `R_H`: above it the homography is chosen.
pub const HOMOGRAPHY_RATIO: f64 = 0.40;

/// ORB-SLAM2's homography score `S_H` of `p2 ~ H p1`: over both transfer directions, `5.991 -
/// e^2 / sigma^2` for each squared transfer error within 5.991 (sigma = 1 px). `H` must be
/// invertible; a singular one scores 0.
pub fn homography_score(h: &Mat3, p1: &[[f64; 2]], p2: &[[f64; 2]]) -> f64 {
    let Some(hinv) = h.try_inverse() else { return 0.0 };
    let score = |m: &Mat3, a: [f64; 2], b: [f64; 2]| {
        let q = transfer(m, a);
        let e2 = (q[0] - b[0]).powi(2) + (q[1] - b[1]).powi(2);
        if e2.is_finite() && e2 <= CHI2_2DOF { CHI2_2DOF - e2 } else { 0.0 }
    };
    p1.iter().zip(p2).map(|(a, b)| score(h, *a, *b) + score(&hinv, *b, *a)).sum()
}

/// ORB-SLAM2's fundamental-matrix score `S_F` of `x2^T F x1 = 0`: over both images, `5.991 -
/// d^2 / sigma^2` for each squared epipolar distance within 3.841 (sigma = 1 px; the score is
/// counted against the two-dof bound so that the two models compare).
pub fn fundamental_score(f: &Mat3, p1: &[[f64; 2]], p2: &[[f64; 2]]) -> f64 {
    let score = |d: f64| {
        let d2 = d * d;
        if d2.is_finite() && d2 <= CHI2_1DOF { CHI2_2DOF - d2 } else { 0.0 }
    };
    let ft = f.transpose();
    p1.iter().zip(p2).map(|(a, b)| score(epipolar_distance(f, *a, *b)) + score(epipolar_distance(&ft, *b, *a))).sum()
}

/// `R_H = S_H / (S_H + S_F)` (0 when neither model scores).
pub fn homography_ratio(h: &Mat3, f: &Mat3, p1: &[[f64; 2]], p2: &[[f64; 2]]) -> f64 {
    let (sh, sf) = (homography_score(h, p1, p2), fundamental_score(f, p1, p2));
    if sh + sf > 0.0 { sh / (sh + sf) } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{RansacConfig, SplitMix64, fit_fundamental, fit_homography_prosac};
    use nalgebra::{Matrix3, Rotation3, Vector3};

    /// Random points 2-6 m deep seen before and after a camera motion (fx 500, 640x480).
    fn pair(rotation: Rotation3<f64>, t: Vector3<f64>, seed: u64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let k = Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
        let mut rng = SplitMix64::new(seed);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        while a.len() < 300 {
            let x = Vector3::new(rng.uniform() * 4.0 - 2.0, rng.uniform() * 3.0 - 1.5, 2.0 + 4.0 * rng.uniform());
            let y = rotation * x + t;
            let (pa, pb) = (k * x, k * y);
            let (pa, pb) = ([pa.x / pa.z, pa.y / pa.z], [pb.x / pb.z, pb.y / pb.z]);
            if [pa, pb].iter().all(|p| (0.0..640.0).contains(&p[0]) && (0.0..480.0).contains(&p[1])) {
                a.push(pa);
                b.push(pb);
            }
        }
        (a, b)
    }

    fn ratio(rotation: Rotation3<f64>, t: Vector3<f64>) -> f64 {
        let (a, b) = pair(rotation, t, 3);
        let config = RansacConfig { threshold: CHI2_2DOF.sqrt(), local_optimisation: false, ..RansacConfig::default() };
        let h = fit_homography_prosac(&a, &b, &vec![1.0; a.len()], &config, &mut SplitMix64::new(1)).unwrap().h;
        let f = fit_fundamental(&a, &b, &RansacConfig::default(), &mut SplitMix64::new(2)).unwrap().f;
        homography_ratio(&h, &f, &a, &b)
    }

    #[test]
    fn a_rotation_is_a_homography_and_a_wide_baseline_is_not() {
        let r = Rotation3::from_euler_angles(0.02, -0.03, 0.01);
        // Pure rotation: H is exact, F is ill-posed; both fit, so the ratio is about one half.
        let rotation = ratio(r, Vector3::zeros());
        assert!(rotation > HOMOGRAPHY_RATIO, "{rotation}");
        // 30 cm sideways in a scene 2-6 m deep: tens of pixels of parallax; H fits only the
        // points near one depth, F all.
        let wide = ratio(r, Vector3::new(0.3, 0.0, 0.0));
        assert!(wide < 0.25, "{wide}");
    }
}
