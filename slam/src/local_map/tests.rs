//! Key-frame culling on a hand-made map, the expected outcome worked out from ORB-SLAM2's rule.
#![allow(clippy::unwrap_used)]

use super::*;
use nalgebra::{Isometry3, Translation3};

const CAM: Pinhole = Pinhole { fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 };

/// Key frame `id` at `x` metres along the x axis observing points `ids` (a grid 2 m away, all
/// on octave `octave`), exactly.
fn batch(id: u64, x: f64, ids: std::ops::Range<u64>, octave: u8, new_points: bool) -> SparseMap {
    let pose = Isometry3::from_parts(Translation3::new(x, 0.0, 0.0), nalgebra::UnitQuaternion::identity());
    let position = |p: u64| Point3::new(-1.0 + 0.1 * (p % 20) as f64, -0.5 + 0.1 * (p / 20) as f64, 2.0);
    let mut map = SparseMap {
        map_id: 0,
        keyframes: vec![MapKeyFrame { id, stamp: id as f64, world_from_cam: pose }],
        ..SparseMap::default()
    };
    for p in ids {
        let c = pose.inverse() * position(p);
        map.observations.push(MapObservation {
            keyframe: id,
            point: p,
            uv: CAM.project(&c).unwrap(),
            depth: Some(c.z),
            octave,
        });
        if new_points {
            map.points.push(MapPoint {
                id: p,
                position: position(p),
                descriptor: [p as u8; 32],
                observations: 0,
                first_keyframe: id,
            });
        }
    }
    map
}

/// Insert key frames 0..=3 at x = 0, 1, 2, 3 cm seeing points 0..100 on octave 0 (key frame 0
/// makes them), then `last`; the ids culled at each insertion.
fn run(config: LocalMapConfig, last: &SparseMap) -> (LocalMapper, Vec<Vec<u64>>, SparseMap) {
    let mut m = LocalMapper::new(config, CAM);
    let mut culled = Vec::new();
    for k in 0..4 {
        let out = m.insert(&batch(k, 0.01 * k as f64, 0..100, 0, k == 0));
        culled.push(out.culled.iter().map(|c| c.id).collect());
    }
    let out = m.insert(last);
    culled.push(out.culled.iter().map(|c| c.id).collect());
    (m, culled, out)
}

#[test]
fn a_key_frame_whose_points_three_others_see_is_culled_best_covisible_first_never_the_first() {
    // All share the same 100 points, so covisible key frames are tried newest first. At key
    // frame 3's insertion key frame 2 has three other observers per point (0, 1, 3): culled;
    // 1 has two left (0, 3): kept. At key frame 4's, 3 has 0, 1, 4: culled; 1 has 0, 4: kept;
    // 0 is the map's first and is never tried.
    let (m, culled, out) = run(LocalMapConfig::rgbd(CAM.fx), &batch(4, 0.04, 0..100, 0, false));
    assert_eq!(culled, vec![vec![], vec![], vec![], vec![2], vec![3]]);
    // The best covisible key frame stands in (a tie: the newest), with the map's relative pose.
    assert_eq!(out.culled[0].anchor, 4);
    assert!((out.culled[0].anchor_from_culled.translation.x + 0.01).abs() < 1e-4, "{:?}", out.culled[0]);
    assert_eq!(m.keyframes(), 3);
    assert_eq!(m.culled_keyframes(), 2);
    assert!(out.keyframes.iter().all(|k| k.id != 3 && k.id != 2));
    // Every point is still seen by key frames 0, 1 and 4: none was removed.
    assert_eq!(m.points(), 100);
    // Switched off, nothing goes.
    let off = LocalMapConfig { cull_keyframes: false, ..LocalMapConfig::rgbd(CAM.fx) };
    let (all, culled, _) = run(off, &batch(4, 0.04, 0..100, 0, false));
    assert!(culled.iter().all(Vec::is_empty));
    assert_eq!(all.keyframes(), 5);
    // The memory report sees it: 3 key frames of 100 observations against 5, the same points.
    let (kept, full) = (m.memory(), all.memory());
    let per_kf = 100 * std::mem::size_of::<MapObservation>();
    assert!(kept.keyframes >= 3 * per_kf && full.keyframes >= 5 * per_kf, "{kept:?} {full:?}");
    assert!(full.keyframes - kept.keyframes >= 2 * per_kf, "{kept:?} {full:?}");
    assert_eq!(kept.bow_index, 0);
}

#[test]
fn own_points_far_points_and_coarser_observers_keep_a_key_frame() {
    // Key frame 4 seen on octave 1 counts for key frame 3's octave-0 observations (octave + 1):
    // 3 goes. On octave 2 it does not: 3 and 1 each keep two fine observers, and stay.
    let (_, culled, _) = run(LocalMapConfig::rgbd(CAM.fx), &batch(4, 0.04, 0..100, 1, false));
    assert_eq!(culled[4], vec![3]);
    let (_, culled, _) = run(LocalMapConfig::rgbd(CAM.fx), &batch(4, 0.04, 0..100, 2, false));
    assert_eq!(culled[4], Vec::<u64>::new());

    // Key frame 4 also sees 20 points of its own, then key frame 5 sees the shared 100 only:
    // of 4's 120 points 100 are redundant (83 %, not over 90 %): 4 stays (and 1 goes: 0, 4, 5).
    let mut last = batch(4, 0.04, 0..100, 0, false);
    let own = batch(4, 0.04, 100..120, 0, true);
    last.observations.extend(own.observations);
    last.points.extend(own.points);
    let (mut m, _, _) = run(LocalMapConfig::rgbd(CAM.fx), &last);
    let out = m.insert(&batch(5, 0.05, 0..100, 0, false));
    assert_eq!(out.culled.iter().map(|c| c.id).collect::<Vec<_>>(), vec![1]);

    // Points beyond the close depth (ORB-SLAM2's 40 baselines) do not count: with it under the
    // points' 2 m no key frame has a close point, and none goes (0 > 0.9 x 0 is false).
    let far = LocalMapConfig { close_depth: 1.5, ..LocalMapConfig::rgbd(CAM.fx) };
    let (_, culled, _) = run(far, &batch(4, 0.04, 0..100, 0, false));
    assert!(culled.iter().all(Vec::is_empty));
    // A single camera has no depth: every observed point counts.
    let (_, culled, _) = run(LocalMapConfig::monocular(CAM.fx), &batch(4, 0.04, 0..100, 0, false));
    assert_eq!(culled[3..], [vec![2], vec![3]]);
}
