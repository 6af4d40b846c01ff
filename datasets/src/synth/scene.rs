//! The scenes, all made of oriented boxes inside a bounding box: a textured room with
//! furniture and walking people ([`Scene::new`]), or a street round a city block for
//! [`super::Motion::Drive`] ([`Scene::street`]); and their state at any time `t`
//! (deterministic by seed).

use nalgebra::{Isometry3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::texture::{PhotoCrop, Surface, Texture, hash};

/// Room extent: `x ∈ [-W, W]`, `y ∈ [-D, D]`, `z ∈ [0, H]` (z up), metres.
pub const ROOM_HALF_WIDTH: f64 = 3.0;
/// See [`ROOM_HALF_WIDTH`].
pub const ROOM_HALF_DEPTH: f64 = 3.2;
/// See [`ROOM_HALF_WIDTH`].
pub const ROOM_HEIGHT: f64 = 2.7;

/// How far people's lanes keep from the band a camera walks in ([`Scene::new`]'s `walkway`),
/// metres, centre of the lane's sway to the band's edge. Chosen from the geometry, not from
/// results: people pass 1-2 m from the camera, as in TUM fr3/walking_*, instead of through it.
pub const WALKWAY_CLEARANCE: f64 = 1.0;

/// Amplitude of a walking person's sideways sway about their lane, metres.
const SWAY: f64 = 0.25;

/// What a pixel sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// Walls, floor, ceiling, furniture.
    Static,
    /// Person number `i` (instance `i + 1`).
    Person(u16),
}

/// An oriented box with a texture.
#[derive(Clone, Debug)]
pub struct Part {
    /// Pose of the box centre.
    pub world_from_part: Isometry3<f64>,
    /// Half extents along the box axes.
    pub half: Vector3<f64>,
    /// Surface pattern.
    pub texture: Texture,
    /// Static or which person.
    pub kind: Kind,
}

/// How people behave.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeopleMode {
    /// Walking across the room at 0.5–1.2 m/s.
    Walking,
    /// Seated near a spot, moving little (TUM `sitting`).
    Sitting,
}

#[derive(Clone, Debug)]
struct Person {
    start: Vector3<f64>,
    heading: f64,
    speed: f64,
    phase: f64,
    clothes: Texture,
    skin: Texture,
    height: f64,
}

/// The static room plus the people's motion model.
#[derive(Clone, Debug)]
pub struct Scene {
    statics: Vec<Part>,
    people: Vec<Person>,
    mode: PeopleMode,
    walls: [Texture; 6],
    /// The enclosing box's corners (the room; the street's sky and far ground), world metres.
    bounds: [Vector3<f64>; 2],
}

/// Distance from the middle of [`super::Motion::Drive`]'s lane to the block's facades on its
/// left, and to the facades across the street on its right, metres (a two-lane street with
/// pavements; chosen for the synthetic scene).
pub const STREET_LEFT: f64 = 7.0;
/// See [`STREET_LEFT`].
pub const STREET_RIGHT: f64 = 9.0;
/// Distance from the middle of the lane to the parked cars on its right, metres.
const PARKED_CARS: f64 = 4.5;

fn unit(h: u32) -> f64 {
    f64::from(h & 0xffff) / 65535.0
}

impl Scene {
    /// A room with `people` people, deterministic by `seed`. `walkway`, the band of `y` a
    /// camera moves through (`Motion::walkway`), keeps people's lanes [`WALKWAY_CLEARANCE`]
    /// away from it: they alternate between the room in front of it and behind it. Without a
    /// walkway (the TUM-like motions, whose camera stands at the back of the room) lanes spread
    /// from near the camera to the back of the room.
    pub fn new(seed: u64, people: usize, mode: PeopleMode, walkway: Option<(f64, f64)>) -> Self {
        let s = hash((seed ^ (seed >> 32)) as u32 ^ 0x5eed);
        // Photographed surfaces, tinted: `tile` is the metres one photo edge covers (the brick
        // photo shows 13 courses of bricks, 1.6 m with 12 cm courses; gravel stones of 1-3 cm).
        let tex = |i: u32, base: [f32; 3], surface: Surface, tile: f32, contrast: f32| Texture {
            base,
            tile,
            seed: hash(s ^ i),
            contrast,
            photo: None,
            surface: Some(surface),
            windows: None,
        };
        let walls = [
            tex(1, [0.75, 0.72, 0.65], Surface::Brick, 1.6, 1.0),  // x-
            tex(2, [0.65, 0.72, 0.78], Surface::Brick, 1.6, 1.0),  // x+
            tex(3, [0.78, 0.70, 0.60], Surface::Brick, 1.6, 1.0),  // y-
            tex(4, [0.70, 0.75, 0.68], Surface::Brick, 1.6, 1.0),  // y+ (facing the camera)
            tex(5, [0.55, 0.45, 0.35], Surface::Gravel, 1.0, 0.9), // floor
            tex(6, [0.90, 0.90, 0.88], Surface::Gravel, 2.0, 0.3), // ceiling
        ];
        let mut statics = Vec::new();
        // Furniture along the walls: cabinets, shelves, a table.
        for i in 0..7u32 {
            let h = hash(s ^ (100 + i));
            let (sx, sy, sz) = (0.3 + 0.6 * unit(h), 0.25 + 0.35 * unit(h >> 7), 0.5 + 1.3 * unit(h >> 13));
            let along = -0.8 + 1.6 * unit(hash(h));
            let (x, y) = match i % 4 {
                0 => (along * (ROOM_HALF_WIDTH - 0.6), ROOM_HALF_DEPTH - sy - 0.01),
                1 => (-ROOM_HALF_WIDTH + sy + 0.01, along * (ROOM_HALF_DEPTH - 0.8) + 1.0),
                2 => (ROOM_HALF_WIDTH - sy - 0.01, along * (ROOM_HALF_DEPTH - 0.8) + 1.0),
                _ => (along * 1.5, 1.8 + 0.6 * unit(h >> 3)),
            };
            let (sz, z) = if i % 4 == 3 { (0.38, 0.38) } else { (sz, sz) };
            let colour =
                [0.3 + 0.5 * unit(h >> 2) as f32, 0.3 + 0.4 * unit(h >> 5) as f32, 0.25 + 0.4 * unit(h >> 11) as f32];
            statics.push(Part {
                world_from_part: Isometry3::translation(x, y, z),
                half: Vector3::new(sx, sy, sz),
                texture: tex(
                    200 + i,
                    colour,
                    [Surface::Grass, Surface::Gravel, Surface::Brick][(h >> 23) as usize % 3],
                    0.5 + 0.4 * unit(h >> 17) as f32,
                    1.0,
                ),
                kind: Kind::Static,
            });
        }
        let n = people.max(1) as f64;
        let people = (0..people as u32)
            .map(|i| {
                let h = hash(s ^ (1000 + i));
                let speed = 0.5 + 0.7 * unit(h);
                // Walk roughly across the view (along x), at depths spread from near the camera
                // (where one person covers 20-40 % of the image) to the back of the room.
                let y = match walkway {
                    None => -1.5 + 3.4 * ((f64::from(i) + 0.6 * unit(h >> 5)) / n),
                    Some((near, far)) => {
                        // Lanes between the walkway's clearance and half a metre from the wall.
                        let (lo, hi) = if i % 2 == 0 {
                            (far + WALKWAY_CLEARANCE + SWAY, ROOM_HALF_DEPTH - 0.5 - SWAY)
                        } else {
                            (-ROOM_HALF_DEPTH + 0.5 + SWAY, near - WALKWAY_CLEARANCE - SWAY)
                        };
                        lo + (hi - lo).max(0.0) * unit(h >> 5)
                    }
                };
                let x = -2.4 + 4.8 * unit(h >> 9);
                let heading = if h & 1 == 0 { 0.0 } else { std::f64::consts::PI } + (unit(h >> 13) - 0.5) * 0.5;
                let colour = [
                    0.2 + 0.7 * unit(h >> 3) as f32,
                    0.2 + 0.6 * unit(h >> 8) as f32,
                    0.2 + 0.7 * unit(h >> 14) as f32,
                ];
                Person {
                    start: Vector3::new(x, y, 0.0),
                    heading,
                    speed,
                    phase: unit(h >> 11) * std::f64::consts::TAU,
                    clothes: Texture {
                        base: colour,
                        tile: 0.09,
                        seed: hash(h),
                        contrast: 1.0,
                        photo: None,
                        surface: None,
                        windows: None,
                    },
                    skin: Texture {
                        base: [0.85, 0.68, 0.55],
                        tile: 0.05,
                        seed: hash(h ^ 7),
                        contrast: 0.5,
                        photo: None,
                        surface: None,
                        windows: None,
                    },
                    height: 1.65 + 0.2 * unit(h >> 19),
                }
            })
            .collect();
        let bounds = [
            Vector3::new(-ROOM_HALF_WIDTH, -ROOM_HALF_DEPTH, 0.0),
            Vector3::new(ROOM_HALF_WIDTH, ROOM_HALF_DEPTH, ROOM_HEIGHT),
        ];
        Self { statics, people, mode, walls, bounds }
    }

    /// The street round a city block that [`super::Motion::Drive`] drives: buildings of 8 to
    /// 20 m frontage, 6 to 20 m high, each with its own photographed surface, tint, tile size
    /// and photo offset (so no two look alike and a facade does not repeat along the street),
    /// set back 0 to 1.5 m with alleys between some; on the block's side of the road
    /// [`STREET_LEFT`] from the lane, across it [`STREET_RIGHT`]; cars parked along the far
    /// kerb with gaps; a gravel-textured road and a plain sky. No people (yet). Deterministic
    /// by `seed`.
    pub fn street(seed: u64) -> Self {
        use super::motion::{DRIVE_CORNER, DRIVE_HALF_X, DRIVE_HALF_Y, drive_sides};
        let s = hash((seed ^ (seed >> 32)) as u32 ^ 0x57ee7);
        let mut statics = Vec::new();
        let mut n = 0u32;
        let mut next = || {
            n += 1;
            hash(s ^ n.wrapping_mul(0x9e37))
        };
        let surfaces = [Surface::Brick, Surface::Brick, Surface::Gravel, Surface::Grass];
        // A box on a side of the round: `along` and `across` (to the driver's left) from the
        // middle of the straight, on the ground; half extents along, across and up.
        let place = |mid: &Vector3<f64>, dir: &Vector3<f64>, along: f64, across: f64, half: Vector3<f64>| {
            let left = Vector3::z().cross(dir);
            let c = mid + dir * along + left * across + Vector3::new(0.0, 0.0, half.z);
            let yaw = dir.y.atan2(dir.x);
            Isometry3::from_parts(Translation3::from(c), UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw))
        };
        for (mid, dir, half_len) in drive_sides() {
            // The block's side: along the straight only (the corners are open squares).
            // Across the street: on past the corners, so the rows meet.
            for (lo, hi, front, depth, inner) in [
                (-half_len + 2.0, half_len - 2.0, STREET_LEFT, 12.0, true),
                (
                    -half_len - DRIVE_CORNER - STREET_RIGHT,
                    half_len + DRIVE_CORNER + STREET_RIGHT,
                    -STREET_RIGHT,
                    8.0,
                    false,
                ),
            ] {
                let mut at = lo;
                while at < hi - 4.0 {
                    let h = next();
                    let width = (8.0 + 12.0 * unit(h)).min(hi - at);
                    let height = 6.0 + 14.0 * unit(h >> 5);
                    let setback = 1.5 * unit(h >> 10);
                    let sign = if inner { 1.0 } else { -1.0 };
                    let across = sign * (front.abs() + setback + depth / 2.0);
                    let tint = [
                        0.45 + 0.45 * unit(h >> 3) as f32,
                        0.45 + 0.4 * unit(h >> 7) as f32,
                        0.4 + 0.4 * unit(h >> 13) as f32,
                    ];
                    let texture = Texture {
                        base: tint,
                        tile: 1.2 + 1.8 * unit(h >> 17) as f32,
                        seed: hash(h ^ 0xfacade),
                        contrast: 1.0,
                        photo: None,
                        surface: Some(surfaces[(h >> 27) as usize % 4]),
                        // Window bays of 2.5 to 4 m, floors of 3 to 3.6 m.
                        windows: Some([2.5 + 1.5 * unit(h >> 21) as f32, 3.0 + 0.6 * unit(h >> 25) as f32]),
                    };
                    statics.push(Part {
                        world_from_part: place(
                            &mid,
                            &dir,
                            at + width / 2.0,
                            across,
                            Vector3::new(width / 2.0, depth / 2.0, height / 2.0),
                        ),
                        half: Vector3::new(width / 2.0, depth / 2.0, height / 2.0),
                        texture,
                        kind: Kind::Static,
                    });
                    // An alley after one building in three.
                    at += width + if (h >> 23) % 3 == 0 { 2.0 + 2.0 * unit(h >> 19) } else { 0.0 };
                }
            }
            // Parked cars along the far kerb, with gaps.
            let mut at = -half_len + 3.0;
            while at < half_len - 5.0 {
                let h = next();
                if h % 3 != 0 {
                    let colour = [
                        0.2 + 0.7 * unit(h >> 4) as f32,
                        0.2 + 0.6 * unit(h >> 9) as f32,
                        0.2 + 0.7 * unit(h >> 14) as f32,
                    ];
                    let half = Vector3::new(2.1, 0.9, 0.75);
                    statics.push(Part {
                        world_from_part: place(&mid, &dir, at + half.x, -PARKED_CARS, half),
                        half,
                        texture: Texture {
                            base: colour,
                            tile: 0.4,
                            seed: hash(h ^ 0xca5),
                            contrast: 0.8,
                            photo: None,
                            surface: None,
                            windows: None,
                        },
                        kind: Kind::Static,
                    });
                }
                at += 5.0 + 6.0 * unit(h >> 18);
            }
        }
        let sky = Texture {
            base: [0.72, 0.82, 0.95],
            tile: 10.0,
            seed: 0,
            contrast: 0.0,
            photo: None,
            surface: None,
            windows: None,
        };
        let road = Texture {
            base: [0.38, 0.37, 0.36],
            tile: 1.0,
            seed: hash(s ^ 5),
            contrast: 0.9,
            photo: None,
            surface: Some(Surface::Gravel),
            windows: None,
        };
        let far = STREET_RIGHT + 8.0 + 1.5 + 30.0;
        let bounds = [
            Vector3::new(-DRIVE_HALF_X - far, -DRIVE_HALF_Y - far, 0.0),
            Vector3::new(DRIVE_HALF_X + far, DRIVE_HALF_Y + far, 60.0),
        ];
        Self { statics, people: Vec::new(), mode: PeopleMode::Walking, walls: [sky, sky, sky, sky, road, sky], bounds }
    }

    /// The enclosing box: its lowest and highest corners (world metres); every ray ends on it.
    pub fn bounds(&self) -> &[Vector3<f64>; 2] {
        &self.bounds
    }

    /// The texture of room face `f` (`0..6`: x-, x+, y-, y+, floor, ceiling).
    pub fn wall(&self, f: usize) -> &Texture {
        &self.walls[f.min(5)]
    }

    /// Furniture.
    pub fn statics(&self) -> &[Part] {
        &self.statics
    }

    /// Where person `p` stands and faces at time `t`: position on the floor, heading (rad).
    fn person_pose(&self, p: &Person, t: f64) -> (Vector3<f64>, f64, f64) {
        match self.mode {
            PeopleMode::Walking => {
                // Walk along the heading and bounce between the side walls (a triangle wave).
                let span = 2.0 * (ROOM_HALF_WIDTH - 0.5);
                let dir = p.heading.cos().signum();
                let s = p.start.x + 2.4 - 0.5 + dir * p.speed * t; // offset into [0, span] coordinates
                let m = s.rem_euclid(2.0 * span);
                let (pos, forward) = if m < span { (m, 1.0) } else { (2.0 * span - m, -1.0) };
                let x = -ROOM_HALF_WIDTH + 0.5 + pos;
                let heading = if forward > 0.0 { 0.0 } else { std::f64::consts::PI } + (p.heading.sin() * 0.3);
                let y = p.start.y + SWAY * (t * 0.4 + p.phase).sin();
                let gait = p.phase + t * p.speed * 5.0;
                (Vector3::new(x, y, 0.0), heading, gait)
            }
            PeopleMode::Sitting => {
                let sway = 0.05 * (t * 0.7 + p.phase).sin();
                (
                    p.start + Vector3::new(sway, 0.03 * (t * 0.5 + p.phase).cos(), 0.0),
                    p.heading + 0.2 * (t * 0.3 + p.phase).sin(),
                    0.0,
                )
            }
        }
    }

    /// The people's boxes at time `t`.
    pub fn people_parts(&self, t: f64) -> Vec<Part> {
        let mut parts = Vec::with_capacity(self.people.len() * 6);
        for (i, p) in self.people.iter().enumerate() {
            let (pos, heading, gait) = self.person_pose(p, t);
            let kind = Kind::Person(i as u16);
            let body = Isometry3::from_parts(
                Translation3::from(pos),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading),
            );
            let s = p.height / 1.75;
            let sitting = self.mode == PeopleMode::Sitting;
            let swing = if sitting { 0.0 } else { 0.45 * gait.sin() };
            let hip_z = if sitting { 0.5 } else { 0.9 * s };
            let torso_h = 0.3 * s;
            let mut push =
                |offset: Vector3<f64>, pivot: Vector3<f64>, angle: f64, half: Vector3<f64>, texture: Texture| {
                    // Rotate about the body's lateral (y) axis at `pivot`, then hang the box below/above it.
                    let joint = Isometry3::from_parts(
                        Translation3::from(pivot),
                        UnitQuaternion::from_axis_angle(&Vector3::y_axis(), angle),
                    );
                    parts.push(Part {
                        world_from_part: body * joint * Isometry3::translation(offset.x, offset.y, offset.z),
                        half,
                        texture,
                        kind,
                    });
                };
            // Torso, head.
            push(
                Vector3::new(0.0, 0.0, torso_h),
                Vector3::new(0.0, 0.0, hip_z),
                0.0,
                Vector3::new(0.12, 0.2, torso_h),
                Texture { photo: Some(PhotoCrop::TORSO), ..p.clothes },
            );
            push(
                Vector3::new(0.0, 0.0, 0.12 * s),
                Vector3::new(0.0, 0.0, hip_z + 2.0 * torso_h + 0.02),
                0.0,
                Vector3::new(0.1, 0.09, 0.12 * s),
                Texture { photo: Some(PhotoCrop::HEAD), ..p.skin },
            );
            // Legs swing opposite each other; arms opposite the legs.
            let leg = Vector3::new(0.07, 0.07, 0.45 * s);
            let legs_angle = if sitting { -1.45 } else { swing };
            push(Vector3::new(0.0, 0.0, -leg.z), Vector3::new(0.0, 0.1, hip_z), legs_angle, leg, p.clothes);
            push(
                Vector3::new(0.0, 0.0, -leg.z),
                Vector3::new(0.0, -0.1, hip_z),
                if sitting { -1.45 } else { -swing },
                leg,
                p.clothes,
            );
            let arm = Vector3::new(0.05, 0.05, 0.32 * s);
            let shoulder = hip_z + 2.0 * torso_h - 0.05;
            push(Vector3::new(0.0, 0.0, -arm.z), Vector3::new(0.0, 0.26, shoulder), -swing * 0.8, arm, p.skin);
            push(Vector3::new(0.0, 0.0, -arm.z), Vector3::new(0.0, -0.26, shoulder), swing * 0.8, arm, p.skin);
        }
        parts
    }
}

/// Rotation from the camera frame (x right, y down, z forward) to a world frame with z up,
/// for a camera looking along world `forward` with world `up`.
pub fn look_rotation(forward: &Vector3<f64>, up: &Vector3<f64>) -> UnitQuaternion<f64> {
    let z = forward.normalize();
    let x = z.cross(up).normalize();
    let y = z.cross(&x);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[x, y, z]))
}
