//! Visual-inertial tracking (ORB-SLAM3's stereo-, RGB-D- and monocular-inertial modes; Campos
//! et al., "ORB-SLAM3", T-RO 2021).
//!
//! Each frame's IMU samples are pre-integrated from the last frame and from the newest key
//! frame ([`crate::imu::Preintegrated`]). Until the IMU is initialised the tracker is the
//! visual one, with ORB-SLAM3's inertial key-frame rule (one key frame every 0.25 s, so that
//! the initialisation sees motion between them). Initialisation is static when the device
//! starts at rest (gravity and the gyroscope bias from the first quarter second's means,
//! [`static_initialise`]), otherwise ORB-SLAM3's inertial-only MAP initialisation
//! ([`initialise`]) once the map's key frames number 10 and span 1 s (its `InitializeIMU` for
//! stereo and RGB-D; a single camera: 2 s, and no static initialisation, its map waiting for
//! motion anyway). A single camera's initialisation also finds the map's scale: the tracker's
//! map (key frames, points, frame poses, the whole map kept for relocalisation) is scaled
//! about the world's origin, and handed whole to local mapping under a new map id, from which
//! local mapping restarts (its own copy is in the old scale; the summary counts it as the same
//! map).
//!
//! Initialised, at each key frame at least 0.25 s after the previous window key frame, the
//! newest 10 such key frames (ORB-SLAM3's inertial window) are optimised visual-inertially
//! ([`optimize_window`]: poses, velocities and biases from the key frames' observations of the
//! map and the IMU between them, the points held as local mapping refined them). Each frame
//! vision tracks is then tracked against the newest window key frame's state as ORB-SLAM3 does
//! ([`optimize_inertial_pose`]: pose and velocity from the frame's observations and the IMU
//! since that key frame), unless its inertial residual fails the chi-square 99 % test
//! ([`INERTIAL_CHI2_9DOF_99`]: the IMU and the observations disagree), when vision's pose is
//! kept and the frame counted. With a single camera the window's scale is free as well, and the map
//! follows it at every window (the same re-handing to local mapping) while ORB-SLAM3 still
//! refines scale ([`SCALE_REFINEMENT_UNTIL`], [`SCALE_REFINEMENT_MAX_KEYFRAMES`]): ORB-SLAM3's
//! local inertial BA moves the scale through its free points, which this window holds.
//!
//! The IMU predicts each frame's pose for the projection search (in place of the
//! constant-velocity model). A frame vision cannot track is propagated by the IMU alone, with
//! its covariance ([`propagate_covariance`]), for up to 5 s (ORB-SLAM3's `timeRecentlyLost`):
//! its pose is the propagated one ([`TrackState::Inertial`]), and the next frame vision sees
//! is searched from it, in the same map. Key frames also come at least every 0.5 s
//! (ORB-SLAM3's temporal condition).
//!
//! Departures from ORB-SLAM3:
//!
//! - The window holds the points (local mapping owns them, and refines them with the key-frame
//!   poses by visual BA alone); its poses are the anchors of visual-inertial tracking, not
//!   written into the map. An earlier form tracked against key-frame velocities from the
//!   inertial-only refinement (poses held, so their noise became velocity error the
//!   pre-integration's tight covariance then trusted) and diverged: ATE 4.5 cm against 6.5 mm
//!   for stereo alone (synthetic hand-held scene, seed 0).
//! - Without the whole map (no vocabulary) the key frames' observations are not kept: the
//!   window's velocities and biases are then refined inertial-only with the key-frame poses
//!   held and gravity held (ORB-SLAM3's `InertialOptimization`, its bias priors centred on
//!   zero), and each frame keeps vision's pose.

use dynaflow_msg::{ImuCalibration, ImuSample};
use nalgebra::{UnitQuaternion, Vector3};

use super::*;
use crate::imu::init::{InitConfig, InitKeyFrame, REST_MIN_SAMPLES, initialise, static_initialise};
use crate::imu::propagate::{Matrix15, NavState, propagate_covariance};
use crate::imu::track::optimize_inertial_pose;
use crate::imu::window::{WindowKeyFrame, optimize_window};
use crate::imu::{Bias, Preintegrated};

/// ORB-SLAM3's `NeedNewKeyFrame` before the IMU is initialised: a key frame every 0.25 s.
pub const INIT_KEYFRAME_INTERVAL: f64 = 0.25;
/// ORB-SLAM3's temporal key-frame condition once initialised: at least every 0.5 s.
pub const INERTIAL_KEYFRAME_INTERVAL: f64 = 0.5;
/// ORB-SLAM3's `InitializeIMU`: key frames needed.
pub const INIT_MIN_KEYFRAMES: usize = 10;
/// ORB-SLAM3's `InitializeIMU`: seconds the key frames must span with depth (1 s; a single
/// camera's 2 s).
pub const INIT_MIN_SPAN: f64 = 1.0;
/// ORB-SLAM3's `timeRecentlyLost`: seconds of IMU-only propagation before the frame is lost.
pub const IMU_ONLY_LIMIT: f64 = 5.0;
/// The chi-square 99 % bound of a 9-degree-of-freedom residual: an inertial residual beyond
/// it after visual-inertial tracking means the IMU and the frame's observations disagree.
pub const INERTIAL_CHI2_9DOF_99: f64 = 21.666;
/// ORB-SLAM3's inertial window (`LocalInertialBA`'s 10 key frames).
pub const INERTIAL_WINDOW: usize = 10;
/// Seconds after the IMU's initialisation during which a single camera's map scale is refined
/// (ORB-SLAM3's `LocalMapping::Run`: `ScaleRefinement` while `mTinit < 100`).
pub const SCALE_REFINEMENT_UNTIL: f64 = 100.0;
/// Key frames in the map up to which a single camera's scale is refined (ORB-SLAM3's
/// `LocalMapping::Run`: `KeyFramesInMap() <= 200`).
pub const SCALE_REFINEMENT_MAX_KEYFRAMES: usize = 200;

/// How the IMU was initialised.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InitMethod {
    /// At rest: gravity and the gyroscope bias from the means.
    Static,
    /// ORB-SLAM3's inertial-only MAP initialisation over the first key frames.
    Map,
}

/// When and how the IMU was initialised.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct InertialInitInfo {
    /// The frame's time, seconds.
    pub stamp: f64,
    /// How.
    pub method: InitMethod,
    /// Key frames it used (a static initialisation: the map's so far).
    pub keyframes: usize,
    /// The gyroscope bias found, rad/s.
    pub gyro_bias: [f64; 3],
    /// The accelerometer bias found, m/s².
    pub accel_bias: [f64; 3],
}

/// The inertial estimate at the last frame, for plots.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InertialEstimate {
    /// The body's velocity in the world, m/s.
    pub velocity: Vector3<f64>,
    /// The biases.
    pub bias: Bias,
    /// Gravity in the world (the first key frame's camera frame), m/s².
    pub gravity_w: Vector3<f64>,
    /// The position's standard deviation from IMU-only propagation (0 when vision tracked
    /// the frame), metres: the square root of the position covariance's trace.
    pub position_sigma: f64,
}

/// The IMU's part of the tracker's state.
#[derive(Debug)]
pub(super) struct Inertial {
    calibration: ImuCalibration,
    /// Samples given for the coming frame.
    pending: Vec<ImuSample>,
    /// The newest sample at or before the last frame (the next span starts from it).
    carry: Option<ImuSample>,
    last_stamp: Option<f64>,
    /// Pre-integrated from the last frame to this one.
    from_frame: Option<Preintegrated>,
    /// From the newest key frame (its id) to this frame.
    from_kf: Option<(u64, Preintegrated)>,
    /// Samples from the start while a static initialisation may still be tried.
    rest: Option<Vec<ImuSample>>,
    /// The newest key frames of the map (id, stamp), and the pre-integration between each
    /// consecutive pair.
    window: Vec<(u64, f64)>,
    between: Vec<Preintegrated>,
    nav: Option<Nav>,
    init: Option<InertialInitInfo>,
    /// Why the last MAP initialisation failed.
    init_failure: Option<String>,
    /// The newest key frame's time (window member or not).
    last_keyframe: Option<f64>,
    /// A monocular initialisation's metric scale, applied as the key frame is handed on.
    pending_scale: Option<f64>,
    /// Times a monocular map was made metric (each restarts local mapping as a new map id).
    rescales: u32,
    /// Scale refinements done: the key frame's time and the factor.
    scale_refinements: Vec<(f64, f64)>,
    /// Visual-inertial windows optimised.
    windows: u64,
}

/// The initialised inertial state.
#[derive(Debug)]
struct Nav {
    world_from_gravity: UnitQuaternion<f64>,
    gravity_w: Vector3<f64>,
    bias: Bias,
    /// Velocities of the window's key frames, world, m/s.
    kf_velocity: BTreeMap<u64, Vector3<f64>>,
    /// Body poses of the window's key frames as the visual-inertial window estimated them
    /// (the anchors of visual-inertial tracking; none until the first window after
    /// initialisation).
    kf_pose: BTreeMap<u64, Isometry3<f64>>,
    /// The last frame's state, and its covariance since vision last tracked.
    frame: NavState,
    covariance: Matrix15,
    /// The last frame vision tracked.
    last_visual: f64,
    /// Frames whose visual-inertial fit failed the consistency test (vision's pose kept).
    inconsistent: u64,
}

impl Inertial {
    pub(super) fn new(calibration: ImuCalibration) -> Self {
        Self {
            calibration,
            pending: Vec::new(),
            carry: None,
            last_stamp: None,
            from_frame: None,
            from_kf: None,
            rest: Some(Vec::new()),
            window: Vec::new(),
            between: Vec::new(),
            nav: None,
            init: None,
            init_failure: None,
            last_keyframe: None,
            pending_scale: None,
            rescales: 0,
            scale_refinements: Vec::new(),
            windows: 0,
        }
    }

    fn bias(&self) -> Bias {
        self.nav.as_ref().map_or_else(Bias::default, |n| n.bias)
    }

    /// Pre-integrate the pending samples up to the frame at `stamp`. Samples at or before
    /// the last one used are ignored (the sources refuse such stamps); after the newest
    /// sample the rates are held up to the frame (at most one sample period).
    fn advance(&mut self, stamp: f64) {
        let after = self.carry.map_or(f64::NEG_INFINITY, |c| c.stamp);
        let mut fresh: Vec<ImuSample> = Vec::with_capacity(self.pending.len());
        let mut later = Vec::new();
        for s in self.pending.drain(..).filter(|s| s.stamp > after) {
            if s.stamp <= stamp { fresh.push(s) } else { later.push(s) }
        }
        self.pending = later;
        if let Some(rest) = &mut self.rest {
            rest.extend_from_slice(&fresh);
        }
        let mut span: Vec<ImuSample> = self.carry.into_iter().chain(fresh.iter().copied()).collect();
        if let Some(last) = span.last().copied()
            && last.stamp < stamp
        {
            span.push(ImuSample { stamp, ..last });
        }
        if let Some(from) = self.last_stamp {
            let mut p = Preintegrated::new(self.bias(), &self.calibration);
            p.integrate_span(&span, from, stamp);
            if let Some((_, k)) = &mut self.from_kf {
                k.integrate_span(&span, from, stamp);
            }
            self.from_frame = Some(p);
        }
        if let Some(last) = fresh.last() {
            self.carry = Some(*last);
        }
        self.last_stamp = Some(stamp);
    }

    /// The newest window key frame's time.
    fn last_keyframe_stamp(&self) -> Option<f64> {
        self.window.last().map(|w| w.1)
    }

    /// The IMU is initialised: gravity's direction, the state of the frame it happened at
    /// (its biases the estimate), the window's velocities; the pre-integrations follow the
    /// biases.
    fn begin(
        &mut self,
        world_from_gravity: UnitQuaternion<f64>,
        frame: NavState,
        kf_velocity: BTreeMap<u64, Vector3<f64>>,
        stamp: f64,
        method: InitMethod,
        keyframes: usize,
    ) {
        self.nav = Some(Nav {
            world_from_gravity,
            gravity_w: world_from_gravity * Vector3::new(0.0, 0.0, -self.calibration.gravity),
            bias: frame.bias,
            kf_velocity,
            kf_pose: BTreeMap::new(),
            frame,
            covariance: Matrix15::zeros(),
            last_visual: stamp,
            inconsistent: 0,
        });
        self.rest = None;
        self.set_bias(frame.bias);
        self.init = Some(InertialInitInfo {
            stamp,
            method,
            keyframes,
            gyro_bias: frame.bias.gyro.into(),
            accel_bias: frame.bias.accel.into(),
        });
    }

    /// Set a new bias estimate everywhere it is used.
    fn set_bias(&mut self, bias: Bias) {
        for p in &mut self.between {
            p.set_bias(bias);
        }
        if let Some((_, p)) = &mut self.from_kf {
            p.set_bias(bias);
        }
        if let Some(nav) = &mut self.nav {
            nav.bias = bias;
            nav.frame.bias = bias;
        }
    }
}

impl Tracker {
    /// Track with this IMU (mounted as `calibration.body_from_cam` says): give each frame's
    /// samples with [`Tracker::add_imu`] before [`Tracker::track`]. See [`inertial`](self).
    pub fn with_imu(mut self, calibration: ImuCalibration) -> Self {
        self.imu = Some(Box::new(Inertial::new(calibration)));
        self
    }

    /// The IMU samples after the previous frame up to the next one (sorted by time).
    pub fn add_imu(&mut self, samples: &[ImuSample]) {
        if let Some(imu) = &mut self.imu {
            imu.pending.extend_from_slice(samples);
        }
    }

    /// Whether the tracker has an IMU.
    pub fn inertial(&self) -> bool {
        self.imu.is_some()
    }

    /// When and how the IMU was initialised (`None`: not yet, or no IMU).
    pub fn inertial_init(&self) -> Option<InertialInitInfo> {
        self.imu.as_ref().and_then(|i| i.init)
    }

    /// Visual-inertial windows optimised ([`crate::imu::window`]).
    pub fn inertial_windows(&self) -> u64 {
        self.imu.as_ref().map_or(0, |i| i.windows)
    }

    /// Frames whose visual-inertial fit failed the consistency test
    /// ([`INERTIAL_CHI2_9DOF_99`]) and kept vision's pose.
    pub fn inertial_inconsistent(&self) -> u64 {
        self.imu.as_ref().and_then(|i| i.nav.as_ref()).map_or(0, |n| n.inconsistent)
    }

    /// A single camera's scale refinements: each key frame's time and the factor applied.
    pub fn scale_refinements(&self) -> &[(f64, f64)] {
        self.imu.as_ref().map_or(&[], |i| &i.scale_refinements)
    }

    /// Why the last inertial MAP initialisation failed.
    pub fn inertial_init_failure(&self) -> Option<&str> {
        self.imu.as_ref().and_then(|i| i.init_failure.as_deref())
    }

    /// The inertial estimate at the last frame (`None` before the IMU is initialised).
    pub fn inertial_estimate(&self) -> Option<InertialEstimate> {
        let nav = self.imu.as_ref()?.nav.as_ref()?;
        let trace: f64 = (6..9).map(|k| nav.covariance[(k, k)]).sum();
        Some(InertialEstimate {
            velocity: nav.frame.velocity,
            bias: nav.bias,
            gravity_w: nav.gravity_w,
            position_sigma: trace.max(0.0).sqrt(),
        })
    }

    /// Before a frame is tracked: pre-integrate its samples.
    pub(super) fn imu_advance(&mut self, stamp: f64) {
        if let Some(imu) = &mut self.imu {
            imu.advance(stamp);
        }
    }

    /// The IMU's prediction of this frame's camera pose (initialised only).
    pub(super) fn imu_prediction(&self) -> Option<Isometry3<f64>> {
        let imu = self.imu.as_ref()?;
        let (nav, pre) = (imu.nav.as_ref()?, imu.from_frame.as_ref()?);
        let state = nav.frame.predict(pre, &nav.gravity_w);
        Some(renormalised(&(state.world_from_body * imu.calibration.body_from_cam)))
    }

    /// ORB-SLAM3's key-frame rule with an IMU: `None` without one (ORB-SLAM2's rules decide);
    /// before initialisation one every [`INIT_KEYFRAME_INTERVAL`]; after, ORB-SLAM2's rules
    /// (`visual`) or [`INERTIAL_KEYFRAME_INTERVAL`] since the last.
    pub(super) fn inertial_keyframe_rule(&self, stamp: f64, visual: bool) -> Option<bool> {
        let imu = self.imu.as_ref()?;
        let since = imu.last_keyframe.map_or(f64::INFINITY, |t| stamp - t);
        Some(if imu.nav.is_none() {
            since >= INIT_KEYFRAME_INTERVAL
        } else {
            visual || since >= INERTIAL_KEYFRAME_INTERVAL
        })
    }

    /// After vision tracked a frame (initialised only). Where the newest window key frame has
    /// the visual-inertial window's state, ORB-SLAM3's tracking against it: the frame's pose
    /// and velocity from its observations and the IMU since that key frame
    /// ([`optimize_inertial_pose`]), which replaces vision's pose in `fit`. Otherwise the
    /// frame keeps its visual pose, with the velocity the IMU carries from the key frame.
    pub(super) fn inertial_follow(&mut self, fit: &mut Fit, features: &[Feature], stamp: f64) {
        let obs = self.fit_observations(features, &fit.matched);
        let Some(imu) = self.imu.as_mut() else { return };
        let body_from_cam = imu.calibration.body_from_cam;
        let (Some(nav), Some((kf, pre))) = (imu.nav.as_mut(), imu.from_kf.as_ref()) else { return };
        let world_from_body = fit.world_from_cam * body_from_cam.inverse();
        let anchor =
            |pose: &Isometry3<f64>, v: &Vector3<f64>| NavState { world_from_body: *pose, velocity: *v, bias: nav.bias };
        match (nav.kf_pose.get(kf), self.keyframe_poses.get(kf), nav.kf_velocity.get(kf)) {
            (Some(pose), _, Some(v)) => {
                let anchor = anchor(pose, v);
                let predicted = anchor.predict(pre, &nav.gravity_w);
                let initial = NavState { world_from_body, ..predicted };
                let r = optimize_inertial_pose(
                    &obs,
                    &self.cam,
                    self.config.bf,
                    &body_from_cam,
                    &anchor,
                    pre,
                    &nav.gravity_w,
                    &initial,
                    None,
                );
                if r.inertial_chi2 <= INERTIAL_CHI2_9DOF_99 {
                    nav.frame = r.state;
                    fit.world_from_cam = renormalised(&(r.state.world_from_body * body_from_cam));
                } else {
                    // The IMU since the anchor and the frame's observations disagree: vision's pose.
                    nav.inconsistent += 1;
                    nav.frame = NavState { world_from_body, velocity: r.state.velocity, bias: nav.bias };
                }
            }
            (None, Some(kf_pose), Some(v)) => {
                let velocity = anchor(&(kf_pose * body_from_cam.inverse()), v).predict(pre, &nav.gravity_w).velocity;
                nav.frame = NavState { world_from_body, velocity, bias: nav.bias };
            }
            _ => nav.frame = NavState { world_from_body, velocity: nav.frame.velocity, bias: nav.bias },
        }
        nav.covariance = Matrix15::zeros();
        nav.last_visual = stamp;
    }

    /// The observations of a tracked frame's matched map points, as motion-only BA used them.
    fn fit_observations(&self, features: &[Feature], matched: &[Option<u64>]) -> Vec<PoseObservation> {
        matched
            .iter()
            .zip(features)
            .filter_map(|(m, f)| {
                let p = self.points.get(&(*m)?)?;
                Some(PoseObservation {
                    point: p.position,
                    uv: f.uv,
                    sigma: sigma(self.config.scale_factor, f.octave),
                    depth: f.depth.filter(|&d| d > 0.0 && d <= self.config.max_depth),
                })
            })
            .collect()
    }

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
                    Some(PoseObservation {
                        point: p.position,
                        uv: k.uv,
                        sigma: sigma(self.config.scale_factor, k.octave),
                        depth: k.depth.filter(|&d| d > 0.0 && d <= self.config.max_depth),
                    })
                })
                .collect(),
        )
    }

    /// A frame vision could not track: the IMU's propagation, while it may still be trusted
    /// (initialised, and within [`IMU_ONLY_LIMIT`] of the last frame vision tracked).
    pub(super) fn imu_only(&mut self, stamp: f64, features: usize) -> Option<TrackingResult> {
        let imu = self.imu.as_mut()?;
        let calibration = imu.calibration;
        let (nav, pre) = (imu.nav.as_mut()?, imu.from_frame.as_ref()?);
        if stamp - nav.last_visual > IMU_ONLY_LIMIT {
            return None;
        }
        nav.covariance = propagate_covariance(&nav.frame, &nav.covariance, pre, &calibration);
        nav.frame = nav.frame.predict(pre, &nav.gravity_w);
        let pose = renormalised(&(nav.frame.world_from_body * calibration.body_from_cam));
        self.last = Some(pose);
        self.velocity = Isometry3::identity();
        Some(self.untracked(Some(pose), TrackState::Inertial, features))
    }

    /// A key frame was made: it joins the inertial window; the IMU is initialised, or the
    /// window's velocities and biases refined.
    pub(super) fn imu_keyframe(&mut self, id: u64, stamp: f64) {
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
        let min_span = if self.config.sensor == Sensor::Monocular { 2.0 * INIT_MIN_SPAN } else { INIT_MIN_SPAN };
        let kfs: Vec<InitKeyFrame> = imu
            .window
            .iter()
            .filter_map(|(k, t)| self.keyframe_poses.get(k).map(|p| InitKeyFrame { stamp: *t, world_from_cam: *p }))
            .collect();
        if kfs.len() != imu.window.len() {
            return;
        }
        let span = stamp - imu.window[0].1;
        // Once initialised: the visual-inertial window where the key frames' observations are
        // known (the whole map kept), else the inertial-only refinement below.
        let (initialised, ids): (bool, Vec<u64>) = (imu.nav.is_some(), imu.window.iter().map(|w| w.0).collect());
        let observations: Option<Vec<Vec<PoseObservation>>> = match initialised {
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
            None if kfs.len() >= INIT_MIN_KEYFRAMES && span >= min_span => {
                let mono = self.config.sensor == Sensor::Monocular;
                let config = if mono { InitConfig::monocular() } else { InitConfig::with_depth() };
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
                        imu.begin(r.world_from_gravity, frame, velocities, stamp, InitMethod::Map, kfs.len());
                    }
                    Err(e) => imu.init_failure = Some(e.to_string()),
                }
            }
            None => {}
        }
    }

    /// Loop closing moved key frames by `delta` (each `new · old⁻¹`, cameras in the world;
    /// `newest` the reference key frame's): the window's anchor states and velocities move
    /// with their key frames, the frame's state with the newest (ORB-SLAM3 corrects velocities
    /// with the key frames' rotations the same way).
    pub(super) fn imu_correct(&mut self, delta: &BTreeMap<u64, Isometry3<f64>>, newest: Option<Isometry3<f64>>) {
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
    pub(super) fn imu_rescale(&mut self) -> Option<SparseMap> {
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

    /// After a frame vision tracked: a static initialisation, once, when the samples from
    /// the start are enough ([`REST_MIN_SAMPLES`]) and the map has begun; refused (the device
    /// moves) it is not tried again, and the MAP initialisation follows.
    pub(super) fn imu_try_static(&mut self, stamp: f64) {
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
        let world_from_body = last * imu.calibration.body_from_cam.inverse();
        let world_from_gravity = world_from_body.rotation * s.gravity_from_body.inverse();
        let bias = Bias { gyro: s.gyro_bias, accel: Vector3::zeros() };
        let frame = NavState { world_from_body, velocity: Vector3::zeros(), bias };
        let velocities = imu.window.iter().map(|w| (w.0, Vector3::zeros())).collect();
        let keyframes = imu.window.len();
        imu.begin(world_from_gravity, frame, velocities, stamp, InitMethod::Static, keyframes);
    }
}
