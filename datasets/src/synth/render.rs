//! A ray caster for the scene: per pixel the nearest of the room's inner faces, the furniture
//! boxes and the people's boxes. Rays are `((u - cx)/fx, (v - cy)/fy, 1)` in the camera frame
//! (through a Kannala-Brandt fisheye: the pixel's ray unprojected, scaled to `z = 1`), so the
//! ray parameter is the z-depth directly. Objects are culled per pixel by their projected
//! screen rectangle (of the part in front of the camera: a box behind it is never tested; a
//! fisheye bends straight edges, so there each ray is tested against the box's rectangle on
//! the `z = 1` plane instead); rows are split across threads.

use nalgebra::{Isometry3, Matrix3, Point3, Vector3};

use super::scene::{Kind, Part, Scene};
use super::texture::Texture;

/// The rendered camera: a pinhole without distortion, or a Kannala-Brandt fisheye (whose
/// image must stay within 90 degrees of the axis: a z-depth has no meaning beyond).
pub type Intrinsics = dynaflow_msg::CameraInfo;

/// The ray through image point `(u, v)`, scaled to `z = 1`.
fn ray(k: &Intrinsics, lens: Option<&dynaflow_vision::camera::KannalaBrandt>, u: f64, v: f64) -> Vector3<f64> {
    match lens {
        Some(kb) => {
            let [x, y] = kb.unproject_normalised([u, v]);
            Vector3::new(x, y, 1.0)
        }
        None => Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0),
    }
}

/// What a pixel's ray hit, for ground-truth flow.
#[derive(Clone, Copy, Debug, Default)]
pub struct Hit {
    /// Index into the dynamic parts, or `u32::MAX` for static geometry.
    pub part: u32,
    /// The point: world coordinates if static, part coordinates if dynamic.
    pub point: [f32; 3],
}

/// A rendered frame before sensor effects.
#[derive(Clone, Debug, Default)]
pub struct Rendered {
    /// RGB8, row-major.
    pub rgb: Vec<u8>,
    /// True z-depth in metres (no noise); 0 where nothing was hit.
    pub depth: Vec<f32>,
    /// 0 = static, 1 = person.
    pub class: Vec<u16>,
    /// 0 = static, `i + 1` = person `i`.
    pub instance: Vec<u16>,
    /// Per-pixel hit, when asked for.
    pub hits: Vec<Hit>,
}

struct Prepared<'a> {
    part: &'a Part,
    cam_from_part_rot: Matrix3<f64>,
    /// The inverse rotation and the camera centre in part coordinates (`Rᵀ(0 − t)`), once per
    /// frame instead of once per ray.
    part_from_cam_rot: Matrix3<f64>,
    origin_in_part: Vector3<f64>,
    /// Screen rectangle `[u0, v0, u1, v1]` (inclusive) where the box may appear.
    rect: [i64; 4],
    /// The same on the `z = 1` plane `[x0, y0, x1, y1]`: a ray `(x, y, 1)` outside it misses
    /// the box (what a fisheye's rays are tested against).
    plane_rect: [f64; 4],
    dynamic_index: u32,
}

/// The eight corners of `part`'s box through `frame_from_part`; corner `c` has coordinate
/// `+half` on axis `i` where bit `i` of `c` is set, `-half` elsewhere.
pub(super) fn box_corners(part: &Part, frame_from_part: &Isometry3<f64>) -> [Point3<f64>; 8] {
    std::array::from_fn(|corner| {
        let s = |bit: usize| if corner & (1 << bit) == 0 { -1.0 } else { 1.0 };
        frame_from_part * Point3::new(s(0) * part.half.x, s(1) * part.half.y, s(2) * part.half.z)
    })
}

fn prepare<'a>(
    part: &'a Part,
    cam_from_world: &Isometry3<f64>,
    k: &Intrinsics,
    dynamic_index: u32,
    cull: bool,
) -> Prepared<'a> {
    let cam_from_part = cam_from_world * part.world_from_part;
    let (w, h) = (i64::from(k.width), i64::from(k.height));
    let corners = box_corners(part, &cam_from_part);
    // The part of the box a ray can hit lies at z >= NEAR (`hit_box` takes hits at t > 1e-4,
    // and t is the z-depth): the corners in front of that plane and where the box's edges
    // cross it. Its projection bounds every pixel the box can cover, so the culling is exact;
    // a box wholly behind the camera is never tested.
    const NEAR: f64 = 0.5e-4;
    let mut front: Vec<Point3<f64>> = corners.iter().filter(|p| p.z >= NEAR).copied().collect();
    for a in 0..8usize {
        for bit in 0..3 {
            let b = a | (1 << bit);
            let (p, q) = (corners[a], corners[b]);
            if b != a && (p.z < NEAR) != (q.z < NEAR) {
                front.push(p + (q - p) * ((NEAR - p.z) / (q.z - p.z)));
            }
        }
    }
    let mut rect = [i64::MAX, i64::MAX, i64::MIN, i64::MIN];
    // Widened by a relative 1e-9 against the rounding of the two divisions.
    let mut plane_rect = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for p in &front {
        let (x, y) = (p.x / p.z, p.y / p.z);
        let slack = 1e-9 * (1.0 + x.abs() + y.abs());
        plane_rect = [
            plane_rect[0].min(x - slack),
            plane_rect[1].min(y - slack),
            plane_rect[2].max(x + slack),
            plane_rect[3].max(y + slack),
        ];
    }
    for p in &front {
        let (u, v) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
        // Clamped a little beyond the image (the tests allow a pixel of margin).
        let (u, v) = (u.clamp(-4.0, (w + 4) as f64), v.clamp(-4.0, (h + 4) as f64));
        rect = [
            rect[0].min(u.floor() as i64),
            rect[1].min(v.floor() as i64),
            rect[2].max(u.ceil() as i64),
            rect[3].max(v.ceil() as i64),
        ];
    }
    if front.is_empty() {
        // Nothing in front: a rectangle no pixel (nor its margin) falls in.
        rect = [w + 4, h + 4, -4, -4];
    }
    if !cull {
        rect = [-4, -4, w + 4, h + 4];
        plane_rect = [f64::NEG_INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::INFINITY];
    }
    let cam_from_part_rot = cam_from_part.rotation.to_rotation_matrix().into_inner();
    let part_from_cam_rot = cam_from_part_rot.transpose();
    let origin_in_part = -(part_from_cam_rot * cam_from_part.translation.vector);
    Prepared { part, cam_from_part_rot, part_from_cam_rot, origin_in_part, rect, plane_rect, dynamic_index }
}

/// Slab test of a camera-frame ray (origin 0) against an oriented box: `(t, face axis, local point)`.
fn hit_box(p: &Prepared<'_>, d: &Vector3<f64>) -> Option<(f64, usize, Vector3<f64>)> {
    // Ray in part coordinates: o' = Rᵀ(0 − t), d' = Rᵀ d.
    let o = p.origin_in_part;
    let dl = p.part_from_cam_rot * d;
    let mut tmin = f64::NEG_INFINITY;
    let mut tmax = f64::INFINITY;
    let mut axis = 0;
    for a in 0..3 {
        let h = p.part.half[a];
        if dl[a].abs() < 1e-12 {
            if o[a].abs() > h {
                return None;
            }
            continue;
        }
        let (t1, t2) = ((-h - o[a]) / dl[a], (h - o[a]) / dl[a]);
        let (lo, hi) = if t1 < t2 { (t1, t2) } else { (t2, t1) };
        if lo > tmin {
            tmin = lo;
            axis = a;
        }
        tmax = tmax.min(hi);
    }
    (tmax >= tmin && tmin > 1e-4).then(|| (tmin, axis, o + dl * tmin))
}

/// Sub-samples per pixel side for the colour of edge pixels: a 3x3 stratified grid (its
/// middle cell is the centre ray). 2x2 plus the centre left LK's endpoint error at 0.11 px on
/// the synthetic scene (OpenCV's too), 3x3 brings both to 0.085 px.
const SUPERSAMPLE: usize = 3;

/// Offsets of the stratified sub-samples other than the centre, pixels.
fn subsample_offsets() -> impl Iterator<Item = (f64, f64)> {
    let n = SUPERSAMPLE as f64;
    (0..SUPERSAMPLE * SUPERSAMPLE)
        // An odd grid's middle cell is the centre ray, already traced.
        .filter(|&i| SUPERSAMPLE.is_multiple_of(2) || i != SUPERSAMPLE * SUPERSAMPLE / 2)
        .map(move |i| (((i % SUPERSAMPLE) as f64 + 0.5) / n - 0.5, ((i / SUPERSAMPLE) as f64 + 0.5) / n - 0.5))
}

/// Lit colour in 0..=1 (averaged over sub-samples before quantising).
fn shade_linear(colour: [f32; 3], light: f32) -> [f32; 3] {
    colour.map(|c| (c * light).clamp(0.0, 1.0))
}

/// Render the scene from `world_from_cam` with the given dynamic parts.
pub fn render(
    scene: &Scene,
    dynamic: &[Part],
    world_from_cam: &Isometry3<f64>,
    k: &Intrinsics,
    want_hits: bool,
) -> Rendered {
    render_culled(scene, dynamic, world_from_cam, k, want_hits, true)
}

/// [`render`], with the per-object screen rectangles (`cull`) or every object tested by every
/// ray (the reference the culling must reproduce bit for bit).
pub(super) fn render_culled(
    scene: &Scene,
    dynamic: &[Part],
    world_from_cam: &Isometry3<f64>,
    k: &Intrinsics,
    want_hits: bool,
    cull: bool,
) -> Rendered {
    let cam_from_world = world_from_cam.inverse();
    let objects: Vec<Prepared<'_>> = scene
        .statics()
        .iter()
        .map(|p| prepare(p, &cam_from_world, k, u32::MAX, cull))
        .chain(dynamic.iter().enumerate().map(|(i, p)| prepare(p, &cam_from_world, k, i as u32, cull)))
        .collect();
    let (w, h) = (k.width as usize, k.height as usize);
    let n = w * h;
    let mut out = Rendered {
        rgb: vec![0; n * 3],
        depth: vec![0.0; n],
        class: vec![0; n],
        instance: vec![0; n],
        hits: if want_hits { vec![Hit::default(); n] } else { Vec::new() },
    };
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get).clamp(1, 8);
    let rows_per = h.div_ceil(threads).max(1);
    let room_rot = world_from_cam.rotation.to_rotation_matrix().into_inner();
    let origin = world_from_cam.translation.vector;
    std::thread::scope(|s| {
        let rgb = out.rgb.chunks_mut(rows_per * w * 3);
        let depth = out.depth.chunks_mut(rows_per * w);
        let class = out.class.chunks_mut(rows_per * w);
        let inst = out.instance.chunks_mut(rows_per * w);
        let mut hits: Vec<Option<&mut [Hit]>> = if want_hits {
            out.hits.chunks_mut(rows_per * w).map(Some).collect()
        } else {
            (0..threads).map(|_| None).collect()
        };
        for (band, (((rgb, depth), class), inst)) in rgb.zip(depth).zip(class).zip(inst).enumerate() {
            let hits = hits.get_mut(band).and_then(Option::take);
            let objects = &objects;
            s.spawn(move || {
                let v0 = band * rows_per;
                render_rows(scene, objects, k, &room_rot, &origin, v0, rgb, depth, class, inst, hits);
            });
        }
    });
    out
}

/// What one ray sees: distance, surface colour, normal, what it hit, and whether the texture
/// there has hard colour edges (procedural tiles; photos are bilinear, so smooth).
type Seen = (f64, [f32; 3], Vector3<f64>, Kind, Hit, bool);

/// The fixed parts of a frame's rays.
struct Rays<'a> {
    scene: &'a Scene,
    objects: &'a [Prepared<'a>],
    k: &'a Intrinsics,
    lens: Option<dynaflow_vision::camera::KannalaBrandt>,
    world_from_cam_rot: &'a Matrix3<f64>,
    origin: &'a Vector3<f64>,
}

impl Rays<'_> {
    /// Objects whose rectangle meets row `v` (a pixel's sub-samples reach half a pixel beyond);
    /// through a fisheye, whose rows are curves on the `z = 1` plane, every object.
    fn candidates(&self, v: usize) -> Vec<&Prepared<'_>> {
        if self.lens.is_some() {
            return self.objects.iter().collect();
        }
        let vi = v as i64;
        self.objects.iter().filter(|o| o.rect[1] - 1 <= vi && vi <= o.rect[3] + 1).collect()
    }

    /// Trace the ray through image point `(uf, vf)` against `candidates` and the room.
    fn trace(&self, candidates: &[&Prepared<'_>], uf: f64, vf: f64) -> Seen {
        let (scene, k, world_from_cam_rot, origin) = (self.scene, self.k, self.world_from_cam_rot, self.origin);
        let [bounds_min, bounds_max] = *scene.bounds();
        let d = ray(k, self.lens.as_ref(), uf, vf);
        let (ui, vi) = (uf.round() as i64, vf.round() as i64);
        let fisheye = self.lens.is_some();
        let inside = |o: &&&Prepared<'_>| {
            if fisheye {
                let r = &o.plane_rect;
                return r[0] <= d.x && d.x <= r[2] && r[1] <= d.y && d.y <= r[3];
            }
            o.rect[0] - 1 <= ui && ui <= o.rect[2] + 1 && o.rect[1] - 1 <= vi && vi <= o.rect[3] + 1
        };
        let mut best: Option<(f64, &Prepared<'_>, usize, Vector3<f64>)> = None;
        for o in candidates.iter().filter(inside) {
            if let Some((t, axis, local)) = hit_box(o, &d)
                && best.as_ref().is_none_or(|b| t < b.0)
            {
                best = Some((t, o, axis, local));
            }
        }
        // The room always encloses the camera: its exit distance bounds every hit.
        let dw = world_from_cam_rot * d;
        let mut t_room = f64::INFINITY;
        let mut face = 0;
        for a in 0..3 {
            let (t, f) = if dw[a] > 1e-12 {
                ((bounds_max[a] - origin[a]) / dw[a], 2 * a + 1)
            } else if dw[a] < -1e-12 {
                ((bounds_min[a] - origin[a]) / dw[a], 2 * a)
            } else {
                continue;
            };
            if t < t_room {
                t_room = t;
                face = f;
            }
        }
        match best {
            Some((t, o, axis, local)) if t < t_room => {
                let (a, b) = match axis {
                    0 => (local.y + o.part.half.y, local.z + o.part.half.z),
                    1 => (local.x + o.part.half.x, local.z + o.part.half.z),
                    _ => (local.x + o.part.half.x, local.y + o.part.half.y),
                };
                let mut n = Vector3::zeros();
                n[axis] = local[axis].signum();
                let nw = o.part.world_from_part.rotation * n;
                let hit = if o.dynamic_index == u32::MAX {
                    let pw = origin + dw * t;
                    Hit { part: u32::MAX, point: [pw.x as f32, pw.y as f32, pw.z as f32] }
                } else {
                    Hit { part: o.dynamic_index, point: [local.x as f32, local.y as f32, local.z as f32] }
                };
                let (sa, sb) = match axis {
                    0 => (2.0 * o.part.half.y, 2.0 * o.part.half.z),
                    1 => (2.0 * o.part.half.x, 2.0 * o.part.half.z),
                    _ => (2.0 * o.part.half.x, 2.0 * o.part.half.y),
                };
                let tex = &o.part.texture;
                let cos = (o.cam_from_part_rot * n).dot(&d).abs() / d.norm();
                let colour = tex.sample_face(axis, a as f32, b as f32, sa as f32, sb as f32, footprint(t, &d, cos, k));
                (t, colour, nw, o.part.kind, hit, tex.hard_edges(axis))
            }
            _ => {
                let pw = origin + dw * t_room;
                let axis = face / 2;
                let (a, b) = match axis {
                    0 => (pw.y, pw.z),
                    1 => (pw.x, pw.z),
                    _ => (pw.x, pw.y),
                };
                let tex: &Texture = scene.wall(face);
                let mut n = Vector3::zeros();
                n[axis] = if face % 2 == 0 { 1.0 } else { -1.0 };
                (
                    t_room,
                    tex.sample(a as f32, b as f32, footprint(t_room, &d, n.dot(&dw).abs() / dw.norm(), k)),
                    n,
                    Kind::Static,
                    Hit { part: u32::MAX, point: [pw.x as f32, pw.y as f32, pw.z as f32] },
                    tex.hard_edges(axis),
                )
            }
        }
    }
}

/// Metres of a surface one pixel covers: the ray's length over the focal length, stretched by
/// the incidence (capped at 4x, where a grazing surface is blurred anyway).
fn footprint(t: f64, d: &Vector3<f64>, cos: f64, k: &Intrinsics) -> f32 {
    (t * d.norm() / (k.fx.min(k.fy) * cos.max(0.25))) as f32
}

/// Lit colour of what a ray saw.
fn lit(seen: &Seen) -> [f32; 3] {
    let light = Vector3::new(0.3, -0.5, 0.8).normalize();
    shade_linear(seen.1, 0.7 + 0.3 * seen.2.dot(&light).abs() as f32)
}

/// On a texture with hard edges, a pixel needs sub-samples when its centre colour differs
/// from a neighbour's by more than this (four grey levels, twice the sensor noise).
const EDGE_CONTRAST: f32 = 4.0 / 255.0;

/// Whether a pixel and its neighbour straddle an edge its sub-samples must integrate: a
/// geometric one (another object or face, a depth step of more than 2 %), or a colour step on
/// a texture with hard edges. Photo textures are sampled bilinearly, so their colour moves
/// smoothly under sub-pixel motion without sub-samples (and would otherwise mark nearly every
/// pixel an edge).
fn straddles(a: &Seen, a_lit: &[f32; 3], b: &Seen, b_lit: &[f32; 3]) -> bool {
    let geometric = a.3 != b.3 || a.2.dot(&b.2) < 0.999 || (a.0 - b.0).abs() > 0.02 * a.0.min(b.0);
    geometric || ((a.5 || b.5) && (0..3).any(|i| (a_lit[i] - b_lit[i]).abs() > EDGE_CONTRAST))
}

#[allow(clippy::too_many_arguments)]
fn render_rows(
    scene: &Scene,
    objects: &[Prepared<'_>],
    k: &Intrinsics,
    world_from_cam_rot: &Matrix3<f64>,
    origin: &Vector3<f64>,
    v0: usize,
    rgb: &mut [u8],
    depth: &mut [f32],
    class: &mut [u16],
    inst: &mut [u16],
    mut hits: Option<&mut [Hit]>,
) {
    let w = k.width as usize;
    let h = k.height as usize;
    let rays = Rays {
        scene,
        objects,
        k,
        lens: dynaflow_vision::camera::KannalaBrandt::from_camera_info(k),
        world_from_cam_rot,
        origin,
    };
    // Centre rays of a whole row (the ground truth: depth, class, flow anchor) and their
    // lit colours; the rows above and below decide which pixels straddle an edge.
    let centre_row = |v: usize| -> Vec<Seen> {
        let c = rays.candidates(v);
        (0..w).map(|u| rays.trace(&c, u as f64, v as f64)).collect()
    };
    let rows = depth.len() / w.max(1);
    // A row's centre rays with their lit colours, each traced and lit once.
    let traced_row = |v: usize| -> (Vec<Seen>, Vec<[f32; 3]>) {
        let seen = centre_row(v);
        let lit = seen.iter().map(lit).collect();
        (seen, lit)
    };
    let mut above = (v0 > 0).then(|| traced_row(v0 - 1));
    let mut current = traced_row(v0);
    for (row, depth_row) in depth.chunks_mut(w).enumerate() {
        let v = v0 + row;
        let below = (v + 1 < h).then(|| traced_row(v + 1));
        let candidates = rays.candidates(v);
        for (u, depth_px) in depth_row.iter_mut().enumerate() {
            let idx = row * w + u;
            let (Some(seen), Some(&centre)) = (current.0.get(u), current.1.get(u)) else { continue };
            let differs = |(r, l): &(Vec<Seen>, Vec<[f32; 3]>), i: usize| match (r.get(i), l.get(i)) {
                (Some(n), Some(nl)) => straddles(seen, &centre, n, nl),
                _ => false,
            };
            let edge = u.checked_sub(1).is_some_and(|l| differs(&current, l))
                || differs(&current, u + 1)
                || above.as_ref().is_some_and(|r| differs(r, u))
                || below.as_ref().is_some_and(|r| differs(r, u));
            // On an edge the colour integrates over the pixel like a real sensor:
            // SUPERSAMPLE^2 rays on a stratified grid (the centre one reused). Point sampling
            // would snap edges to whole pixels and hide sub-pixel motion from optical flow.
            let mut acc = centre;
            let mut n = 1.0;
            if edge {
                for (du, dv) in subsample_offsets() {
                    let s = lit(&rays.trace(&candidates, u as f64 + du, v as f64 + dv));
                    for i in 0..3 {
                        acc[i] += s[i];
                    }
                    n += 1.0;
                }
            }
            let px = acc.map(|a| (a / n * 255.0).round().clamp(0.0, 255.0) as u8);
            if let Some(dst) = rgb.get_mut(idx * 3..idx * 3 + 3) {
                dst.copy_from_slice(&px);
            }
            let (t, _, _, kind, hit, _) = *seen;
            *depth_px = t as f32;
            if let Kind::Person(i) = kind {
                if let Some(c) = class.get_mut(idx) {
                    *c = 1;
                }
                if let Some(c) = inst.get_mut(idx) {
                    *c = i + 1;
                }
            }
            if let Some(hh) = hits.as_deref_mut().and_then(|hh| hh.get_mut(idx)) {
                *hh = hit;
            }
        }
        match below {
            Some(b) if row + 1 < rows => above = Some(std::mem::replace(&mut current, b)),
            _ => break,
        }
    }
}
