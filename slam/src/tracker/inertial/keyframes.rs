//! The inertial window at each key frame (the IMU's initialisation, the visual-inertial
//! window, a single camera's scale), and the inertial state through loop corrections and
//! rescaling: see the parent module.

use super::*;
use crate::imu::window::{WindowKeyFrame, optimize_window};

impl Tracker {
    /// A window key frame's observations of the map's points (the whole map's record of it,
    /// which local mapping's refinements keep current); `None` without the whole map.
    fn keyframe_observations(&self, id: u64) -> Option<Vec<PoseObservation>> {
        let places = self.places.as_ref()?;
        let kf = places.kfs.get(&id)?;
        Some(
            kf.keypoints
                .iter()
                .filter_map(|k| {
                    let p = places.points.get(&k.point?)?;
                    Some(self.observation(p.position, k.uv, k.octave, k.depth))
                })
                .collect(),
        )
    }

    /// A key frame was made: it joins the inertial window; the IMU is initialised, or the
    /// window's velocities and biases refined.
    pub(in crate::tracker) fn imu_keyframe(&mut self, id: u64, stamp: f64) {
        let new_map = id == self.first_keyframe;
        let Some(imu) = self.imu.as_mut() else { return };
        let bias = imu.bias();
        let calibration = imu.calibration;
        imu.last_keyframe = Some(stamp);
        // Window key frames are at least INIT_KEYFRAME_INTERVAL apart: with poses held,
        // closer ones turn the poses' noise into velocity errors (tested: 33 ms apart, the
        // velocities from 1 mm noise are centimetres per second off).
        if !new_map && imu.last_keyframe_stamp().is_some_and(|t| stamp - t < INIT_KEYFRAME_INTERVAL) {
            return;
        }
        match imu.from_kf.take() {
            Some((prev, p)) if !new_map && imu.window.last().is_some_and(|w| w.0 == prev) => imu.between.push(p),
            _ => {
                imu.window.clear();
                imu.between.clear();
            }
        }
        imu.window.push((id, stamp));
        if imu.window.len() > INERTIAL_WINDOW {
            imu.window.remove(0);
            imu.between.remove(0);
        }
        imu.from_kf = Some((id, Preintegrated::new(bias, &calibration)));
        let kfs: Vec<InitKeyFrame> = imu
            .window
            .iter()
            .filter_map(|(k, t)| self.keyframe_poses.get(k).map(|p| InitKeyFrame { stamp: *t, world_from_cam: *p }))
            .collect();
        if kfs.len() != imu.window.len() {
            return;
        }
        let span = stamp - imu.window[0].1;
        // Once initialised (and three key frames in the window): the visual-inertial window
        // where the key frames' observations are known (the whole map kept), else the
        // inertial-only refinement below.
        let ids: Vec<u64> = imu.window.iter().map(|w| w.0).collect();
        let observations: Option<Vec<Vec<PoseObservation>>> = match imu.nav.is_some() && ids.len() >= 3 {
            true => ids.iter().map(|k| self.keyframe_observations(*k)).collect(),
            false => None,
        };
        let Some(imu) = self.imu.as_mut() else { return };
        match imu.nav.as_mut() {
            Some(nav) => {
                nav.kf_velocity.insert(id, nav.frame.velocity);
                if kfs.len() < 3 {
                    return;
                }
                // A single camera's map follows the scale every window finds (ORB-SLAM3's local
                // inertial BA moves it through its free points), while ORB-SLAM3 still refines
                // scale: within SCALE_REFINEMENT_UNTIL of the initialisation and up to
                // SCALE_REFINEMENT_MAX_KEYFRAMES key frames (re-handing the map to local
                // mapping costs in proportion to its size).
                let since_init = imu.init.map_or(0.0, |i| stamp - i.stamp);
                let refine_scale = self.config.sensor == Sensor::Monocular
                    && since_init < SCALE_REFINEMENT_UNTIL
                    && self.keyframe_poses.len() <= SCALE_REFINEMENT_MAX_KEYFRAMES;
                if let Some(observations) = observations {
                    let body_from_cam_inv = calibration.body_from_cam.inverse();
                    let window: Vec<WindowKeyFrame> = imu
                        .window
                        .iter()
                        .zip(&kfs)
                        .zip(observations)
                        .map(|(((k, _), kf), observations)| WindowKeyFrame {
                            world_from_body: kf.world_from_cam * body_from_cam_inv,
                            velocity: nav.kf_velocity.get(k).copied().unwrap_or(nav.frame.velocity),
                            observations,
                        })
                        .collect();
                    let fit = optimize_window(
                        &window,
                        &imu.between,
                        &self.cam,
                        self.config.bf,
                        &calibration,
                        &nav.gravity_w,
                        nav.bias,
                        refine_scale,
                    );
                    imu.windows += 1;
                    let ids = imu.window.iter().map(|w| w.0);
                    nav.kf_velocity = ids.clone().zip(fit.states.iter().map(|s| s.velocity)).collect();
                    nav.kf_pose = ids.zip(fit.states.iter().map(|s| s.world_from_body)).collect();
                    nav.frame = fit.states[fit.states.len() - 1];
                    if refine_scale {
                        // The map follows the window's scale as the key frame is handed on
                        // (`imu_rescale`, which scales the frame's position with the map's).
                        imu.scale_refinements.push((stamp, fit.scale));
                        imu.pending_scale = Some(fit.scale);
                        nav.frame.world_from_body = window[window.len() - 1].world_from_body;
                    }
                    imu.set_bias(fit.bias);
                    return;
                }
                // The bias priors centred on zero, as ORB-SLAM3's `InertialOptimization` sets
                // them (centred on the last estimate they let the biases walk from one window
                // to the next: 4.7 m/s² of accelerometer bias where walking people were taken
                // for static; centred on zero, 2.9 m/s² there: no gate yet on a misled window).
                let config = InitConfig { gravity: Some(nav.world_from_gravity), ..InitConfig::with_depth() };
                let Ok(r) = initialise(&kfs, &imu.between, &calibration.body_from_cam, calibration.gravity, &config)
                else {
                    return;
                };
                nav.kf_velocity = imu.window.iter().map(|w| w.0).zip(r.velocities.iter().copied()).collect();
                nav.frame.velocity = r.velocities[r.velocities.len() - 1];
                imu.set_bias(r.bias);
            }
            None => {
                // ORB-SLAM3's rule (10 key frames over 1 s; a single camera's over 2 s), but a
                // single camera whose map's gravity a rest gave: gravity held, and the span
                // with depth ([`INIT_MIN_KEYFRAMES_AT_REST`]).
                let mono = self.config.sensor == Sensor::Monocular;
                let (min_keyframes, min_span, config, method) = match (mono, imu.map_gravity) {
                    (true, Some(g)) => (
                        INIT_MIN_KEYFRAMES_AT_REST,
                        INIT_MIN_SPAN,
                        InitConfig { gravity: Some(g), ..InitConfig::monocular() },
                        InitMethod::MapGravityAtRest,
                    ),
                    (true, None) => (INIT_MIN_KEYFRAMES, 2.0 * INIT_MIN_SPAN, InitConfig::monocular(), InitMethod::Map),
                    (false, _) => (INIT_MIN_KEYFRAMES, INIT_MIN_SPAN, InitConfig::with_depth(), InitMethod::Map),
                };
                if kfs.len() < min_keyframes || span < min_span {
                    return;
                }
                match initialise(&kfs, &imu.between, &calibration.body_from_cam, calibration.gravity, &config) {
                    Ok(r) => {
                        if mono {
                            imu.pending_scale = Some(r.scale);
                        }
                        let frame = NavState {
                            world_from_body: kfs[kfs.len() - 1].world_from_cam * calibration.body_from_cam.inverse(),
                            velocity: r.velocities[r.velocities.len() - 1],
                            bias: r.bias,
                        };
                        let velocities = imu.window.iter().map(|w| w.0).zip(r.velocities.iter().copied()).collect();
                        imu.begin(r.world_from_gravity, frame, velocities, stamp, method, kfs.len());
                    }
                    Err(e) => imu.init_failure = Some(e.to_string()),
                }
            }
        }
    }

    /// Loop closing moved key frames by `delta` (each `new · old⁻¹`, cameras in the world;
    /// `newest` the reference key frame's): the window's anchor states and velocities move
    /// with their key frames, the frame's state with the newest (ORB-SLAM3 corrects velocities
    /// with the key frames' rotations the same way).
    pub(in crate::tracker) fn imu_correct(
        &mut self,
        delta: &BTreeMap<u64, Isometry3<f64>>,
        newest: Option<Isometry3<f64>>,
    ) {
        let Some(nav) = self.imu.as_mut().and_then(|i| i.nav.as_mut()) else { return };
        for (id, pose) in &mut nav.kf_pose {
            if let Some(d) = delta.get(id) {
                *pose = renormalised(&(d * *pose));
            }
        }
        for (id, v) in &mut nav.kf_velocity {
            if let Some(d) = delta.get(id) {
                *v = d.rotation * *v;
            }
        }
        if let Some(d) = newest {
            nav.frame.world_from_body = renormalised(&(d * nav.frame.world_from_body));
            nav.frame.velocity = d.rotation * nav.frame.velocity;
        }
    }

    /// Maps started (a monocular map made metric keeps counting as one).
    pub fn maps(&self) -> u32 {
        self.map_id - self.imu.as_ref().map_or(0, |i| i.rescales)
    }

    /// After a monocular inertial initialisation: the map made metric (every key-frame pose,
    /// point and frame pose scaled about the world's origin), and the whole map handed to
    /// local mapping under a new map id (it restarts from it: its own copy is in the old
    /// scale). `None` when no scale is pending.
    pub(in crate::tracker) fn imu_rescale(&mut self) -> Option<SparseMap> {
        let s = self.imu.as_mut()?.pending_scale.take()?;
        let scaled = |p: &Isometry3<f64>| Isometry3::from_parts((p.translation.vector * s).into(), p.rotation);
        for p in self.keyframe_poses.values_mut() {
            *p = scaled(p);
        }
        for p in self.points.values_mut() {
            p.position = Point3::from(p.position.coords * s);
        }
        self.last = self.last.map(|p| scaled(&p));
        self.velocity = scaled(&self.velocity);
        if let Some(imu) = self.imu.as_mut() {
            imu.rescales += 1;
            let body_from_cam = imu.calibration.body_from_cam;
            if let Some(nav) = imu.nav.as_mut() {
                // The camera's position scales; the lever arm to the body is metric.
                let world_from_cam = scaled(&(nav.frame.world_from_body * body_from_cam));
                nav.frame.world_from_body = world_from_cam * body_from_cam.inverse();
            }
        }
        for a in &mut self.anchors {
            a.2 = scaled(&a.2);
        }
        self.map_id += 1;
        let mut batch = SparseMap { map_id: self.map_id, ..SparseMap::default() };
        let Some(places) = &mut self.places else {
            // Without the whole map (no vocabulary): the tracker's own points and poses.
            batch.keyframes =
                self.keyframe_poses.iter().map(|(&id, p)| MapKeyFrame { id, stamp: 0.0, world_from_cam: *p }).collect();
            return Some(batch);
        };
        places.map_id = self.map_id;
        for kf in places.kfs.values_mut() {
            kf.info.world_from_cam = scaled(&kf.info.world_from_cam);
        }
        for p in places.points.values_mut() {
            p.position = Point3::from(p.position.coords * s);
        }
        for (id, kf) in &places.kfs {
            batch.keyframes.push(kf.info);
            for k in &kf.keypoints {
                match k.point.filter(|p| places.points.contains_key(p)) {
                    Some(point) => batch.observations.push(MapObservation {
                        keyframe: *id,
                        point,
                        uv: k.uv,
                        depth: k.depth,
                        octave: k.octave,
                    }),
                    None => batch.features.push(MapFeature {
                        keyframe: *id,
                        uv: k.uv,
                        octave: k.octave,
                        descriptor: k.descriptor,
                    }),
                }
            }
        }
        batch.points = places.points.values().copied().collect();
        Some(batch)
    }
}
