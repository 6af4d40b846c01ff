//! The semi-synthetic dynamic RGB-D generator (`synth`) with exact ground truth.
//!
//! A textured room with furniture and walking (or sitting) people made of oriented boxes is
//! ray cast from a camera following a TUM-fr3-like motion; Kinect-like depth noise, holes and
//! quantisation and image noise/blur are added. Ground truth: camera poses
//! (`world_from_cam`, TUM convention), per-pixel class and instance masks, optical flow.
//!
//! Split: `scene` (geometry and motion of people), `texture` (procedural patterns),
//! `motion` (camera trajectories), `render` (ray caster), `sensor` (noise models), `imu` (the
//! rig's IMU), `tum`, `kitti` and `euroc` (writing those layouts). The `synth` operator that streams it into a graph lives in
//! `dynaflow-operators`.

mod euroc;
mod imu;
mod kitti;
mod motion;
mod render;
mod scene;
mod sensor;
mod texture;
mod tum;

pub use euroc::{EurocWriteOptions, write_euroc};
pub use imu::{DIFF_STEP, rig_calibration};
pub use kitti::{KittiWriteOptions, write_kitti};
pub use motion::{DRIVE_SPEED, HANDHELD_REST, Motion, drive_length, drive_period};
pub use render::Intrinsics;
pub use scene::PeopleMode;
pub use tum::{WriteOptions, write_tum};

use nalgebra::{Isometry3, Point3};

/// TUM fr3 intrinsics at 640x480: what the generated camera uses, so `tum_rgbd` reads it back
/// with `fr3`.
pub const FR3: Intrinsics = crate::intrinsics::FR3.camera_info(640, 480);
/// First timestamp (seconds), in the range of TUM's Unix-time stamps.
pub const STAMP_BASE: f64 = 1_700_000_000.0;

/// Generator settings.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthConfig {
    /// Camera motion.
    pub motion: Motion,
    /// Number of people.
    pub people: usize,
    /// Walking or sitting.
    pub mode: PeopleMode,
    /// Scene and noise seed.
    pub seed: u64,
    /// Frame rate, Hz.
    pub rate_hz: f64,
    /// Camera model (scaled FR3 by default).
    pub intrinsics: Intrinsics,
    /// Kinect depth noise, holes and quantisation.
    pub depth_noise: bool,
    /// Image noise σ in grey levels (0 = none).
    pub image_noise: f32,
    /// 3×3 blur of the image.
    pub blur: bool,
    /// "Kidnap" the camera at this frame: [`KIDNAP_BLACKOUT`] frames are black with no depth
    /// (the camera covered and carried away), then the motion resumes [`KIDNAP_REWIND`]
    /// seconds earlier (the camera set down where it was then: a place already seen).
    pub kidnap: Option<u64>,
    /// Cover the camera at this frame for `blackout_frames` frames (black, no depth) while
    /// the motion goes on: what an IMU carries a tracker through, or, long, a camera that comes
    /// back somewhere its map never saw (a new map, merged later).
    pub blackout: Option<u64>,
    /// Frames a blackout lasts ([`KIDNAP_BLACKOUT`] by default).
    pub blackout_frames: u64,
}

/// TUM-VI cam0's Kannala-Brandt coefficients `[k1, k2, k3, k4]` (the published equidistant
/// calibration of its 512x512 cameras, Schubert et al., IROS 2018): the generated fisheye's lens.
pub const TUMVI_KB: [f64; 4] =
    [0.003_482_389_402_249_343, 0.000_715_034_845_216_225_7, -0.002_053_236_141_870_62, 0.000_202_936_735_918_111_8];

/// Focal length of the generated fisheye at 640x480, pixels: the image's corners 1.34 rad
/// (77 degrees) off the axis, as far as TUM-VI's 512x512 image reaches at its edges' midpoints
/// (256 / 190.98 px), and inside the 90 degrees a z-depth renderer can trace. A horizontal
/// field of view of 123 degrees against the pinhole's 62. Chosen for the synthetic scene.
pub const FISHEYE_FOCAL: f64 = 298.5;

/// The generated fisheye at `width` x `height`: [`FISHEYE_FOCAL`] scaled from 640x480 (the
/// principal point at the centre), TUM-VI's lens ([`TUMVI_KB`]).
pub fn fisheye(width: u32, height: u32) -> Intrinsics {
    let (sx, sy) = (f64::from(width) / 640.0, f64::from(height) / 480.0);
    let [k1, k2, k3, k4] = TUMVI_KB;
    Intrinsics {
        width,
        height,
        fx: FISHEYE_FOCAL * sx,
        fy: FISHEYE_FOCAL * sy,
        cx: f64::from(width) / 2.0 - 0.5,
        cy: f64::from(height) / 2.0 - 0.5,
        distortion: [k1, k2, k3, k4, 0.0],
        model: dynaflow_msg::LensModel::KannalaBrandt,
    }
}

/// Frames a kidnapped camera sees nothing (one second at 30 Hz).
pub const KIDNAP_BLACKOUT: u64 = 30;
/// How far back in its motion a kidnapped camera is set down, seconds.
pub const KIDNAP_REWIND: f64 = 10.0;

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            motion: Motion::Xyz,
            people: 2,
            mode: PeopleMode::Walking,
            seed: 0,
            rate_hz: 30.0,
            intrinsics: FR3,
            depth_noise: true,
            image_noise: 2.0,
            blur: true,
            kidnap: None,
            blackout: None,
            blackout_frames: KIDNAP_BLACKOUT,
        }
    }
}

/// KITTI odometry 00-02's left colour camera (`P2`): 1241x376, fx = fy = 718.856 px.
const KITTI_00: (f64, f64, f64, u32, u32) = (718.856, 607.1928, 185.2157, 1241, 376);

/// KITTI's camera at another resolution, square pixels kept: the focal length scales with
/// the width, the principal point with each axis. What [`Motion::Drive`] is seen through.
pub fn scaled_kitti(width: u32, height: u32) -> Intrinsics {
    let (f, cx, cy, w, h) = KITTI_00;
    let (sx, sy) = (f64::from(width) / f64::from(w), f64::from(height) / f64::from(h));
    Intrinsics {
        width,
        height,
        fx: f * sx,
        fy: f * sx,
        cx: (cx + 0.5) * sx - 0.5,
        cy: (cy + 0.5) * sy - 0.5,
        distortion: [0.0; 5],
        model: dynaflow_msg::LensModel::BrownConrady,
    }
}

/// Intrinsics for another resolution: FR3 scaled.
pub fn scaled_fr3(width: u32, height: u32) -> Intrinsics {
    let (sx, sy) = (f64::from(width) / 640.0, f64::from(height) / 480.0);
    Intrinsics {
        width,
        height,
        fx: FR3.fx * sx,
        fy: FR3.fy * sy,
        cx: (FR3.cx + 0.5) * sx - 0.5,
        cy: (FR3.cy + 0.5) * sy - 0.5,
        distortion: [0.0; 5],
        model: dynaflow_msg::LensModel::BrownConrady,
    }
}

/// One generated frame.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Frame number.
    pub index: u64,
    /// Timestamp, seconds.
    pub stamp: f64,
    /// Ground-truth camera pose.
    pub world_from_cam: Isometry3<f64>,
    /// RGB8 with sensor effects.
    pub rgb: Vec<u8>,
    /// Depth in metres with sensor effects (0 = no measurement).
    pub depth: Vec<f32>,
    /// Depth in metres without noise.
    pub depth_true: Vec<f32>,
    /// 0 static, 1 person.
    pub class: Vec<u16>,
    /// 0 static, `i + 1` person `i`.
    pub instance: Vec<u16>,
    /// Optical flow to the next frame `(du, dv)` per pixel, when asked for.
    pub flow: Option<Vec<[f32; 2]>>,
}

/// The generator: a scene plus a clock.
#[derive(Clone, Debug)]
pub struct Generator {
    config: SynthConfig,
    scene: scene::Scene,
}

impl Generator {
    /// A generator for `config`.
    pub fn new(config: SynthConfig) -> Self {
        // The drive has its own scene, the street; the people walk rooms only.
        let scene = if config.motion == Motion::Drive {
            scene::Scene::street(config.seed)
        } else {
            scene::Scene::new(config.seed, config.people, config.mode, config.motion.walkway())
        };
        Self { config, scene }
    }

    /// The settings.
    pub fn config(&self) -> &SynthConfig {
        &self.config
    }

    /// Time of frame `k` since the start, seconds.
    pub fn time(&self, k: u64) -> f64 {
        k as f64 / self.config.rate_hz
    }

    /// Ground-truth pose of frame `k`.
    pub fn pose(&self, k: u64) -> Isometry3<f64> {
        let t = self.time(k);
        match self.config.kidnap {
            Some(at) if k >= at + KIDNAP_BLACKOUT => self.config.motion.pose(t - KIDNAP_REWIND),
            _ => self.config.motion.pose(t),
        }
    }

    /// Is frame `k` blacked out (by a kidnap or a blackout)?
    pub fn blacked_out(&self, k: u64) -> bool {
        let kidnapped = self.config.kidnap.is_some_and(|at| (at..at + KIDNAP_BLACKOUT).contains(&k));
        let covered =
            self.config.blackout.is_some_and(|at| (at..at.saturating_add(self.config.blackout_frames)).contains(&k));
        kidnapped || covered
    }

    /// The people's body parts at frame `k` as oriented boxes (world from box centre, half
    /// extents): the ground truth of where the moving things are.
    pub fn people_boxes(&self, k: u64) -> Vec<(Isometry3<f64>, nalgebra::Vector3<f64>)> {
        self.scene.people_parts(self.time(k)).into_iter().map(|p| (p.world_from_part, p.half)).collect()
    }

    /// The static room's parts (walls, floor, furniture) as oriented boxes.
    pub fn static_boxes(&self) -> Vec<(Isometry3<f64>, nalgebra::Vector3<f64>)> {
        self.scene.statics().iter().map(|p| (p.world_from_part, p.half)).collect()
    }

    /// The RGB8 image (with its own sensor noise) of the right camera of a rectified stereo
    /// pair `baseline` metres to the right of the camera of `left` (a frame of this
    /// generator), same intrinsics and orientation: ORB-SLAM2's and KITTI's convention, a
    /// left point at column `u` is at `u - d` in the right image ([`disparity`](Self::disparity)).
    /// `None` for a baseline that is not positive and finite.
    pub fn right(&self, left: &Frame, baseline: f64) -> Option<Vec<u8>> {
        if !(baseline > 0.0 && baseline.is_finite()) {
            return None;
        }
        let c = &self.config;
        let k = left.index;
        if self.blacked_out(k) {
            return Some(vec![0; left.rgb.len()]);
        }
        let world_from_right = left.world_from_cam * nalgebra::Translation3::new(baseline, 0.0, 0.0);
        let parts = self.scene.people_parts(self.time(k));
        let r = render::render(&self.scene, &parts, &world_from_right, &c.intrinsics, false);
        let (w, h) = (c.intrinsics.width as usize, c.intrinsics.height as usize);
        let seed32 = (c.seed ^ (c.seed >> 32)) as u32;
        // Its own sensor noise: another seed for the noise hash.
        Some(sensor::camera_image(&r.rgb, w, h, c.image_noise, c.blur, seed32 ^ 0x5EED_0001, k as u32))
    }

    /// The exact disparity `fx * baseline / z` of every pixel of `left` for a right camera
    /// `baseline` metres to its right (0 where no surface was hit); a pinhole's (a fisheye's
    /// pair is not rectified: its disparity is not along rows).
    pub fn disparity(&self, left: &Frame, baseline: f64) -> Vec<f32> {
        let bf = self.config.intrinsics.fx * baseline;
        left.depth_true.iter().map(|&z| if z > 0.0 { (bf / f64::from(z)) as f32 } else { 0.0 }).collect()
    }

    /// Render frame `k` (and its flow to frame `k + 1` if `flow`).
    pub fn frame(&self, k: u64, flow: bool) -> Frame {
        let c = &self.config;
        let t = self.time(k);
        let world_from_cam = self.pose(k);
        let parts = self.scene.people_parts(t);
        let r = render::render(&self.scene, &parts, &world_from_cam, &c.intrinsics, flow);
        let (w, h) = (c.intrinsics.width as usize, c.intrinsics.height as usize);
        let seed32 = (c.seed ^ (c.seed >> 32)) as u32;
        let frame32 = k as u32;
        let mut depth =
            if c.depth_noise { sensor::kinect_depth(&r.depth, w, seed32, frame32) } else { r.depth.clone() };
        let mut rgb = sensor::camera_image(&r.rgb, w, h, c.image_noise, c.blur, seed32, frame32);
        if self.blacked_out(k) {
            rgb.fill(0);
            depth.fill(0.0);
        }
        let flow = flow.then(|| {
            let t1 = self.time(k + 1);
            let next_parts = self.scene.people_parts(t1);
            let cam1_from_world = self.pose(k + 1).inverse();
            let k_ = &c.intrinsics;
            let lens = dynaflow_vision::camera::KannalaBrandt::from_camera_info(k_);
            r.hits
                .iter()
                .enumerate()
                .map(|(i, hit)| {
                    let p = Point3::new(f64::from(hit.point[0]), f64::from(hit.point[1]), f64::from(hit.point[2]));
                    let world = match next_parts.get(hit.part as usize) {
                        Some(part) if hit.part != u32::MAX => part.world_from_part * p,
                        _ => p,
                    };
                    let q = cam1_from_world * world;
                    let (u, v) = ((i % w) as f64, (i / w) as f64);
                    if q.z <= 1e-6 {
                        return [f32::NAN, f32::NAN];
                    }
                    let [pu, pv] = match &lens {
                        Some(kb) => kb.project(&q).unwrap_or([f64::NAN; 2]),
                        None => [k_.fx * q.x / q.z + k_.cx, k_.fy * q.y / q.z + k_.cy],
                    };
                    [(pu - u) as f32, (pv - v) as f32]
                })
                .collect()
        });
        Frame {
            index: k,
            stamp: STAMP_BASE + t,
            world_from_cam,
            rgb,
            depth,
            depth_true: r.depth,
            class: r.class,
            instance: r.instance,
            flow,
        }
    }
}

#[cfg(test)]
mod tests;
