//! Visual-inertial tracking (ORB-SLAM3's stereo-, RGB-D- and monocular-inertial modes; Campos
//! et al., "ORB-SLAM3", T-RO 2021).
//!
//! Each frame's IMU samples are pre-integrated from the last frame and from the newest key
//! frame ([`crate::imu::Preintegrated`]). Until the IMU is initialised the tracker is the
//! visual one, with ORB-SLAM3's inertial key-frame rule (one key frame every 0.25 s, so that
//! the initialisation sees motion between them). Initialisation is static when the device
//! starts at rest (gravity and the gyroscope bias from the first quarter second's means,
//! [`static_initialise`], when vision agrees that the camera stood still:
//! [`REST_MAX_DISPARITY_PX`]; a turn at a constant rate looks like a rest to the IMU alone),
//! otherwise ORB-SLAM3's inertial-only MAP initialisation
//! ([`initialise`]) once the map's key frames number 10 and span 1 s (its `InitializeIMU` for
//! stereo and RGB-D; a single camera: 2 s). A single camera's map waits for motion, so a rest at
//! the start gives it gravity instead: the rest's attitude to gravity is carried by the
//! gyroscope to the map's first key frame (the initialisation's reference frame), and the MAP
//! initialisation runs with gravity held once 5 key frames are in (when the gyroscope, less the
//! rest's bias, turns the body between the map's first two key frames as vision does)
//! ([`INIT_MIN_KEYFRAMES_AT_REST`]). The IMU is pre-integrated from the reference frame, so the
//! map's first two key frames join the inertial window, as ORB-SLAM3's do. A single camera's
//! initialisation also finds the map's scale: the tracker's
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
use crate::imu::{Bias, Preintegrated};

mod keyframes;
mod rest;

/// ORB-SLAM3's `NeedNewKeyFrame` before the IMU is initialised: a key frame every 0.25 s.
pub const INIT_KEYFRAME_INTERVAL: f64 = 0.25;
/// ORB-SLAM3's second full inertial BA, seconds after the initialisation (`LocalMapping::Run`:
/// `mTinit > 15`), after which tracking searches the local map more tightly.
const INERTIAL_BA2_AFTER_S: f64 = 15.0;
/// ORB-SLAM3's temporal key-frame condition once initialised: at least every 0.5 s.
pub const INERTIAL_KEYFRAME_INTERVAL: f64 = 0.5;
/// ORB-SLAM3's `InitializeIMU`: key frames needed.
pub const INIT_MIN_KEYFRAMES: usize = 10;
/// ORB-SLAM3's `InitializeIMU`: seconds the key frames must span with depth (1 s; a single
/// camera's 2 s).
pub const INIT_MIN_SPAN: f64 = 1.0;
/// Key frames a single camera's initialisation needs when its attitude to gravity is known
/// from a rest at the start: gravity is then held, and scale, velocities and biases remain,
/// which ORB-SLAM3 finds with depth from 1 s of key frames; 1 s at its 0.25 s spacing
/// ([`INIT_KEYFRAME_INTERVAL`]) is 5 key frames.
pub const INIT_MIN_KEYFRAMES_AT_REST: usize = 5;
/// ORB-SLAM3's `timeRecentlyLost`: seconds of IMU-only propagation before the frame is lost.
pub const IMU_ONLY_LIMIT: f64 = 5.0;
/// The chi-square 99 % bound of a 9-degree-of-freedom residual: an inertial residual beyond
/// it after visual-inertial tracking means the IMU and the frame's observations disagree.
pub const INERTIAL_CHI2_9DOF_99: f64 = 21.666;
/// The image motion, in pixels, below which vision agrees that the device rested (OpenVINS's
/// stationary test, `init_max_disparity`, default 10 px). The IMU alone cannot tell a rest from
/// a turn at a constant rate (its gyroscope's mean is then the rate, not a bias): a static
/// initialisation needs vision's word too.
pub const REST_MAX_DISPARITY_PX: f64 = 10.0;
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
    /// A single camera: the MAP initialisation with gravity held where a rest at the start gave
    /// it (carried to the map's first key frame by the gyroscope).
    MapGravityAtRest,
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
    /// A single camera (its initialisation differs).
    monocular: bool,
    /// A single camera before initialisation, after a rest at the start: the body's attitude
    /// to gravity (`R_gb`) at the last frame, carried by the gyroscope with the rest's bias.
    attitude: Option<(UnitQuaternion<f64>, Vector3<f64>)>,
    /// A single camera's initialisation reference frame (before its map starts).
    reference: Option<Reference>,
    /// `R_wg` of a single camera's map whose first key frame's attitude was known.
    map_gravity: Option<UnitQuaternion<f64>>,
}

/// A single camera's initialisation reference frame: the IMU is pre-integrated from it, so
/// that the map's first two key frames join the inertial window as ORB-SLAM3's do.
#[derive(Debug)]
struct Reference {
    stamp: f64,
    /// `R_gb` at the frame, where known.
    gravity_from_body: Option<UnitQuaternion<f64>>,
    from: Preintegrated,
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
    pub(super) fn new(calibration: ImuCalibration, monocular: bool) -> Self {
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
            monocular,
            attitude: None,
            reference: None,
            map_gravity: None,
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
            if let Some(r) = &mut self.reference {
                r.from.integrate_span(&span, from, stamp);
            }
            if let Some((attitude, gyro)) = &mut self.attitude {
                let mut a = Preintegrated::new(Bias { gyro: *gyro, accel: Vector3::zeros() }, &self.calibration);
                a.integrate_span(&span, from, stamp);
                *attitude *= a.delta_rotation();
            }
            self.from_frame = Some(p);
        }
        if let Some(last) = fresh.last() {
            self.carry = Some(*last);
        }
        self.last_stamp = Some(stamp);
        // A single camera: whether it started at rest, once (its map waits for motion, so the
        // rest's gravity is carried to the map's first key frame).
        if self.monocular && self.nav.is_none() && self.rest.as_ref().is_some_and(|r| r.len() >= REST_MIN_SAMPLES) {
            let samples = self.rest.take().unwrap_or_default();
            if let Ok(s) = static_initialise(&samples, &self.calibration) {
                self.attitude = Some((s.gravity_from_body, s.gyro_bias));
                // A reference frame taken so far was taken during the rest.
                if let Some(r) = &mut self.reference {
                    r.gravity_from_body = r.gravity_from_body.or(Some(s.gravity_from_body));
                }
            }
        }
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
        self.attitude = None;
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
        self.imu = Some(Box::new(Inertial::new(calibration, self.config.sensor == Sensor::Monocular)));
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

    /// ORB-SLAM3's local-map search with an IMU (`Tracking::SearchLocalPoints`'s `th`): 10
    /// before the IMU is initialised, 6 until its second full inertial BA (15 s after), 2 after;
    /// `None` without one.
    pub(super) fn inertial_local_search(&self, stamp: f64) -> Option<f64> {
        let imu = self.imu.as_ref()?;
        Some(match &imu.init {
            None => 10.0,
            Some(i) if stamp - i.stamp < INERTIAL_BA2_AFTER_S => 6.0,
            Some(_) => 2.0,
        })
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
        let Some(imu) = self.imu.as_ref() else { return };
        let body_from_cam = imu.calibration.body_from_cam;
        let (Some(nav), Some((kf, pre))) = (imu.nav.as_ref(), imu.from_kf.as_ref()) else { return };
        let world_from_body = fit.world_from_cam * body_from_cam.inverse();
        let anchor =
            |pose: Isometry3<f64>, velocity: Vector3<f64>| NavState { world_from_body: pose, velocity, bias: nav.bias };
        let visual = |velocity: Vector3<f64>| NavState { world_from_body, velocity, bias: nav.bias };
        // The frame's state; whether it replaces vision's pose; whether the test failed.
        let (state, replace, inconsistent) =
            match (nav.kf_pose.get(kf), self.keyframe_poses.get(kf), nav.kf_velocity.get(kf)) {
                (Some(pose), _, Some(v)) => {
                    let anchor = anchor(*pose, *v);
                    let initial = NavState { world_from_body, ..anchor.predict(pre, &nav.gravity_w) };
                    let r = optimize_inertial_pose(
                        &self.fit_observations(features, &fit.matched),
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
                        (r.state, true, false)
                    } else {
                        // The IMU since the anchor and the frame's observations disagree:
                        // vision's pose.
                        (visual(r.state.velocity), false, true)
                    }
                }
                (None, Some(kf_pose), Some(v)) => (
                    visual(anchor(kf_pose * body_from_cam.inverse(), *v).predict(pre, &nav.gravity_w).velocity),
                    false,
                    false,
                ),
                _ => (visual(nav.frame.velocity), false, false),
            };
        if replace {
            fit.world_from_cam = renormalised(&(state.world_from_body * body_from_cam));
        }
        let Some(nav) = self.imu.as_mut().and_then(|i| i.nav.as_mut()) else { return };
        nav.inconsistent += u64::from(inconsistent);
        nav.frame = state;
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
                Some(self.observation(p.position, f.uv, f.octave, f.depth))
            })
            .collect()
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
}
