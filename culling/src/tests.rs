use super::*;

#[test]
fn points_take_the_label_of_the_nearest_track_within_the_radius() {
    // A dynamic track at (10, 10), a static one at (30, 10).
    let labelled = [([10.0, 10.0], true), ([30.0, 10.0], false)];
    let points = [[10.0, 10.0], [17.0, 10.0], [22.0, 10.0], [10.0, 25.0], [100.0, 100.0]];
    let mut dynamic = vec![false; points.len()];
    nearest_track_labels(&labelled, &points, 10.0, &mut dynamic);
    // On the track; nearer the dynamic one; nearer the static one; 15 px away; far away.
    assert_eq!(dynamic, [true, true, false, false, false]);
    // Radius 0: only a point exactly on a dynamic track.
    let mut dynamic = vec![false; points.len()];
    nearest_track_labels(&labelled, &points, 0.0, &mut dynamic);
    assert_eq!(dynamic, [true, false, false, false, false]);
    // A mask's verdict is never undone by a static track.
    let mut dynamic = vec![true; points.len()];
    nearest_track_labels(&labelled, &points, 10.0, &mut dynamic);
    assert!(dynamic.iter().all(|&d| d));
}

/// Every point's pixel in each of `frames` frames of a camera moving by `step` (rotation,
/// translation) a frame in a room 2-6 m deep; a fifth of the points (a walker) drift 0.6 px
/// a frame sideways.
fn frames_of(frames: usize, step: (f64, f64)) -> Vec<Vec<[f32; 2]>> {
    let mut rng = SplitMix64::new(5);
    let points: Vec<nalgebra::Point3<f64>> = (0..400)
        .map(|_| nalgebra::Point3::new(rng.uniform() * 3.0 - 1.5, rng.uniform() * 2.0 - 1.0, 2.0 + 4.0 * rng.uniform()))
        .collect();
    let camera = Pinhole::new(525.0, 525.0, 320.0, 240.0);
    (0..frames)
        .map(|f| {
            let k = f as f64;
            let pose = nalgebra::Isometry3::new(
                nalgebra::Vector3::new(step.1 * k, 0.0, 0.0),
                nalgebra::Vector3::new(0.0, step.0.to_radians() * k, 0.0),
            );
            let drift = |i: usize| if i.is_multiple_of(5) { 0.6 * k } else { 0.0 };
            let project = |(i, x): (usize, &nalgebra::Point3<f64>)| {
                let p = camera.project(&(pose * x)).unwrap_or([0.0, 0.0]);
                [(p[0] + drift(i)) as f32, p[1] as f32]
            };
            points.iter().enumerate().map(project).collect()
        })
        .collect()
}

/// The ten-frame epipolar rule (0.4 px) over `frames`, one result per frame pair.
fn label_frames(frames: &[Vec<[f32; 2]>], long_baseline: LongBaseline, select_model: bool) -> Vec<EpipolarFrame> {
    let options = EpipolarOptions {
        threshold: 0.4,
        ransac: RansacConfig { threshold: 0.4, ..RansacConfig::default() },
        sticky: false,
        fit_static: false,
        baseline: 10,
        long_baseline,
        select_model,
    };
    let ids: Vec<u64> = (0..frames[0].len() as u64).collect();
    let mut cull = EpipolarCull::new(options);
    (1..frames.len()).map(|f| cull.label(&ids, &frames[f - 1], &frames[f], f as u64)).collect()
}

#[test]
fn the_longer_baseline_runs_where_orbslam2_finds_no_parallax() {
    let run = |frames: &[Vec<[f32; 2]>], long_baseline| label_frames(frames, long_baseline, false);
    // A camera that only rotates: no parallax, ORB-SLAM2 would take the homography, so
    // every track tracked ten frames is tested over them, as without the gate.
    let rotating = frames_of(12, (0.3, 0.0));
    let (gated, always) = (run(&rotating, LongBaseline::LowParallax), run(&rotating, LongBaseline::Always));
    let last = gated.last().unwrap();
    assert!(last.homography_ratio.is_some_and(|r| r > HOMOGRAPHY_RATIO), "{:?}", last.homography_ratio);
    assert_eq!(last.long, 400);
    assert!(gated.iter().zip(&always).all(|(g, a)| g.decisions == a.decisions && g.long == a.long));
    // 20 cm sideways a frame: tens of pixels of parallax, F is well posed, and the gated
    // rule keeps to consecutive frames (the ungated one does not).
    let wide = frames_of(12, (0.0, 0.2));
    let (gated, always) = (run(&wide, LongBaseline::LowParallax), run(&wide, LongBaseline::Always));
    let last = gated.last().unwrap();
    assert!(last.homography_ratio.is_some_and(|r| r < HOMOGRAPHY_RATIO), "{:?}", last.homography_ratio);
    assert_eq!((last.long, always.last().unwrap().long), (0, 400));
}

#[test]
fn model_selection_tests_a_rotation_against_its_homography() {
    let last = |frames: &[Vec<[f32; 2]>], select_model| {
        label_frames(frames, LongBaseline::Always, select_model).pop().unwrap()
    };
    // A rotating camera: the ten-frame pair is a homography (R_H > 0.40), so the walkers
    // (every fifth point, 6 px off over ten frames) are judged by their transfer error,
    // which no epipole can explain away: every one flagged, no static point.
    let rotating = frames_of(12, (0.3, 0.0));
    let f = last(&rotating, true);
    assert!(f.long_homography && f.long_homography_ratio.is_some_and(|r| r > HOMOGRAPHY_RATIO));
    let flagged: Vec<bool> = f.decisions.iter().map(|d| d.dynamic).collect();
    assert!(flagged.iter().enumerate().all(|(i, d)| *d == i.is_multiple_of(5)), "{flagged:?}");
    // 20 cm a frame: parallax, F is selected and the decisions are the epipolar test's.
    let wide = frames_of(12, (0.0, 0.2));
    let (selected, plain) = (last(&wide, true), last(&wide, false));
    assert!(!selected.long_homography && selected.long_homography_ratio.is_some_and(|r| r < HOMOGRAPHY_RATIO));
    assert_eq!(selected.decisions, plain.decisions);
}

#[test]
fn the_history_gives_a_tracks_pixel_k_frames_back_while_it_is_tracked() {
    let mut h = TrackHistory::new(2);
    h.update(&[1], &[[0.0, 0.0]], &[[1.0, 0.0]]);
    assert_eq!(h.back(1), None, "one frame of history for k = 2");
    h.update(&[1, 2], &[[1.0, 0.0], [5.0, 5.0]], &[[2.0, 0.0], [6.0, 5.0]]);
    assert_eq!(h.back(1), Some([0.0, 0.0]));
    assert_eq!(h.back(2), None);
    h.update(&[1, 2], &[[2.0, 0.0], [6.0, 5.0]], &[[3.0, 0.0], [7.0, 5.0]]);
    assert_eq!(h.back(1), Some([1.0, 0.0]));
    assert_eq!(h.back(2), Some([5.0, 5.0]));
    h.update(&[2], &[[7.0, 5.0]], &[[8.0, 5.0]]);
    assert_eq!(h.back(1), None, "a track that ended is forgotten");
}

#[test]
fn a_dynamic_track_stays_dynamic_while_tracked_and_is_forgotten_when_it_ends() {
    let d = |dynamic: bool| Decision { dynamic, reason: LabelReason::Epipolar, score: 0.0 };
    let mut sticky = StickyLabels::default();
    // Frame 1: track 7 is dynamic, 8 static.
    let mut f1 = vec![d(true), d(false)];
    sticky.apply(&[7, 8], &mut f1);
    assert!(sticky.was_dynamic(7) && !sticky.was_dynamic(8));
    // Frame 2: 7 under the threshold (moving along its epipolar line) stays dynamic; 8 too.
    let mut f2 = vec![d(false), d(false), d(false)];
    sticky.apply(&[7, 8, 9], &mut f2);
    assert_eq!(f2.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![true, false, false]);
    // Frame 3: track 7 is lost; frame 4: a new track with another id is not dynamic.
    let mut f3 = vec![d(false)];
    sticky.apply(&[8], &mut f3);
    assert!(!sticky.was_dynamic(7));
    // `remember` records without changing decisions.
    let f4 = vec![d(true)];
    sticky.remember(&[11], &f4);
    let mut f5 = vec![d(false)];
    sticky.apply(&[11], &mut f5);
    assert!(f5[0].dynamic);
}

#[test]
fn combine_labels_decision_table() {
    let s = |score| Some(Decision { dynamic: false, reason: LabelReason::Static, score });
    let sem = Some(Decision { dynamic: true, reason: LabelReason::Semantic, score: 1.0 });
    let epi = Some(Decision { dynamic: true, reason: LabelReason::Epipolar, score: 0.9 });
    // (a, b, mode) -> (dynamic, reason, score): every combination of static, dynamic and
    // unlabelled on both sides, for both modes.
    let table = [
        (s(0.1), s(0.2), Combine::Or, false, LabelReason::Static, 0.1),
        (sem, s(0.2), Combine::Or, true, LabelReason::Semantic, 1.0),
        (s(0.1), epi, Combine::Or, true, LabelReason::Epipolar, 0.9),
        (sem, epi, Combine::Or, true, LabelReason::Semantic, 1.0),
        (None, epi, Combine::Or, true, LabelReason::Epipolar, 0.9),
        (sem, None, Combine::Or, true, LabelReason::Semantic, 1.0),
        (None, s(0.2), Combine::Or, false, LabelReason::Static, 0.2),
        (s(0.1), s(0.2), Combine::And, false, LabelReason::Static, 0.1),
        (sem, s(0.2), Combine::And, false, LabelReason::Static, 0.2),
        (s(0.1), epi, Combine::And, false, LabelReason::Static, 0.1),
        (sem, epi, Combine::And, true, LabelReason::Semantic, 1.0),
        (None, epi, Combine::And, false, LabelReason::Static, 0.9),
        (sem, None, Combine::And, false, LabelReason::Static, 1.0),
    ];
    for (k, (a, b, how, dynamic, reason, score)) in table.into_iter().enumerate() {
        let d = combine(a, b, how);
        assert_eq!((d.dynamic, d.reason, d.score), (dynamic, reason, score), "row {k}: {a:?} {how:?} {b:?}");
    }
    assert!(combine(None, None, Combine::Or).score.is_nan() && !combine(None, None, Combine::Or).dynamic);
}

#[test]
fn fixed_and_adaptive_epipolar_rules() {
    let d = [0.1, 0.5, 3.0, f32::NAN];
    let fixed = epipolar_fixed(&d, 0.4);
    assert_eq!(fixed.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![false, true, true, true]);
    // Outside boxes: 0.1 and 0.5 -> threshold 0.3; inside: 3.0 dynamic, NaN dynamic.
    let (adaptive, thr) = epipolar_adaptive(&d, &[false, false, true, true]);
    assert!((thr - 0.3).abs() < 1e-6);
    assert_eq!(adaptive.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![false, false, true, true]);
    assert_eq!(adaptive[0].reason, LabelReason::Static);
}

#[test]
fn semantic_prior_follows_yg_slam() {
    let boxes = vec![
        LabelledBox { bbox: [0.0, 0.0, 10.0, 10.0], label: "person".into() },
        LabelledBox { bbox: [20.0, 0.0, 30.0, 10.0], label: "chair".into() },
        LabelledBox { bbox: [5.0, 5.0, 8.0, 8.0], label: "book".into() },
    ];
    let value = |l: &str| DEFAULT_DYNAMIC_VALUES.iter().find(|(n, _)| *n == l).map_or(0.0, |(_, v)| *v);
    let pts = [[2.0, 2.0], [25.0, 5.0], [6.0, 6.0], [50.0, 50.0]];
    let normal = semantic_prior(&pts, &boxes, value, false);
    assert_eq!(normal.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![true, false, false, false]);
    let key = semantic_prior(&pts, &boxes, value, true);
    // The chair (0.6) counts on key frames; the point on the book inside the person is kept.
    assert_eq!(key.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![true, true, false, false]);
}

#[test]
fn depth_consistency_flags_points_whose_depth_does_not_follow_the_camera() {
    let cam = Pinhole::new(500.0, 500.0, 320.0, 240.0);
    // The camera moved 0.1 m forward since the key frame: static points came 0.1 m closer.
    let cur_from_key = nalgebra::Isometry3::translation(0.0, 0.0, -0.1);
    let pts = [[320.0, 240.0], [100.0, 100.0], [200.0, 300.0], [50.0, 50.0]];
    let predicted: Vec<Option<nalgebra::Point3<f64>>> =
        pts.iter().enumerate().map(|(i, p)| (i != 3).then(|| cur_from_key * cam.unproject(*p, 2.0))).collect();
    // Moving straight forward keeps the centre pixel and pulls the others outwards: the
    // second point now projects near (88, 93), where something 0.5 m nearer is seen (it
    // moved); the third near (194, 303), with no measurement; the fourth had no key depth.
    let depth_cur = |x: f32, y: f32| {
        if (x - 320.0).abs() < 0.5 && (y - 240.0).abs() < 0.5 {
            1.9
        } else if x < 150.0 && y < 150.0 {
            1.4
        } else {
            0.0
        }
    };
    let d = depth_consistency(&predicted, cam, depth_cur, 0.1);
    assert_eq!(d.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![false, true, false, false]);
    assert!(d[0].score < 1e-5 && (d[1].score - 0.5).abs() < 1e-5 && d[2].score.is_nan());
    assert_eq!(d[1].reason, LabelReason::Depth);
}

#[test]
fn mask_rule_uses_the_point_position() {
    let d = mask_rule(&[[1.0, 1.0], [5.0, 5.0], [-3.0, 2.0]], |x, y| x < 3 && y < 3);
    assert_eq!(d.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![true, false, false]);
}

#[test]
fn depth_anchors_keep_a_static_point_and_flag_one_that_moved() {
    // A camera 2 m in front of a wall moves 0.1 m sideways; track 1 sits on the wall,
    // track 2 on a person 1 m away who walks with the camera (same pixel, same depth).
    let camera = Pinhole::new(500.0, 500.0, 320.0, 240.0);
    let wall = |_: f32, _: f32| 2.0f32;
    let person = |x: f32, _: f32| if (x - 320.0).abs() < 1.0 { 1.0f32 } else { 2.0 };
    let world_from_prev = nalgebra::Isometry3::identity();
    let world_from_cur = nalgebra::Isometry3::translation(0.1, 0.0, 0.0);
    // The wall point shifts by fx * 0.1 / 2 = 25 px; the person stays at the centre.
    let tracks = [
        TrackedPoint { id: 1, prev: [300.0, 240.0], cur: [275.0, 240.0] },
        TrackedPoint { id: 2, prev: [320.0, 240.0], cur: [320.0, 240.0] },
    ];
    let mut anchors = DepthAnchors::new();
    // First frame: nothing anchored yet, nothing judged.
    let first = anchors.label(&tracks, camera, None::<(fn(f32, f32) -> f32, _)>, (person, world_from_prev), 0.1);
    assert!(first.iter().all(|d| !d.dynamic && d.score.is_nan()) && anchors.is_empty());
    let second = anchors.label(&tracks, camera, Some((person, world_from_prev)), (person, world_from_cur), 0.1);
    assert_eq!(anchors.len(), 2);
    assert!(!second[0].dynamic && second[0].score < 1e-3, "{:?}", second[0]);
    // The person's anchor (1 m ahead at x = 0) is seen at x = -0.1 m, 50 px left of the
    // centre, where the wall (2 m) is measured: 1 m off, dynamic.
    assert!(second[1].dynamic && (second[1].score - 1.0).abs() < 1e-3, "{:?}", second[1]);
    // A track that ends is forgotten.
    let _ = anchors.label(&tracks[..1], camera, Some((wall, world_from_cur)), (wall, world_from_cur), 0.1);
    assert_eq!(anchors.len(), 1);
}
