//! ORB-SLAM2's sparse stereo matching on synthetic rectified pairs: depth against
//! the generator's exact disparity, next to OpenCV's StereoSGBM at the same keypoints.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use common::stereo::{Pair, exact_disparity, match_pair, quantile, sgbm, synth_stereo};
use dynaflow_datasets::synth::Motion;

/// The pairs measured: frames of three camera motions of the walking scene, 8 cm baseline
/// (ORB-SLAM2's RGB-D `bf` of 40 at fx 525 is a 7.6 cm virtual baseline; Kinect v1's
/// projector-camera baseline is 7.5 cm).
fn pairs() -> Vec<Pair> {
    [(Motion::Xyz, 10), (Motion::Halfsphere, 100), (Motion::Rpy, 200)]
        .into_iter()
        .map(|(m, k)| synth_stereo(m, 3, k, 0.08))
        .collect()
}

#[test]
fn stereo_matches_recover_the_exact_disparity_and_agree_with_sgbm() {
    let pairs = pairs();
    let dir = common::TempDir::new("stereo");
    let mut ours = Vec::new();
    let (mut keypoints, mut matched) = (0usize, 0usize);
    let mut at_points = Vec::new();
    for pair in &pairs {
        let (f, m) = match_pair(pair);
        keypoints += f.keypoints.len();
        matched += m.matched();
        println!(
            "pair: {} keypoints, {} matched; no candidate {}, no refinement {}, out of range {}, SAD above the median's bound {}",
            f.keypoints.len(),
            m.matched(),
            m.no_candidate,
            m.no_refinement,
            m.out_of_range,
            m.high_cost
        );
        let mut points = Vec::new();
        for (k, s) in f.keypoints.iter().zip(&m.matches) {
            let (Some(s), Some(exact)) = (s, exact_disparity(pair, k.x, k.y)) else { continue };
            ours.push((f64::from(k.x - s.u_right), f64::from(exact)));
            points.push([k.x, k.y]);
        }
        at_points.push(points);
    }
    let fraction = matched as f64 / keypoints as f64;
    let mut err: Vec<f64> = ours.iter().map(|(d, e)| (d - e).abs()).collect();
    let (median, p90) = (quantile(&mut err.clone(), 0.5), quantile(&mut err, 0.9));
    println!(
        "ours: {matched} of {keypoints} keypoints matched ({:.0} %), disparity error at {} with exact disparity: median {median:.3} px, p90 {p90:.3} px",
        100.0 * fraction,
        ours.len()
    );
    // A third of the keypoints (ORB's quadtree keeps the strongest corner of each cell, which
    // the other view often does not keep: most misses are keypoints with no counterpart on
    // their row band), with sub-pixel disparity (the parabola step) at most of them. Bounds
    // from this test's own measurement (36 %, 0.26 / 0.79 px) with a margin.
    assert!(fraction > 0.3, "matched {fraction}");
    assert!(median < 0.35 && p90 < 1.0, "median {median}, p90 {p90}");

    let Some(python) = common::frontend::cv2_python("stereo matching against StereoSGBM") else { return };
    let jobs: Vec<(&Pair, Vec<[f32; 2]>)> = pairs.iter().zip(at_points).collect();
    let theirs = sgbm(&python, dir.path(), &jobs, 1);
    let exact: Vec<f64> = ours.iter().map(|(_, e)| *e).collect();
    let sg: Vec<Option<f64>> = theirs.iter().flat_map(|(d, _)| d.clone()).collect();
    assert_eq!(sg.len(), exact.len());
    let mut sg_err: Vec<f64> = sg.iter().zip(&exact).filter_map(|(s, e)| Some((s.as_ref()? - e).abs())).collect();
    let sg_found = sg_err.len() as f64 / exact.len() as f64;
    let (sg_median, sg_p90) = (quantile(&mut sg_err.clone(), 0.5), quantile(&mut sg_err, 0.9));
    println!(
        "StereoSGBM at the same keypoints: a disparity at {:.0} %, error median {sg_median:.3} px, p90 {sg_p90:.3} px",
        100.0 * sg_found
    );
    // The dense peer on the same rectified pairs agrees with the exact disparity (the pairs
    // are rectified as claimed), and with ours: where both have a disparity, within a pixel
    // at nearly every keypoint. SGBM is the more precise of the two (its cost is aggregated
    // along 8 paths; ORB-SLAM2's is one 11x11 SAD with a parabola), and the docs say so.
    assert!(sg_median < 0.5, "SGBM median {sg_median}: the pairs are not rectified as claimed");
    let both: Vec<f64> = sg.iter().zip(&ours).filter_map(|(s, (d, _))| Some((s.as_ref()? - d).abs())).collect();
    let agree = both.iter().filter(|e| **e <= 1.0).count() as f64 / both.len() as f64;
    println!("ours and SGBM within 1 px at {:.1} % of the {} keypoints both matched", 100.0 * agree, both.len());
    assert!(agree > 0.9, "agreement {agree}");
    assert!(median < sg_median + 0.15, "ours {median} against SGBM {sg_median}");
}
