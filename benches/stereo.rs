//! Per-frame cost of ORB-SLAM2's two other sensor modes' front-end steps, single thread, on
//! the synthetic scene: sparse stereo matching of one rectified pair (the left and
//! right ORB given; the right image's ORB timed beside it, since the stereo mode pays it on
//! every frame) and the monocular two-view initialisation (initial matching is the tracker's;
//! here the H and F RANSAC, model selection, decomposition and triangulation of
//! `dynaflow_vision::geometry::initialise` on the matches of two frames 10 apart).
//!
//! `cargo bench --bench stereo` (add `-- REPS`, default 30). No peer runs here: OpenCV has no
//! sparse ORB stereo matcher nor ORB-SLAM2's initialiser; the real ORB-SLAM2 is the
//! whole-system peer (bench script).
#![allow(clippy::unwrap_used, clippy::panic)]

#[path = "common/timing.rs"]
mod timing;

#[path = "../tests/common/mod.rs"]
mod common;
#[path = "../vision/tests/common/frontend.rs"]
mod frontend;
#[path = "../vision/tests/common/stereo.rs"]
mod stereo;

use timing::median_ms;

use dynaflow_datasets::synth::{Generator, Motion, SynthConfig};
use dynaflow_vision::GrayImage;
use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{SplitMix64, TwoViewConfig, initialise};
use dynaflow_vision::matching::{MatchConfig, match_brute_force};
use dynaflow_vision::orb::{OrbConfig, OrbExtractor};
use dynaflow_vision::stereo::{StereoView, stereo_match};

fn xy(k: &dynaflow_vision::orb::Keypoint) -> [f64; 2] {
    [f64::from(k.x), f64::from(k.y)]
}

fn main() {
    let reps: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(30);
    println!("single thread, median of {reps} runs, 640x480, ORB 1000 features (ORB-SLAM2's settings)");
    for (motion, k) in [(Motion::Xyz, 10), (Motion::Halfsphere, 100)] {
        let pair = stereo::synth_stereo(motion, 3, k, 0.12);
        let mut left = OrbExtractor::new(OrbConfig::default());
        let mut right = OrbExtractor::new(OrbConfig::default());
        let orb_ms = median_ms(reps, || {
            std::hint::black_box(right.extract(&pair.right, None));
        });
        let fl = left.extract(&pair.left, None);
        let fr = right.extract(&pair.right, None);
        let (ll, rl) = (left.pyramid(&pair.left), right.pyramid(&pair.right));
        let mut matched = 0;
        let match_ms = median_ms(reps, || {
            let m = stereo_match(
                &StereoView { keypoints: &fl.keypoints, descriptors: &fl.descriptors, levels: &ll },
                &StereoView { keypoints: &fr.keypoints, descriptors: &fr.descriptors, levels: &rl },
                &pair.rig,
            )
            .unwrap();
            matched = m.matches.iter().flatten().count();
        });
        println!(
            "stereo {motion:?} frame {k}: stereo_match {match_ms:.2} ms ({matched} of {} keypoints matched); the right image's ORB {orb_ms:.2} ms",
            fl.keypoints.len()
        );
    }
    // Monocular initialisation: frames 0 and 10 of the static xyz scene, ORB matches
    // (cross-checked, ratio 0.9) as the pixel pairs.
    for (motion, a, b) in [(Motion::Xyz, 0, 10), (Motion::Halfsphere, 0, 10)] {
        let g = Generator::new(SynthConfig { motion, people: 0, seed: 3, ..SynthConfig::default() });
        let i = g.config().intrinsics.clone();
        let gray = |k: u64| GrayImage::from_rgb8(i.width as usize, i.height as usize, &g.frame(k, false).rgb).unwrap();
        let mut orb = OrbExtractor::new(OrbConfig::default());
        let (f1, f2) = (orb.extract(&gray(a), None), orb.extract(&gray(b), None));
        let config = MatchConfig { ratio: 0.9, cross_check: true, ..MatchConfig::default() };
        let m = match_brute_force(&f2.descriptors, &f1.descriptors, None, &config);
        let p1: Vec<[f64; 2]> = m.iter().map(|m| xy(&f1.keypoints[m.train as usize])).collect();
        let p2: Vec<[f64; 2]> = m.iter().map(|m| xy(&f2.keypoints[m.query as usize])).collect();
        let cam = Pinhole::from(&i);
        let mut outcome = String::new();
        let ms = median_ms(reps, || {
            let r = initialise(&p1, &p2, &cam, &TwoViewConfig::default(), &mut SplitMix64::new(7));
            outcome = match r {
                Ok(init) => format!(
                    "{:?}, R_H {:.2}, {} points, parallax {:.1} deg",
                    init.model,
                    init.ratio,
                    init.points.iter().flatten().count(),
                    init.parallax_deg
                ),
                Err(e) => format!("refused: {e}"),
            };
        });
        println!("mono init {motion:?} frames {a}-{b}: {ms:.2} ms on {} matches ({outcome})", p1.len());
    }
}
