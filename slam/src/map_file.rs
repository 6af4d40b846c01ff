//! A saved map: every key frame (pose, keypoints with descriptor, depth and point, spanning-tree
//! parent, loop edges) and every point, with the id of the vocabulary its words come from. The
//! covisibility graph and the key-frame database are rebuilt from it on loading.
//!
//! Layout (little-endian): `b"DFMAP\0\0\0"`, format version `u32`, the vocabulary id (16 ASCII
//! hex digits), map id `u32`, key-frame count `u32`, point count `u32`; per point: id `u64`,
//! position 3 x `f64`, descriptor 32 bytes, first key frame `u64`; per key frame: id `u64`,
//! stamp `f64`, pose (translation 3 x `f64`, quaternion i j k w 4 x `f64`), parent `u64`
//! (`u64::MAX`: none), loop count `u32` and ids `u64`, keypoint count `u32` and per keypoint u
//! `f64`, v `f64`, octave `u8`, depth `f64` (0: none), descriptor 32 bytes, point `u64`
//! (`u64::MAX`: none); then an FNV-1a checksum `u64` of everything before it.

use std::path::Path;
use std::sync::Arc;

use dynaflow_vision::camera::Pinhole;
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};

use crate::bow::Vocabulary;
use crate::keyframe_map::KeyFrameMap;
use crate::map::{MapKeyFrame, MapKeypoint, MapPoint, SparseMap};

const MAGIC: &[u8; 8] = b"DFMAP\0\0\0";
/// Version of the layout written.
pub const MAP_FORMAT_VERSION: u32 = 1;

/// Largest coordinate of a stored point or key frame, metres: a bound far beyond any map a
/// camera builds (1000 km), so that a damaged or crafted file cannot carry values that overflow
/// the optimisers. Chosen, not from a source.
const MAX_COORDINATE_M: f64 = 1e6;
/// Pyramid levels a keypoint may sit on: ORB-SLAM2 uses 8; the octave is a `u8` index into
/// per-level tables, so anything at or beyond this is refused.
const MAX_OCTAVES: usize = 32;
/// Largest keypoint coordinate, pixels (no camera has an image this large).
const MAX_IMAGE_PX: f64 = 65_536.0;

/// Why a map file could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum MapFileError {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// No map header.
    #[error("{path}: not a dynaflow map file")]
    NotAMap {
        /// The file.
        path: String,
    },
    /// A format version this build does not read.
    #[error("{path}: map format version {found}, this build reads {MAP_FORMAT_VERSION}")]
    Version {
        /// The file.
        path: String,
        /// Its version.
        found: u32,
    },
    /// Contents that cannot be a map.
    #[error("{path}: truncated or corrupt ({what})")]
    Corrupt {
        /// The file.
        path: String,
        /// What is wrong.
        what: String,
    },
    /// The checksum does not match.
    #[error(
        "{path}: checksum {found:016x} does not match the stored {expected:016x} (the file is damaged or truncated)"
    )]
    Checksum {
        /// The file.
        path: String,
        /// The checksum of its contents.
        found: u64,
        /// The checksum it stores.
        expected: u64,
    },
    /// Made with another vocabulary.
    #[error(
        "{path}: the map was built with vocabulary {map}, but this run uses vocabulary {run}: words differ between vocabularies, so its key frames cannot be recognised (load the map with the vocabulary it was saved with)"
    )]
    Vocabulary {
        /// The file.
        path: String,
        /// The vocabulary the map was built with.
        map: String,
        /// The run's.
        run: String,
    },
    /// No key frame in it.
    #[error(
        "{path}: the map holds no key frame (saved by a run whose tracker never started a map): there is nothing to localise in"
    )]
    Empty {
        /// The file.
        path: String,
    },
}

/// 64-bit FNV-1a.
fn fnv(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The file's bytes for `map` (written as a new file renamed into place by the caller,
/// `dynaflow_engine::files::write_atomic`).
pub fn encode(map: &KeyFrameMap) -> Vec<u8> {
    let mut b: Vec<u8> = Vec::new();
    b.extend_from_slice(MAGIC);
    b.extend_from_slice(&MAP_FORMAT_VERSION.to_le_bytes());
    let id = map.vocabulary().id();
    let mut id16 = [b'0'; 16];
    for (d, s) in id16.iter_mut().zip(id.bytes()) {
        *d = s;
    }
    b.extend_from_slice(&id16);
    b.extend_from_slice(&map.map_id.to_le_bytes());
    b.extend_from_slice(&(map.kfs.len() as u32).to_le_bytes());
    b.extend_from_slice(&(map.points.len() as u32).to_le_bytes());
    let f = |b: &mut Vec<u8>, v: f64| b.extend_from_slice(&v.to_le_bytes());
    let u = |b: &mut Vec<u8>, v: u64| b.extend_from_slice(&v.to_le_bytes());
    for p in map.points.values() {
        u(&mut b, p.id);
        for v in p.position.coords.iter() {
            f(&mut b, *v);
        }
        b.extend_from_slice(&p.descriptor);
        u(&mut b, p.first_keyframe);
    }
    for k in map.kfs.values() {
        u(&mut b, k.info.id);
        f(&mut b, k.info.stamp);
        let t = k.info.world_from_cam.translation.vector;
        let q = k.info.world_from_cam.rotation.coords;
        for v in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
            f(&mut b, v);
        }
        u(&mut b, k.parent.unwrap_or(u64::MAX));
        b.extend_from_slice(&(k.loops.len() as u32).to_le_bytes());
        for l in &k.loops {
            u(&mut b, *l);
        }
        b.extend_from_slice(&(k.keypoints.len() as u32).to_le_bytes());
        for kp in &k.keypoints {
            f(&mut b, kp.uv[0]);
            f(&mut b, kp.uv[1]);
            b.push(kp.octave);
            f(&mut b, kp.depth.unwrap_or(0.0));
            b.extend_from_slice(&kp.descriptor);
            u(&mut b, kp.point.unwrap_or(u64::MAX));
        }
    }
    let sum = fnv(&b);
    b.extend_from_slice(&sum.to_le_bytes());
    b
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
    path: &'a str,
}

impl Reader<'_> {
    fn take(&mut self, n: usize, what: &str) -> Result<&[u8], MapFileError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len()).ok_or_else(|| MapFileError::Corrupt {
            path: self.path.into(),
            what: format!("it ends inside {what} at byte {}", self.at),
        })?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self, what: &str) -> Result<u32, MapFileError> {
        let s = self.take(4, what)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    fn u64(&mut self, what: &str) -> Result<u64, MapFileError> {
        let mut a = [0u8; 8];
        a.copy_from_slice(self.take(8, what)?);
        Ok(u64::from_le_bytes(a))
    }
    fn f64(&mut self, what: &str) -> Result<f64, MapFileError> {
        let v = f64::from_bits(self.u64(what)?);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(MapFileError::Corrupt { path: self.path.into(), what: format!("{what} is not finite") })
        }
    }
    fn descriptor(&mut self, what: &str) -> Result<[u8; 32], MapFileError> {
        let mut d = [0u8; 32];
        d.copy_from_slice(self.take(32, what)?);
        Ok(d)
    }
}

/// Read a map saved by [`save`] for a camera `cam` of `width` x `height` with `vocabulary`,
/// which must be the one the map was saved with. Every inconsistency is an error naming the
/// file.
pub fn load(
    path: &Path,
    cam: Pinhole,
    width: f64,
    height: f64,
    scale_factor: f64,
    vocabulary: Arc<Vocabulary>,
) -> Result<KeyFrameMap, MapFileError> {
    let p = path.display().to_string();
    let b = std::fs::read(path).map_err(|source| MapFileError::Io { path: p.clone(), source })?;
    if b.len() < MAGIC.len() || &b[..MAGIC.len()] != MAGIC {
        return Err(MapFileError::NotAMap { path: p });
    }
    if b.len() < MAGIC.len() + 4 + 16 + 12 + 8 {
        return Err(MapFileError::Corrupt { path: p, what: format!("{} bytes is shorter than the header", b.len()) });
    }
    let version = u32::from_le_bytes([b[8], b[9], b[10], b[11]]);
    if version != MAP_FORMAT_VERSION {
        return Err(MapFileError::Version { path: p, found: version });
    }
    let (body, tail) = b.split_at(b.len() - 8);
    let mut t = [0u8; 8];
    t.copy_from_slice(tail);
    let (found, expected) = (fnv(body), u64::from_le_bytes(t));
    if found != expected {
        return Err(MapFileError::Checksum { path: p, found, expected });
    }
    let map_vocabulary = String::from_utf8_lossy(&body[12..28]).into_owned();
    if map_vocabulary != vocabulary.id() {
        return Err(MapFileError::Vocabulary { path: p, map: map_vocabulary, run: vocabulary.id() });
    }
    let mut r = Reader { b: body, at: 28, path: &p };
    let map_id = r.u32("the map id")?;
    let nk = r.u32("the key-frame count")? as usize;
    let np = r.u32("the point count")? as usize;
    let mut batch = SparseMap { map_id, ..SparseMap::default() };
    for _ in 0..np {
        let id = r.u64("a point")?;
        let position = Point3::new(r.f64("a point")?, r.f64("a point")?, r.f64("a point")?);
        let descriptor = r.descriptor("a point")?;
        let first_keyframe = r.u64("a point")?;
        batch.points.push(MapPoint { id, position, descriptor, observations: 0, first_keyframe });
    }
    let corrupt = |what: String| MapFileError::Corrupt { path: p.clone(), what };
    let mut point_ids = std::collections::HashSet::new();
    for pt in &batch.points {
        if !point_ids.insert(pt.id) {
            return Err(corrupt(format!("point {} is stored twice", pt.id)));
        }
        if pt.position.coords.iter().any(|c| c.abs() > MAX_COORDINATE_M) {
            return Err(corrupt(format!("point {} lies {:e} m from the origin", pt.id, pt.position.coords.amax())));
        }
    }
    let mut map = KeyFrameMap::new(cam, width, height, scale_factor, vocabulary);
    map.switch_map(map_id);
    map.apply_refinements(&batch);
    let mut seen = std::collections::HashSet::new();
    let mut parents = std::collections::HashMap::new();
    for _ in 0..nk {
        let id = r.u64("a key frame")?;
        let stamp = r.f64("a key frame")?;
        let v: Vec<f64> = (0..7).map(|_| r.f64("a key frame's pose")).collect::<Result<_, _>>()?;
        let q = Quaternion::new(v[6], v[3], v[4], v[5]);
        if (q.norm() - 1.0).abs() > 1e-6 {
            return Err(MapFileError::Corrupt { path: p.clone(), what: format!("key frame {id}: not a rotation") });
        }
        if v[..3].iter().any(|c| c.abs() > MAX_COORDINATE_M) {
            return Err(corrupt(format!(
                "key frame {id} lies {:e} m from the origin",
                v[0].abs().max(v[1].abs()).max(v[2].abs())
            )));
        }
        if !seen.insert(id) {
            return Err(corrupt(format!("key frame {id} is stored twice")));
        }
        let pose = Isometry3::from_parts(Translation3::new(v[0], v[1], v[2]), UnitQuaternion::from_quaternion(q));
        let parent = r.u64("a key frame")?;
        let nl = r.u32("a key frame's loops")? as usize;
        let loops: Vec<u64> = (0..nl).map(|_| r.u64("a key frame's loops")).collect::<Result<_, _>>()?;
        let nkp = r.u32("a key frame's keypoints")? as usize;
        let mut kf = SparseMap {
            map_id,
            keyframes: vec![MapKeyFrame { id, stamp, world_from_cam: pose }],
            ..SparseMap::default()
        };
        for _ in 0..nkp {
            let uv = [r.f64("a keypoint")?, r.f64("a keypoint")?];
            let octave = r.take(1, "a keypoint")?[0];
            let depth = r.f64("a keypoint")?;
            let descriptor = r.descriptor("a keypoint")?;
            let point = r.u64("a keypoint")?;
            if usize::from(octave) >= MAX_OCTAVES {
                return Err(corrupt(format!("key frame {id}: a keypoint on pyramid level {octave}")));
            }
            if uv.iter().any(|c| !(-1.0..=MAX_IMAGE_PX).contains(c)) {
                return Err(corrupt(format!("key frame {id}: a keypoint at ({}, {})", uv[0], uv[1])));
            }
            if !(0.0..=MAX_COORDINATE_M).contains(&depth) {
                return Err(corrupt(format!("key frame {id}: a keypoint at depth {depth} m")));
            }
            if point != u64::MAX && !point_ids.contains(&point) {
                return Err(corrupt(format!(
                    "key frame {id}: a keypoint of point {point}, which the map does not hold"
                )));
            }
            kf.keypoints.push(MapKeypoint {
                keyframe: id,
                uv,
                octave,
                depth: (depth > 0.0).then_some(depth),
                descriptor,
                point: (point != u64::MAX).then_some(point),
            });
        }
        parents.insert(id, parent);
        if kf.keypoints.is_empty() {
            continue;
        }
        if let Some((k, bow)) = map.add_keyframe(&kf) {
            map.db.add(k, bow);
        }
        if let Some(k) = map.kfs.get_mut(&id) {
            k.parent = (parent != u64::MAX).then_some(parent);
            k.loops = loops.into_iter().collect();
        }
    }
    if r.at != body.len() {
        let extra = body.len() - r.at;
        return Err(MapFileError::Corrupt { path: p.clone(), what: format!("{extra} bytes after the last key frame") });
    }
    // The spanning tree: every parent a key frame of the map, and no cycle.
    for (&id, &parent) in &parents {
        if parent != u64::MAX && !parents.contains_key(&parent) {
            return Err(corrupt(format!("key frame {id} has parent {parent}, which the map does not hold")));
        }
        let (mut at, mut steps) = (parent, 0usize);
        while at != u64::MAX {
            steps += 1;
            if steps > parents.len() {
                return Err(corrupt(format!("key frame {id}'s parents form a cycle")));
            }
            at = parents.get(&at).copied().unwrap_or(u64::MAX);
        }
    }
    if map.kfs.is_empty() {
        return Err(MapFileError::Empty { path: p });
    }
    Ok(map)
}
