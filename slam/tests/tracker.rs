//! The tracker and local mapping on generated RGB-D keypoints (exact world points with random
//! ORB-like descriptors, pixel and depth noise): clean tracking, and degenerate input that
//! must lose tracking gracefully, recover and say so, never panic.
#![allow(clippy::unwrap_used)]

use dynaflow_slam::eval::{Align, evaluate};
use dynaflow_slam::{Feature, LocalMapConfig, LocalMapper, TrackState, Tracker, TrackerConfig};
use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::SplitMix64;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};

const CAM: Pinhole = Pinhole { fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 };

struct World {
    points: Vec<(Point3<f64>, [u8; 32])>,
}

impl World {
    /// `n` points in front of the start pose; on the plane z = 4 when `plane`.
    fn new(n: usize, seed: u64, plane: bool) -> Self {
        let mut rng = SplitMix64::new(seed);
        let points = (0..n)
            .map(|_| {
                let z = if plane { 4.0 } else { 2.0 + 4.0 * rng.uniform() };
                let p = Point3::new(8.0 * rng.uniform() - 4.0, 6.0 * rng.uniform() - 3.0, z);
                let mut d = [0u8; 32];
                for b in &mut d {
                    *b = (rng.next_u64() & 0xff) as u8;
                }
                (p, d)
            })
            .collect();
        Self { points }
    }

    /// The keypoints a camera at `world_from_cam` sees (at most 1000), with noise.
    fn frame(&self, world_from_cam: &Isometry3<f64>, rng: &mut SplitMix64, with_depth: bool) -> Vec<Feature> {
        let cam_from_world = world_from_cam.inverse();
        let mut out = Vec::new();
        for (p, d) in &self.points {
            let pc = cam_from_world * p;
            let Some(uv) = CAM.project(&pc) else { continue };
            if !(0.0..640.0).contains(&uv[0]) || !(0.0..480.0).contains(&uv[1]) {
                continue;
            }
            let mut descriptor = *d;
            // A few flipped bits: the same corner seen again is never bit-identical.
            for _ in 0..4 {
                let bit = rng.below(256);
                descriptor[bit / 8] ^= 1 << (bit % 8);
            }
            out.push(Feature {
                uv: [uv[0] + 0.6 * (rng.uniform() - 0.5), uv[1] + 0.6 * (rng.uniform() - 0.5)],
                octave: 0,
                angle: -1.0,
                depth: with_depth.then(|| pc.z * (1.0 + 0.004 * (rng.uniform() - 0.5))),
                descriptor,
                dynamic: false,
            });
            if out.len() == 1000 {
                break;
            }
        }
        out
    }
}

/// The camera path: 1 cm and 0.2 degrees of yaw per frame.
fn pose(k: usize) -> Isometry3<f64> {
    let k = k as f64;
    Isometry3::from_parts(
        Translation3::new(0.01 * k, 0.002 * k, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0035 * k, 0.0),
    )
}

struct Slam {
    tracker: Tracker,
    mapper: LocalMapper,
    est: Vec<(f64, Isometry3<f64>)>,
    gt: Vec<(f64, Isometry3<f64>)>,
    states: Vec<TrackState>,
}

impl Slam {
    fn new() -> Self {
        Self {
            tracker: Tracker::new(TrackerConfig::rgbd(CAM.fx), CAM, 640, 480, 1),
            mapper: LocalMapper::new(LocalMapConfig::rgbd(CAM.fx), CAM),
            est: Vec::new(),
            gt: Vec::new(),
            states: Vec::new(),
        }
    }

    /// One frame; local mapping answers at once (lockstep with `delay: 1` does the same one
    /// frame later).
    fn step(&mut self, k: usize, features: &[Feature]) -> TrackState {
        let r = self.tracker.track(k as f64 / 30.0, features);
        if let Some(kf) = &r.keyframe {
            let update = self.mapper.insert(kf);
            self.tracker.apply_map_update(&update);
        }
        if let Some(p) = r.world_from_cam {
            self.est.push((k as f64 / 30.0, p));
            self.gt.push((k as f64 / 30.0, pose(k)));
        }
        self.states.push(r.state);
        r.state
    }

    fn ate(&self) -> f64 {
        evaluate(&self.gt, &self.est, 1e-3, Align::Se3, 1).unwrap().ate.rmse
    }

    /// Position error of the last pose (the map's world is the first frame's camera).
    fn last_error(&self) -> f64 {
        let (_, e) = self.est.last().unwrap();
        let (_, g) = self.gt.last().unwrap();
        let first = self.gt.first().unwrap().1;
        (e.translation.vector - (first.inverse() * g).translation.vector).norm()
    }
}

#[test]
fn tracks_a_clean_sequence_with_local_mapping() {
    let world = World::new(3000, 1, false);
    let mut rng = SplitMix64::new(2);
    let mut slam = Slam::new();
    for k in 0..80 {
        let f = world.frame(&pose(k), &mut rng, true);
        slam.step(k, &f);
    }
    assert_eq!(slam.states[0], TrackState::NewMap);
    assert!(slam.states[1..].iter().all(|s| *s == TrackState::Tracked), "{:?}", slam.states);
    // The view changes enough for tracking to fall below 75 % of the first key frame's
    // points: local mapping gets a second key frame (time alone makes none: ORB-SLAM2's rule).
    assert!(slam.mapper.keyframes() >= 2, "key frames: {}", slam.mapper.keyframes());
    assert!(slam.ate() < 0.005, "ATE {}", slam.ate());
}

#[test]
fn a_camera_that_stays_put_makes_no_key_frame_on_time_alone() {
    // ORB-SLAM2's rule: `max_frames` passing (its c1a) makes a key frame only together with its
    // c2 (tracking fell below 75 % of the reference, or too few close points): a still camera
    // keeps its first key frame, where a key frame a second would give ten over 300 frames.
    let world = World::new(3000, 3, false);
    let mut rng = SplitMix64::new(4);
    let mut slam = Slam::new();
    let mut made = 0;
    for k in 0..300 {
        let f = world.frame(&pose(0), &mut rng, true);
        let r = slam.tracker.track(k as f64 / 30.0, &f);
        if let Some(kf) = &r.keyframe {
            made += 1;
            let update = slam.mapper.insert(kf);
            slam.tracker.apply_map_update(&update);
        }
        assert!(matches!(r.state, TrackState::NewMap | TrackState::Tracked), "frame {k}: {:?}", r.state);
    }
    assert_eq!(made, 1);
}

#[test]
fn dynamic_keypoints_never_reach_the_solver() {
    // Half of the keypoints stick to the image (an object moving with the camera).
    let world = World::new(3000, 3, false);
    let mut rng = SplitMix64::new(4);
    let run = |flag: bool, rng: &mut SplitMix64| {
        let mut slam = Slam::new();
        let stuck = world.frame(&pose(0), &mut SplitMix64::new(9), true);
        for k in 0..60 {
            let mut f = world.frame(&pose(k), rng, true);
            f.extend(stuck.iter().take(600).map(|s| Feature { dynamic: flag, ..*s }));
            slam.step(k, &f);
        }
        slam.ate()
    };
    let (labelled, unlabelled) = (run(true, &mut rng), run(false, &mut rng));
    assert!(labelled < 0.005, "labelled dynamic: ATE {labelled}");
    assert!(unlabelled > labelled, "the stuck points must hurt when they are used: {unlabelled} vs {labelled}");
}

#[test]
fn no_depth_waits_for_a_frame_that_can_start_the_map() {
    let world = World::new(3000, 5, false);
    let mut rng = SplitMix64::new(6);
    let mut slam = Slam::new();
    for k in 0..3 {
        let f = world.frame(&pose(k), &mut rng, false);
        assert_eq!(slam.step(k, &f), TrackState::NotInitialised);
    }
    assert!(slam.est.is_empty(), "no pose before a map exists");
    for k in 3..20 {
        let f = world.frame(&pose(k), &mut rng, true);
        slam.step(k, &f);
    }
    assert_eq!(slam.states[3], TrackState::NewMap);
    assert!(slam.states[4..].iter().all(|s| *s == TrackState::Tracked), "{:?}", slam.states);
}

#[test]
fn a_black_frame_and_too_few_matches_lose_tracking_then_it_recovers() {
    let world = World::new(3000, 7, false);
    let mut rng = SplitMix64::new(8);
    let mut slam = Slam::new();
    for k in 0..40 {
        let mut f = world.frame(&pose(k), &mut rng, true);
        match k {
            20 => f.clear(),     // a black frame: no keypoints at all
            21 => f.truncate(3), // fewer than four matches
            _ => {}
        }
        slam.step(k, &f);
    }
    assert_eq!(slam.states[20], TrackState::Lost);
    assert_eq!(slam.states[21], TrackState::Lost);
    assert!(matches!(slam.states[22], TrackState::Tracked | TrackState::Relocalised), "{:?}", slam.states);
    assert!(slam.states[23..].iter().all(|s| *s == TrackState::Tracked), "{:?}", slam.states);
    assert!(slam.last_error() < 0.01, "error after recovery {}", slam.last_error());
    assert_eq!(slam.tracker.map_id(), 1, "a short loss keeps the map");
}

#[test]
fn a_ten_frame_gap_is_bridged_by_relocalisation() {
    let world = World::new(3000, 9, false);
    let mut rng = SplitMix64::new(10);
    let mut slam = Slam::new();
    // A faster camera: 3 cm per frame, so the gap is a 30 cm jump the motion model cannot guess.
    let fast = |k: usize| pose(3 * k);
    for k in (0..30).chain(40..60) {
        let f = world.frame(&fast(k), &mut rng, true);
        let r = slam.tracker.track(k as f64 / 30.0, &f);
        if let Some(kf) = &r.keyframe {
            let u = slam.mapper.insert(kf);
            slam.tracker.apply_map_update(&u);
        }
        if k == 40 {
            assert_eq!(r.state, TrackState::Relocalised, "the jump needs relocalisation");
            let e = (r.world_from_cam.unwrap().translation.vector - fast(40).translation.vector).norm();
            assert!(e < 0.01, "relocalised within {e} m");
        }
        slam.states.push(r.state);
    }
    assert!(slam.states.iter().skip(31).all(|s| *s == TrackState::Tracked), "{:?}", slam.states);
}

#[test]
fn a_plane_is_enough() {
    let world = World::new(3000, 11, true);
    let mut rng = SplitMix64::new(12);
    let mut slam = Slam::new();
    for k in 0..60 {
        let f = world.frame(&pose(k), &mut rng, true);
        slam.step(k, &f);
    }
    assert!(slam.states[1..].iter().all(|s| *s == TrackState::Tracked), "{:?}", slam.states);
    assert!(slam.ate() < 0.005, "ATE on a plane {}", slam.ate());
}

#[test]
fn a_long_loss_in_a_new_place_starts_a_new_map() {
    let world = World::new(3000, 13, false);
    let elsewhere = World::new(3000, 14, false);
    let mut rng = SplitMix64::new(15);
    let mut slam = Slam::new();
    for k in 0..20 {
        let f = world.frame(&pose(k), &mut rng, true);
        slam.step(k, &f);
    }
    // Nothing recognisable for ten frames (the camera was covered, then moved somewhere new).
    for k in 20..40 {
        let f = elsewhere.frame(&pose(k), &mut rng, true);
        slam.step(k, &f);
    }
    // `reset_after` (5) lost frames, then a new map.
    assert!(slam.states[20..25].iter().all(|s| *s == TrackState::Lost), "{:?}", &slam.states[20..]);
    assert_eq!(slam.states[25], TrackState::NewMap, "{:?}", &slam.states[20..]);
    assert!(slam.states[21..].contains(&TrackState::NewMap), "{:?}", &slam.states[20..]);
    assert_eq!(slam.tracker.map_id(), 2);
    assert_eq!(*slam.states.last().unwrap(), TrackState::Tracked);
    // The new map continues from the dead-reckoned pose: every frame still has a pose.
    assert_eq!(slam.est.len(), 40);
}

/// The monocular pipeline on its own (no engine): two-view initialisation, tracking without
/// depth, triangulation and fusion in local mapping; scored after Sim(3) alignment.
fn mono_run(world: &World, frames: usize, path: impl Fn(usize) -> Isometry3<f64>) -> (Slam, Vec<Option<u64>>) {
    let mut slam = Slam::new();
    slam.tracker = Tracker::new(TrackerConfig::monocular(CAM.fx), CAM, 640, 480, 1);
    slam.mapper = LocalMapper::new(LocalMapConfig::monocular(CAM.fx), CAM);
    let mut rng = SplitMix64::new(9);
    let mut triangulated = Vec::new();
    for k in 0..frames {
        let f = world.frame(&path(k), &mut rng, false);
        let r = slam.tracker.track(k as f64 / 30.0, &f);
        if let Some(kf) = &r.keyframe {
            let update = slam.mapper.insert(kf);
            triangulated.push(Some(slam.mapper.last_triangulated() as u64));
            slam.tracker.apply_map_update(&update);
        }
        if let Some(p) = r.world_from_cam {
            slam.est.push((k as f64 / 30.0, p));
            slam.gt.push((k as f64 / 30.0, path(k)));
        }
        slam.states.push(r.state);
    }
    (slam, triangulated)
}

#[test]
fn monocular_initialises_from_two_views_and_maps_new_points() {
    let world = World::new(3000, 4, false);
    let (slam, triangulated) = mono_run(&world, 120, pose);
    // The first frames wait for parallax; then a map from two views, tracked to the end.
    let first = slam.states.iter().position(|s| *s == TrackState::NewMap).unwrap();
    assert!(first <= 30, "initialised at frame {first}");
    assert!(slam.states[..first].iter().all(|s| *s == TrackState::NotInitialised));
    assert!(slam.states[first + 1..].iter().all(|s| *s == TrackState::Tracked), "{:?}", slam.states);
    // The camera moves 1.2 m past what the first two views saw: local mapping had to
    // triangulate new points for tracking to go on.
    assert!(triangulated.iter().flatten().sum::<u64>() > 200, "{triangulated:?}");
    let e = evaluate(&slam.gt, &slam.est, 1e-3, Align::Sim3, 1).unwrap();
    assert!(e.ate.rmse < 0.01, "ATE (sim3) {} m", e.ate.rmse);
    // The initial map's scale: median depth 1 (the scene is 2-6 m deep: scale about 4).
    assert!(e.scale > 2.0 && e.scale < 8.0, "scale {}", e.scale);
}

#[test]
fn monocular_without_translation_never_claims_a_pose() {
    // A camera that only turns about its centre: no parallax, no initialisation, no pose.
    let world = World::new(3000, 5, false);
    let turn = |k: usize| {
        Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_euler_angles(0.0, 0.004 * k as f64, 0.0))
    };
    let (slam, _) = mono_run(&world, 60, turn);
    assert!(slam.est.is_empty());
    assert!(slam.states.iter().all(|s| *s == TrackState::NotInitialised));
    assert!(slam.tracker.init_failure().is_some_and(|w| w.contains("parallax")), "{:?}", slam.tracker.init_failure());
}
