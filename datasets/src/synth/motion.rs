//! Camera trajectories modelled on the TUM fr3 sequences (`static`, `xyz`, `rpy`, `halfsphere`),
//! `loop`, a walk around the room that comes back to where it started (loop closing), and
//! `handheld`, a camera held in the hand that rests, then shakes and turns (visual-inertial
//! initialisation), and `drive`, a car driving round a city block again and again (a
//! KITTI-like long sequence in the street scene, [`super::scene::Scene::street`]).

use std::f64::consts::PI;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::scene::look_rotation;

/// A camera motion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// Fixed camera.
    Static,
    /// Translation along x, y and z (±0.3 m), orientation fixed.
    Xyz,
    /// Roll, pitch and yaw oscillations (±10–20°), position fixed.
    Rpy,
    /// The camera moves on a half sphere around the scene, looking at its centre.
    Halfsphere,
    /// The camera walks a circle of 0.6 m radius in the middle of the room, looking outwards
    /// (it sees every wall in turn), and is back where it started after [`LOOP_PERIOD`]
    /// seconds: frames after that revisit the first ones. People walk their lanes a metre
    /// clear of its circle ([`Motion::walkway`]), in front of it and behind it.
    Loop,
    /// A camera held in the hand at the back of the room: at rest for [`HANDHELD_REST`]
    /// seconds (a static IMU initialisation can run), then, eased in over
    /// [`HANDHELD_EASE`] seconds, it moves along all three axes (±12 to ±25 cm, periods of
    /// 1.7 to 3.1 s, peak accelerations of 1.0 to 1.6 m/s²) and turns about all three (±7 to
    /// ±14°, periods of 3.7 to 5.3 s), so that scale, gravity and the biases are observable
    /// from the first seconds of motion.
    Handheld,
    /// A car driving counter-clockwise round a city block at [`DRIVE_SPEED`], the camera
    /// [`DRIVE_CAMERA_HEIGHT`] above the road looking along it (KITTI's rig): a rounded
    /// rectangle of [`DRIVE_HALF_X`] x [`DRIVE_HALF_Y`] metres with corners of
    /// [`DRIVE_CORNER`] m radius, back at its start after [`drive_period`] seconds, then round
    /// again (4,500 frames at 10 Hz drive it 2.3 times: two revisits). Only in the street scene.
    Drive,
}

/// Half extents of [`Motion::Drive`]'s round (the middle of its lane), metres.
pub const DRIVE_HALF_X: f64 = 95.0;
/// See [`DRIVE_HALF_X`].
pub const DRIVE_HALF_Y: f64 = 56.0;
/// Radius of [`Motion::Drive`]'s corners, metres.
pub const DRIVE_CORNER: f64 = 12.0;
/// [`Motion::Drive`]'s speed, m/s (11 km/h: a car in city traffic, 0.3 m a frame at KITTI's
/// 10 Hz).
pub const DRIVE_SPEED: f64 = 3.0;
/// Height of the camera above the road, metres (KITTI's: 1.65 m).
pub const DRIVE_CAMERA_HEIGHT: f64 = 1.65;

/// Length of one round of [`Motion::Drive`], metres.
pub fn drive_length() -> f64 {
    4.0 * (DRIVE_HALF_X - DRIVE_CORNER) + 4.0 * (DRIVE_HALF_Y - DRIVE_CORNER) + 2.0 * PI * DRIVE_CORNER
}

/// Seconds of one round of [`Motion::Drive`].
pub fn drive_period() -> f64 {
    drive_length() / DRIVE_SPEED
}

/// The four straights of [`Motion::Drive`], in driving order: the middle of the straight
/// (on the road), the driving direction, and half the straight's length. The round starts at
/// the middle of the first.
pub fn drive_sides() -> [(Vector3<f64>, Vector3<f64>, f64); 4] {
    let (hx, hy) = (DRIVE_HALF_X - DRIVE_CORNER, DRIVE_HALF_Y - DRIVE_CORNER);
    [
        (Vector3::new(0.0, -DRIVE_HALF_Y, 0.0), Vector3::x(), hx),
        (Vector3::new(DRIVE_HALF_X, 0.0, 0.0), Vector3::y(), hy),
        (Vector3::new(0.0, DRIVE_HALF_Y, 0.0), -Vector3::x(), hx),
        (Vector3::new(-DRIVE_HALF_X, 0.0, 0.0), -Vector3::y(), hy),
    ]
}

/// Where [`Motion::Drive`] is after `s` metres of its round: position on the road and
/// driving direction.
fn drive_at(s: f64) -> (Vector3<f64>, Vector3<f64>) {
    let mut s = s.rem_euclid(drive_length());
    let sides = drive_sides();
    // From the middle of straight `i`: its second half, then the corner, then the next one's
    // first half.
    for (i, &(mid, dir, half)) in sides.iter().enumerate() {
        if s <= half {
            return (mid + dir * s, dir);
        }
        s -= half;
        let arc = 0.5 * PI * DRIVE_CORNER;
        let left = Vector3::z().cross(&dir);
        if s <= arc {
            // Turning left about the corner's centre.
            let centre = mid + dir * half + left * DRIVE_CORNER;
            let a = s / DRIVE_CORNER;
            let p = centre - left * (DRIVE_CORNER * a.cos()) + dir * (DRIVE_CORNER * a.sin());
            return (p, dir * a.cos() + left * a.sin());
        }
        s -= arc;
        let (next_mid, next_dir, next_half) = sides[(i + 1) % 4];
        if s <= next_half || i == 3 {
            return (next_mid - next_dir * (next_half - s), next_dir);
        }
        s -= next_half;
    }
    (sides[0].0, sides[0].1)
}

/// Seconds [`Motion::Handheld`] rests before it moves.
pub const HANDHELD_REST: f64 = 1.0;
/// Seconds over which [`Motion::Handheld`]'s motion eases in (a quintic smooth step, so
/// acceleration stays continuous and the IMU sees no jump).
pub const HANDHELD_EASE: f64 = 1.5;

/// Seconds of one round of [`Motion::Loop`] (900 frames at 30 Hz).
pub const LOOP_PERIOD: f64 = 30.0;

/// Centre of [`Motion::Loop`]'s circle (world, metres).
const LOOP_CENTRE: [f64; 3] = [0.0, -0.4, 1.4];
/// Radius of [`Motion::Loop`]'s circle, metres.
const LOOP_RADIUS: f64 = 0.6;

impl Motion {
    /// Names used in graphs and on the command line.
    pub const NAMES: &'static [&'static str] = &["static", "xyz", "rpy", "halfsphere", "loop", "handheld", "drive"];

    /// Parse a name.
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "static" => Some(Self::Static),
            "xyz" => Some(Self::Xyz),
            "rpy" => Some(Self::Rpy),
            "halfsphere" => Some(Self::Halfsphere),
            "loop" => Some(Self::Loop),
            "handheld" => Some(Self::Handheld),
            "drive" => Some(Self::Drive),
            _ => None,
        }
    }

    /// The band of world `y` the camera walks through when it moves through the middle of the
    /// room (the scene keeps people's lanes clear of it), or `None` when it stays at the back of
    /// the room, where people walk in front of it.
    pub fn walkway(self) -> Option<(f64, f64)> {
        match self {
            Motion::Loop => Some((LOOP_CENTRE[1] - LOOP_RADIUS, LOOP_CENTRE[1] + LOOP_RADIUS)),
            _ => None,
        }
    }

    /// `world_from_cam` at time `t` seconds.
    pub fn pose(self, t: f64) -> Isometry3<f64> {
        let base = Vector3::new(0.0, -2.5, 1.4);
        let target = Vector3::new(0.0, 1.5, 1.05);
        let up = Vector3::z();
        let w = |period: f64| 2.0 * PI * t / period;
        match self {
            Motion::Static => Isometry3::from_parts(Translation3::from(base), look_rotation(&(target - base), &up)),
            Motion::Xyz => {
                let p = base + Vector3::new(0.3 * w(6.0).sin(), 0.25 * w(9.0).sin(), 0.2 * w(7.5).sin());
                Isometry3::from_parts(Translation3::from(p), look_rotation(&(target - base), &up))
            }
            Motion::Rpy => {
                let look = look_rotation(&(target - base), &up);
                // Intrinsic rotations in the camera frame: yaw about y (down), pitch about x, roll about z.
                let yaw = 0.35 * w(8.0).sin();
                let pitch = 0.2 * w(6.5).sin();
                let roll = 0.2 * w(10.0).sin();
                let wiggle = UnitQuaternion::from_euler_angles(pitch, yaw, roll);
                Isometry3::from_parts(Translation3::from(base), look * wiggle)
            }
            Motion::Halfsphere => {
                let centre = Vector3::new(0.0, 1.5, 1.0);
                let azimuth = 0.5 * w(20.0).sin();
                let elevation = 0.22 + 0.2 * w(13.0).sin();
                let r = 3.8;
                let p = centre
                    + r * Vector3::new(
                        azimuth.sin() * elevation.cos(),
                        -azimuth.cos() * elevation.cos(),
                        elevation.sin(),
                    );
                Isometry3::from_parts(Translation3::from(p), look_rotation(&(centre - p), &up))
            }
            Motion::Loop => {
                // Start where the other motions are looking from, facing the same wall (+y);
                // turn left (counter-clockwise seen from above) once per period. A slow bob in
                // height keeps the views of one round from being a pure rotation.
                let a = w(LOOP_PERIOD);
                let centre = Vector3::from(LOOP_CENTRE);
                let radial = Vector3::new(-a.sin(), a.cos(), 0.0);
                let p = centre + LOOP_RADIUS * radial + Vector3::new(0.0, 0.0, 0.1 * (2.0 * a).sin());
                let forward = radial - Vector3::new(0.0, 0.0, 0.08);
                Isometry3::from_parts(Translation3::from(p), look_rotation(&forward, &up))
            }
            Motion::Handheld => {
                // Incommensurate periods (1.7 to 5.3 s), so no two axes move in step.
                let e = handheld_envelope(t);
                let shake = Vector3::new(0.25 * w(3.1).sin(), 0.15 * (w(2.3) + 1.0).sin(), 0.12 * w(1.7).sin());
                let look = look_rotation(&(target - base), &up);
                let yaw = 0.25 * w(4.3).sin();
                let pitch = 0.15 * (w(3.7) + 0.5).sin();
                let roll = 0.12 * w(5.3).sin();
                let wiggle = UnitQuaternion::from_euler_angles(e * pitch, e * yaw, e * roll);
                Isometry3::from_parts(Translation3::from(base + e * shake), look * wiggle)
            }
            Motion::Drive => {
                let (p, dir) = drive_at(DRIVE_SPEED * t);
                let p = p + Vector3::new(0.0, 0.0, DRIVE_CAMERA_HEIGHT);
                Isometry3::from_parts(Translation3::from(p), look_rotation(&dir, &up))
            }
        }
    }
}

/// How much of [`Motion::Handheld`]'s motion is on at `t`: 0 at rest, then a quintic smooth
/// step (zero first and second derivatives at both ends) to 1.
fn handheld_envelope(t: f64) -> f64 {
    let x = ((t - HANDHELD_REST) / HANDHELD_EASE).clamp(0.0, 1.0);
    x * x * x * (x * (6.0 * x - 15.0) + 10.0)
}
