//! The inertial initialisation's start: a static initialisation at rest (its samples, and
//! vision's word that the device did rest), and a single camera's initialisation reference frame
//! (the IMU pre-integrated from it, the rest's gravity carried to it): see the parent module.

use super::*;

impl Tracker {
    /// After each frame, a single camera before its map: the initialisation's reference frame
    /// (ORB-SLAM3 pre-integrates from it), followed as the tracker replaces it.
    pub(in crate::tracker) fn imu_reference(&mut self, stamp: f64) {
        let reference = self.init_ref.as_ref().map(|r| r.0);
        let Some(imu) = self.imu.as_mut().filter(|i| i.monocular) else { return };
        match reference {
            Some(t) if imu.reference.as_ref().is_some_and(|r| r.stamp == t) => {}
            Some(t) if t == stamp => {
                imu.reference = Some(Reference {
                    stamp,
                    gravity_from_body: imu.attitude.map(|a| a.0),
                    from: Preintegrated::new(imu.bias(), &imu.calibration),
                });
            }
            _ => imu.reference = None,
        }
    }

    /// A single camera's map started from the reference frame (`k0` at `t0`) and this one
    /// (`k1`): both join the inertial window, with the IMU pre-integrated between them, and
    /// the map's gravity is known where the reference frame's attitude was.
    pub(in crate::tracker) fn imu_monocular_map(&mut self, (k0, t0): (u64, f64), (k1, t1): (u64, f64)) {
        let Some(imu) = self.imu.as_mut() else { return };
        let Some(reference) = imu.reference.take().filter(|r| r.stamp == t0) else { return };
        let body_from_cam = imu.calibration.body_from_cam;
        // Vision must agree that the rest was one (REST_MAX_DISPARITY_PX): the gyroscope, less
        // the rest's bias, turns the body from k0 to k1 as the two views do.
        let world_from_body = |k: &u64| self.keyframe_poses.get(k).map(|p| p * body_from_cam.inverse());
        imu.map_gravity = match (reference.gravity_from_body, imu.attitude, world_from_body(&k0), world_from_body(&k1))
        {
            (Some(gravity_from_b0), Some((gravity_from_b1, _)), Some(b0), Some(b1)) => {
                let gyro = gravity_from_b0.inverse() * gravity_from_b1;
                let vision = b0.rotation.inverse() * b1.rotation;
                let disagreement = (vision.inverse() * gyro).angle() * self.cam.fx;
                (disagreement <= REST_MAX_DISPARITY_PX).then(|| b0.rotation * gravity_from_b0.inverse())
            }
            _ => None,
        };
        self.imu_keyframe(k0, t0);
        if let Some(imu) = self.imu.as_mut() {
            imu.from_kf = Some((k0, reference.from));
        }
        self.imu_keyframe(k1, t1);
    }

    /// After a frame vision tracked: a static initialisation, once, when the samples from
    /// the start are enough ([`REST_MIN_SAMPLES`]) and the map has begun; refused (the device
    /// moves) it is not tried again, and the MAP initialisation follows.
    pub(in crate::tracker) fn imu_try_static(&mut self, stamp: f64) {
        // (A single camera's map has no scale for the rest to fix: its initialisation waits for
        // motion.)
        let (Some(last), true, false) = (self.last, self.initialised, self.config.sensor == Sensor::Monocular) else {
            return;
        };
        let Some(imu) = self.imu.as_mut() else { return };
        if imu.nav.is_some() || imu.rest.as_ref().is_none_or(|r| r.len() < REST_MIN_SAMPLES) || imu.window.is_empty() {
            return;
        }
        let samples = imu.rest.take().unwrap_or_default();
        let Ok(s) = static_initialise(&samples, &imu.calibration) else { return };
        // Vision must agree: the camera moved less than REST_MAX_DISPARITY_PX since the map's
        // first key frame (rotation at the focal length, translation at the median depth of
        // the points in view).
        if let Some(first) = self.keyframe_poses.get(&self.first_keyframe) {
            let moved = first.inverse() * last;
            let cam_from_world = last.inverse();
            let mut depths: Vec<f64> =
                self.points.values().map(|p| (cam_from_world * p.position).z).filter(|z| *z > 0.0).collect();
            depths.sort_by(f64::total_cmp);
            let depth = depths.get(depths.len() / 2).copied().unwrap_or(f64::INFINITY);
            let disparity = self.cam.fx * (moved.rotation.angle() + moved.translation.vector.norm() / depth);
            if disparity.is_nan() || disparity > REST_MAX_DISPARITY_PX {
                return;
            }
        }
        let Some(imu) = self.imu.as_mut() else { return };
        let world_from_body = last * imu.calibration.body_from_cam.inverse();
        let world_from_gravity = world_from_body.rotation * s.gravity_from_body.inverse();
        let bias = Bias { gyro: s.gyro_bias, accel: Vector3::zeros() };
        let frame = NavState { world_from_body, velocity: Vector3::zeros(), bias };
        let velocities = imu.window.iter().map(|w| (w.0, Vector3::zeros())).collect();
        let keyframes = imu.window.len();
        imu.begin(world_from_gravity, frame, velocities, stamp, InitMethod::Static, keyframes);
    }
}
