//! A compact, exact binary encoding of a [`Message`]: what a graph edge between two machines
//! carries. Every field of every [`Body`] is written bit for bit (floats by their
//! bits, instance ids, class names, descriptors), so a decoded message has the digest of the
//! one encoded and a run split over machines gives the digests of the run in one process.
//!
//! Why one file of this size: one encoder and one decoder, each a `match` over every body,
//! kept side by side so that each field is read in the order it is written.
//!
//! Layout, little-endian: a version byte ([`VERSION`]), the header (`seq` u64, `stamp` f64,
//! `frame_id` string), the body's [`PortType`] tag (u8) and its fields. A string is a u32 byte
//! count and UTF-8; a sequence is a u64 count and its items; an optional value a flag byte (0, or
//! 1 and the value). Decoding checks every count
//! against the bytes left before allocating, so corrupt or truncated input is an error, never
//! a panic or a huge allocation.

use std::sync::Arc;

use nalgebra::{Point3, Quaternion, Translation3, UnitQuaternion};

use crate::{
    Body, CameraInfo, CulledKeyFrame, DepthImage, Descriptors, Detection, Detections, Header, Image, Isometry3,
    Keypoint, Keypoints, LabelReason, MapFeature, MapKeyFrame, MapKeypoint, MapObservation, MapPoint, Message,
    OctreeUpdate, PixelFormat, PointCloud, PointLabel, PointLabels, PortType, Pose, Scalars, SegmentationMask,
    SparseMap, StampedPose, StereoRig, Track, Tracks, Trajectory,
};
use crate::{ImuBatch, ImuCalibration, ImuSample, LensModel};

/// The encoding's version byte; a reader refuses any other.
pub const VERSION: u8 = 3;

/// Why bytes do not decode to a message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CodecError(pub String);

impl std::fmt::Display for CodecError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "not a dynaflow message: {}", self.0)
    }
}

impl std::error::Error for CodecError {}

/// The message as bytes.
pub fn encode(msg: &Message) -> Vec<u8> {
    let mut w = W(Vec::with_capacity(64 + body_size_hint(&msg.body)));
    w.u8(VERSION);
    w.u64(msg.header.seq);
    w.f64(msg.header.stamp);
    w.str(&msg.header.frame_id);
    w.u8(tag(msg.body.port_type()));
    body(&mut w, &msg.body);
    w.0
}

/// The message back from [`encode`]'s bytes (all of them: trailing bytes are an error).
pub fn decode(bytes: &[u8]) -> Result<Message, CodecError> {
    let mut r = R { buf: bytes, pos: 0 };
    let version = r.u8()?;
    if version != VERSION {
        return Err(CodecError(format!("encoding version {version}, this build reads {VERSION}")));
    }
    let header = Header { seq: r.u64()?, stamp: r.f64()?, frame_id: Arc::from(r.str()?) };
    let ty = r.u8()?;
    let body = read_body(&mut r, ty)?;
    if r.pos != bytes.len() {
        return Err(CodecError(format!("{} bytes left after the message", bytes.len() - r.pos)));
    }
    Ok(Message::new(header, body))
}

/// The body's tag is its type's index in [`PortType::ALL`] (a reordering there is a new
/// [`VERSION`]).
const TYPES: [PortType; PortType::ALL.len()] = PortType::ALL;

fn tag(ty: PortType) -> u8 {
    TYPES.iter().position(|t| *t == ty).map_or(u8::MAX, |i| i as u8)
}

/// Whether messages of `ty` can cross a machine boundary (every concrete payload type can;
/// `any` is not a payload).
pub fn encodable(ty: PortType) -> bool {
    TYPES.contains(&ty)
}

fn body_size_hint(b: &Body) -> usize {
    match b {
        Body::Image(i) => i.data.len(),
        Body::Depth(d) => 4 * d.data.len(),
        Body::Mask(m) => 2 * m.classes.len() * if m.instances.is_some() { 2 } else { 1 },
        _ => 256,
    }
}

struct W(Vec<u8>);

impl W {
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u16(&mut self, v: u16) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn len(&mut self, n: usize) {
        self.u64(n as u64);
    }
    fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }
    fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
    fn opt_f64(&mut self, v: Option<f64>) {
        match v {
            None => self.u8(0),
            Some(v) => {
                self.u8(1);
                self.f64(v);
            }
        }
    }
    fn f32s(&mut self, v: &[f32]) {
        for x in v {
            self.f32(*x);
        }
    }
    fn bytes(&mut self, v: &[u8]) {
        self.len(v.len());
        self.0.extend_from_slice(v);
    }
    fn str(&mut self, s: &str) {
        self.u32(u32::try_from(s.len()).unwrap_or(u32::MAX));
        self.0.extend_from_slice(&s.as_bytes()[..s.len().min(u32::MAX as usize)]);
    }
    fn iso(&mut self, iso: &Isometry3<f64>) {
        let t = iso.translation.vector;
        let q = iso.rotation.coords;
        for v in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
            self.f64(v);
        }
    }
    fn u16s(&mut self, v: &[u16]) {
        self.len(v.len());
        for x in v {
            self.u16(*x);
        }
    }
}

fn body(w: &mut W, b: &Body) {
    match b {
        Body::Image(i) => {
            w.u32(i.width);
            w.u32(i.height);
            w.u8(match i.format {
                PixelFormat::Rgb8 => 0,
                PixelFormat::Gray8 => 1,
            });
            w.bytes(&i.data);
        }
        Body::Depth(d) => {
            w.u32(d.width);
            w.u32(d.height);
            w.len(d.data.len());
            w.f32s(&d.data);
        }
        Body::CameraInfo(c) => {
            w.u32(c.width);
            w.u32(c.height);
            for v in [c.fx, c.fy, c.cx, c.cy].iter().chain(&c.distortion) {
                w.f64(*v);
            }
            w.u8(match c.model {
                LensModel::BrownConrady => 0,
                LensModel::KannalaBrandt => 1,
            });
        }
        Body::Keypoints(k) => {
            w.len(k.points.len());
            for p in &k.points {
                w.f32s(&[p.x, p.y, p.size, p.angle, p.response]);
                w.u8(p.octave);
            }
            match &k.descriptors {
                None => w.u8(0),
                Some(d) => {
                    w.u8(1);
                    w.len(d.bytes_per);
                    w.bytes(&d.data);
                }
            }
        }
        Body::Tracks(t) => {
            w.u64(t.prev_seq);
            w.len(t.tracks.len());
            for t in &t.tracks {
                w.u64(t.id);
                w.f32s(&[t.prev[0], t.prev[1], t.cur[0], t.cur[1], t.error]);
            }
        }
        Body::Detections(d) => {
            w.len(d.detections.len());
            for det in &d.detections {
                w.f32s(&det.bbox);
                w.u32(det.class_id);
                w.str(&det.label);
                w.f32(det.score);
            }
        }
        Body::Mask(m) => {
            w.u32(m.width);
            w.u32(m.height);
            w.u16s(&m.classes);
            match &m.instances {
                None => w.u8(0),
                Some(i) => {
                    w.u8(1);
                    w.u16s(i);
                }
            }
            w.len(m.class_names.len());
            for n in &m.class_names {
                w.str(n);
            }
        }
        Body::PointLabels(l) => {
            w.len(l.labels.len());
            for l in &l.labels {
                w.u32(l.index);
                w.u8(u8::from(l.dynamic));
                w.u8(l.reason as u8);
                w.f32s(&[l.score, l.at[0], l.at[1]]);
            }
        }
        Body::Pose(p) => w.iso(&p.world_from_cam),
        Body::Trajectory(t) => {
            w.len(t.poses.len());
            for p in &t.poses {
                w.f64(p.stamp);
                w.iso(&p.world_from_cam);
            }
        }
        Body::PointCloud(c) => {
            w.len(c.points.len());
            for p in &c.points {
                w.f32s(p);
            }
            match &c.colors {
                None => w.u8(0),
                Some(cs) => {
                    w.u8(1);
                    w.len(cs.len());
                    for c in cs {
                        w.0.extend_from_slice(c);
                    }
                }
            }
        }
        Body::OctreeUpdate(o) => {
            w.f32(o.resolution);
            w.len(o.occupied.len());
            for (p, c) in &o.occupied {
                w.f32s(p);
                w.u16(*c);
            }
            w.len(o.freed.len());
            for p in &o.freed {
                w.f32s(p);
            }
        }
        Body::Map(m) => map(w, m),
        Body::Scalars(s) => {
            w.len(s.values.len());
            for (k, v) in &s.values {
                w.str(k);
                w.f64(*v);
            }
        }
        Body::StereoRig(s) => w.f64(s.baseline),
        Body::Imu(b) => {
            let c = &b.calibration;
            for v in [
                c.gyro_noise_density,
                c.accel_noise_density,
                c.gyro_random_walk,
                c.accel_random_walk,
                c.rate_hz,
                c.gravity,
            ] {
                w.f64(v);
            }
            w.iso(&c.body_from_cam);
            w.len(b.samples.len());
            for s in &b.samples {
                w.f64(s.stamp);
                for v in s.gyro.iter().chain(s.accel.iter()) {
                    w.f64(*v);
                }
            }
        }
    }
}

fn map(w: &mut W, m: &SparseMap) {
    w.u32(m.map_id);
    w.len(m.keyframes.len());
    for k in &m.keyframes {
        w.u64(k.id);
        w.f64(k.stamp);
        w.iso(&k.world_from_cam);
    }
    w.len(m.points.len());
    for p in &m.points {
        w.u64(p.id);
        for v in p.position.coords.iter() {
            w.f64(*v);
        }
        w.0.extend_from_slice(&p.descriptor);
        w.u32(p.observations);
        w.u64(p.first_keyframe);
    }
    w.len(m.observations.len());
    for o in &m.observations {
        w.u64(o.keyframe);
        w.u64(o.point);
        w.f64(o.uv[0]);
        w.f64(o.uv[1]);
        w.opt_f64(o.depth);
        w.u8(o.octave);
    }
    w.len(m.removed.len());
    for r in &m.removed {
        w.u64(*r);
    }
    w.len(m.features.len());
    for f in &m.features {
        w.u64(f.keyframe);
        w.f64(f.uv[0]);
        w.f64(f.uv[1]);
        w.u8(f.octave);
        w.0.extend_from_slice(&f.descriptor);
    }
    w.len(m.keypoints.len());
    for k in &m.keypoints {
        w.u64(k.keyframe);
        w.f64(k.uv[0]);
        w.f64(k.uv[1]);
        w.u8(k.octave);
        w.opt_f64(k.depth);
        w.0.extend_from_slice(&k.descriptor);
        match k.point {
            None => w.u8(0),
            Some(p) => {
                w.u8(1);
                w.u64(p);
            }
        }
    }
    w.len(m.culled.len());
    for c in &m.culled {
        w.u64(c.id);
        w.u64(c.anchor);
        w.iso(&c.anchor_from_culled);
    }
}

struct R<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> R<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], CodecError> {
        let left = self.buf.len() - self.pos;
        if n > left {
            return Err(CodecError(format!("truncated: {n} bytes wanted at byte {}, {left} left", self.pos)));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    /// Fail unless `n` more bytes are there.
    fn need(&self, n: usize) -> Result<(), CodecError> {
        let left = self.buf.len() - self.pos;
        if n > left {
            return Err(CodecError(format!("truncated: {n} bytes wanted at byte {}, {left} left", self.pos)));
        }
        Ok(())
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], CodecError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    fn u8(&mut self) -> Result<u8, CodecError> {
        Ok(self.array::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, CodecError> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    fn u32(&mut self) -> Result<u32, CodecError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    fn u64(&mut self) -> Result<u64, CodecError> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    fn f32(&mut self) -> Result<f32, CodecError> {
        Ok(f32::from_bits(self.u32()?))
    }
    fn f64(&mut self) -> Result<f64, CodecError> {
        Ok(f64::from_bits(self.u64()?))
    }
    fn f64n<const N: usize>(&mut self) -> Result<[f64; N], CodecError> {
        let mut a = [0.0; N];
        for v in &mut a {
            *v = self.f64()?;
        }
        Ok(a)
    }
    fn f32n<const N: usize>(&mut self) -> Result<[f32; N], CodecError> {
        let mut a = [0.0; N];
        for v in &mut a {
            *v = self.f32()?;
        }
        Ok(a)
    }
    /// A count of items of at least `min_size` bytes each: never more than the bytes left.
    fn len(&mut self, min_size: usize) -> Result<usize, CodecError> {
        let n = self.u64()?;
        let left = (self.buf.len() - self.pos) as u64;
        if n.saturating_mul(min_size.max(1) as u64) > left {
            return Err(CodecError(format!("a count of {n} at byte {} is more than the {left} bytes left", self.pos)));
        }
        Ok(n as usize)
    }
    fn flag(&mut self) -> Result<bool, CodecError> {
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(CodecError(format!("flag byte {v} at byte {}", self.pos - 1))),
        }
    }
    fn opt_f64(&mut self) -> Result<Option<f64>, CodecError> {
        Ok(if self.flag()? { Some(self.f64()?) } else { None })
    }
    fn bytes(&mut self) -> Result<Vec<u8>, CodecError> {
        let n = self.len(1)?;
        Ok(self.take(n)?.to_vec())
    }
    fn str(&mut self) -> Result<&'a str, CodecError> {
        let n = self.u32()? as usize;
        let at = self.pos;
        std::str::from_utf8(self.take(n)?).map_err(|e| CodecError(format!("string at byte {at}: {e}")))
    }
    fn iso(&mut self) -> Result<Isometry3<f64>, CodecError> {
        let [x, y, z, qx, qy, qz, qw] = [0; 7].map(|_| self.f64()).map(|v| v.unwrap_or(f64::NAN));
        // The bits as written (no renormalisation), so the digest is unchanged.
        Ok(Isometry3::from_parts(
            Translation3::new(x, y, z),
            UnitQuaternion::new_unchecked(Quaternion::new(qw, qx, qy, qz)),
        ))
    }
    fn u16s(&mut self) -> Result<Vec<u16>, CodecError> {
        let n = self.len(2)?;
        (0..n).map(|_| self.u16()).collect()
    }
}

fn read_body(r: &mut R<'_>, tag: u8) -> Result<Body, CodecError> {
    let ty = *TYPES.get(tag as usize).ok_or_else(|| CodecError(format!("unknown payload type {tag}")))?;
    Ok(match ty {
        PortType::Image => {
            let (width, height) = (r.u32()?, r.u32()?);
            let format = match r.u8()? {
                0 => PixelFormat::Rgb8,
                1 => PixelFormat::Gray8,
                v => return Err(CodecError(format!("pixel format {v}"))),
            };
            Body::Image(Image { width, height, format, data: r.bytes()? })
        }
        PortType::Depth => {
            let (width, height) = (r.u32()?, r.u32()?);
            let n = r.len(4)?;
            Body::Depth(DepthImage { width, height, data: (0..n).map(|_| r.f32()).collect::<Result<_, _>>()? })
        }
        PortType::CameraInfo => {
            let (width, height) = (r.u32()?, r.u32()?);
            r.need(72)?;
            let [fx, fy, cx, cy] = [0; 4].map(|_| r.f64().unwrap_or(f64::NAN));
            let distortion = [0; 5].map(|_| r.f64().unwrap_or(f64::NAN));
            let model = match r.u8()? {
                0 => LensModel::BrownConrady,
                1 => LensModel::KannalaBrandt,
                v => return Err(CodecError(format!("lens model {v}"))),
            };
            Body::CameraInfo(CameraInfo { width, height, fx, fy, cx, cy, distortion, model })
        }
        PortType::Keypoints => {
            let n = r.len(21)?;
            let mut points = Vec::with_capacity(n);
            for _ in 0..n {
                let [x, y, size, angle, response] = r.f32n()?;
                points.push(Keypoint { x, y, size, angle, response, octave: r.u8()? });
            }
            let descriptors = if r.flag()? {
                let bytes_per = r.len(0)?;
                Some(Descriptors { bytes_per, data: r.bytes()? })
            } else {
                None
            };
            Body::Keypoints(Keypoints { points, descriptors })
        }
        PortType::Tracks => {
            let prev_seq = r.u64()?;
            let n = r.len(28)?;
            let mut tracks = Vec::with_capacity(n);
            for _ in 0..n {
                let id = r.u64()?;
                let [px, py, cx, cy, error] = r.f32n()?;
                tracks.push(Track { id, prev: [px, py], cur: [cx, cy], error });
            }
            Body::Tracks(Tracks { prev_seq, tracks })
        }
        PortType::Detections => {
            let n = r.len(28)?;
            let mut detections = Vec::with_capacity(n);
            for _ in 0..n {
                let bbox = r.f32n()?;
                let class_id = r.u32()?;
                let label = Arc::from(r.str()?);
                detections.push(Detection { bbox, class_id, label, score: r.f32()? });
            }
            Body::Detections(Detections { detections })
        }
        PortType::Mask => {
            let (width, height) = (r.u32()?, r.u32()?);
            let classes = r.u16s()?;
            let instances = if r.flag()? { Some(r.u16s()?) } else { None };
            let n = r.len(4)?;
            let class_names = (0..n).map(|_| r.str().map(Arc::from)).collect::<Result<_, _>>()?;
            Body::Mask(SegmentationMask { width, height, classes, instances, class_names })
        }
        PortType::PointLabels => {
            let n = r.len(18)?;
            let mut labels = Vec::with_capacity(n);
            for _ in 0..n {
                let index = r.u32()?;
                let dynamic = r.flag()?;
                let reason = match r.u8()? {
                    0 => LabelReason::Static,
                    1 => LabelReason::Epipolar,
                    2 => LabelReason::Semantic,
                    3 => LabelReason::Flow,
                    4 => LabelReason::Depth,
                    v => return Err(CodecError(format!("label reason {v}"))),
                };
                let [score, x, y] = r.f32n()?;
                labels.push(PointLabel { index, dynamic, reason, score, at: [x, y] });
            }
            Body::PointLabels(PointLabels { labels })
        }
        PortType::Pose => Body::Pose(Pose { world_from_cam: checked_iso(r)? }),
        PortType::Trajectory => {
            let n = r.len(64)?;
            let mut poses = Vec::with_capacity(n);
            for _ in 0..n {
                let stamp = r.f64()?;
                poses.push(StampedPose { stamp, world_from_cam: checked_iso(r)? });
            }
            Body::Trajectory(Trajectory { poses })
        }
        PortType::PointCloud => {
            let n = r.len(12)?;
            let points = (0..n).map(|_| r.f32n::<3>()).collect::<Result<_, _>>()?;
            let colors = if r.flag()? {
                let m = r.len(3)?;
                Some((0..m).map(|_| r.array::<3>()).collect::<Result<_, _>>()?)
            } else {
                None
            };
            Body::PointCloud(PointCloud { points, colors })
        }
        PortType::OctreeUpdate => {
            let resolution = r.f32()?;
            let n = r.len(14)?;
            let occupied = (0..n).map(|_| Ok((r.f32n::<3>()?, r.u16()?))).collect::<Result<_, CodecError>>()?;
            let m = r.len(12)?;
            let freed = (0..m).map(|_| r.f32n::<3>()).collect::<Result<_, _>>()?;
            Body::OctreeUpdate(OctreeUpdate { resolution, occupied, freed })
        }
        PortType::Map => Body::Map(read_map(r)?),
        PortType::Scalars => {
            let n = r.len(12)?;
            let values = (0..n).map(|_| Ok((Arc::from(r.str()?), r.f64()?))).collect::<Result<_, CodecError>>()?;
            Body::Scalars(Scalars { values })
        }
        PortType::StereoRig => Body::StereoRig(StereoRig { baseline: r.f64()? }),
        PortType::Imu => {
            let [gyro_noise_density, accel_noise_density, gyro_random_walk, accel_random_walk, rate_hz, gravity] =
                r.f64n::<6>()?;
            let body_from_cam = checked_iso(r)?;
            let calibration = ImuCalibration {
                gyro_noise_density,
                accel_noise_density,
                gyro_random_walk,
                accel_random_walk,
                rate_hz,
                body_from_cam,
                gravity,
            };
            let n = r.len(56)?;
            let samples = (0..n)
                .map(|_| {
                    let stamp = r.f64()?;
                    let [a, b, c, d, e, g] = r.f64n::<6>()?;
                    Ok(ImuSample {
                        stamp,
                        gyro: nalgebra::Vector3::new(a, b, c),
                        accel: nalgebra::Vector3::new(d, e, g),
                    })
                })
                .collect::<Result<_, CodecError>>()?;
            Body::Imu(ImuBatch { samples, calibration })
        }
        PortType::Any => return Err(CodecError("payload type `any`".into())),
    })
}

/// [`R::iso`], failing on truncation (its fields read as NaN there otherwise).
fn checked_iso(r: &mut R<'_>) -> Result<Isometry3<f64>, CodecError> {
    r.need(56)?;
    r.iso()
}

fn read_map(r: &mut R<'_>) -> Result<SparseMap, CodecError> {
    let map_id = r.u32()?;
    let n = r.len(72)?;
    let mut keyframes = Vec::with_capacity(n);
    for _ in 0..n {
        let (id, stamp) = (r.u64()?, r.f64()?);
        keyframes.push(MapKeyFrame { id, stamp, world_from_cam: checked_iso(r)? });
    }
    let n = r.len(76)?;
    let mut points = Vec::with_capacity(n);
    for _ in 0..n {
        let id = r.u64()?;
        let position = Point3::new(r.f64()?, r.f64()?, r.f64()?);
        let descriptor = r.array::<32>()?;
        points.push(MapPoint { id, position, descriptor, observations: r.u32()?, first_keyframe: r.u64()? });
    }
    let n = r.len(34)?;
    let mut observations = Vec::with_capacity(n);
    for _ in 0..n {
        let (keyframe, point) = (r.u64()?, r.u64()?);
        let uv = [r.f64()?, r.f64()?];
        observations.push(MapObservation { keyframe, point, uv, depth: r.opt_f64()?, octave: r.u8()? });
    }
    let n = r.len(8)?;
    let removed = (0..n).map(|_| r.u64()).collect::<Result<_, _>>()?;
    let n = r.len(57)?;
    let mut features = Vec::with_capacity(n);
    for _ in 0..n {
        let keyframe = r.u64()?;
        let uv = [r.f64()?, r.f64()?];
        features.push(MapFeature { keyframe, uv, octave: r.u8()?, descriptor: r.array::<32>()? });
    }
    let n = r.len(59)?;
    let mut keypoints = Vec::with_capacity(n);
    for _ in 0..n {
        let keyframe = r.u64()?;
        let uv = [r.f64()?, r.f64()?];
        let octave = r.u8()?;
        let depth = r.opt_f64()?;
        let descriptor = r.array::<32>()?;
        let point = if r.flag()? { Some(r.u64()?) } else { None };
        keypoints.push(MapKeypoint { keyframe, uv, octave, depth, descriptor, point });
    }
    let n = r.len(72)?;
    let mut culled = Vec::with_capacity(n);
    for _ in 0..n {
        let (id, anchor) = (r.u64()?, r.u64()?);
        culled.push(CulledKeyFrame { id, anchor, anchor_from_culled: checked_iso(r)? });
    }
    Ok(SparseMap { map_id, keyframes, points, observations, removed, features, keypoints, culled })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn iso(a: f64) -> Isometry3<f64> {
        Isometry3::new(nalgebra::Vector3::new(a, -2.0 * a, 0.3), nalgebra::Vector3::new(0.1, a, -0.2))
    }

    /// One message of every payload type, with the awkward values (NaN, -0.0, optional parts
    /// present, non-ASCII names).
    pub(crate) fn every_body() -> Vec<Body> {
        let desc = [7u8; 32];
        vec![
            Body::Image(Image { width: 3, height: 2, format: PixelFormat::Rgb8, data: (0..18).collect() }),
            Body::Image(Image { width: 2, height: 1, format: PixelFormat::Gray8, data: vec![0, 255] }),
            Body::Depth(DepthImage { width: 2, height: 2, data: vec![0.0, f32::NAN, -0.0, 1.25] }),
            Body::CameraInfo(CameraInfo {
                width: 640,
                height: 480,
                fx: 535.4,
                fy: 539.2,
                cx: 320.1,
                cy: 247.6,
                distortion: [0.1, -0.2, 0.0, 1e-9, f64::MIN_POSITIVE],
                model: LensModel::BrownConrady,
            }),
            Body::CameraInfo(CameraInfo {
                width: 512,
                height: 512,
                fx: 190.97,
                fy: 190.97,
                cx: 254.93,
                cy: 256.90,
                distortion: [0.0035, 0.0007, -0.0021, 0.0002, 0.0],
                model: LensModel::KannalaBrandt,
            }),
            Body::Keypoints(Keypoints {
                points: vec![Keypoint { x: 1.5, y: 2.25, size: 31.0, angle: -1.0, response: 1e-3, octave: 3 }],
                descriptors: Some(Descriptors { bytes_per: 32, data: desc.to_vec() }),
            }),
            Body::Keypoints(Keypoints { points: vec![], descriptors: None }),
            Body::Tracks(Tracks {
                prev_seq: 9,
                tracks: vec![Track { id: u64::MAX, prev: [1.0, 2.0], cur: [f32::NAN, 4.0], error: 0.5 }],
            }),
            Body::Detections(Detections {
                detections: vec![Detection {
                    bbox: [1.0, 2.0, 30.0, 40.0],
                    class_id: 0,
                    label: "persön".into(),
                    score: 0.9,
                }],
            }),
            Body::Mask(SegmentationMask {
                width: 2,
                height: 1,
                classes: vec![0, 15],
                instances: Some(vec![0, 3]),
                class_names: vec!["background".into(), "person".into()],
            }),
            Body::PointLabels(PointLabels {
                labels: vec![PointLabel {
                    index: 4,
                    dynamic: true,
                    reason: LabelReason::Epipolar,
                    score: 0.41,
                    at: [f32::NAN, 1.0],
                }],
            }),
            Body::Pose(Pose { world_from_cam: iso(0.5) }),
            Body::Trajectory(Trajectory {
                poses: vec![
                    StampedPose { stamp: 1.0, world_from_cam: iso(0.1) },
                    StampedPose { stamp: 1.1, world_from_cam: iso(0.2) },
                ],
            }),
            Body::PointCloud(PointCloud { points: vec![[1.0, 2.0, 3.0]], colors: Some(vec![[1, 2, 3]]) }),
            Body::OctreeUpdate(OctreeUpdate {
                resolution: 0.05,
                occupied: vec![([0.1, 0.2, 0.3], 15)],
                freed: vec![[1.0, 1.0, 1.0]],
            }),
            Body::Map(SparseMap {
                map_id: 2,
                keyframes: vec![MapKeyFrame { id: 1, stamp: 0.5, world_from_cam: iso(0.3) }],
                points: vec![MapPoint {
                    id: 5,
                    position: Point3::new(1.0, 2.0, 3.0),
                    descriptor: desc,
                    observations: 3,
                    first_keyframe: 1,
                }],
                observations: vec![MapObservation { keyframe: 1, point: 5, uv: [1.0, 2.0], depth: None, octave: 1 }],
                removed: vec![4, 6],
                features: vec![MapFeature { keyframe: 1, uv: [3.0, 4.0], octave: 0, descriptor: desc }],
                keypoints: vec![MapKeypoint {
                    keyframe: 1,
                    uv: [5.0, 6.0],
                    octave: 2,
                    depth: Some(1.5),
                    descriptor: desc,
                    point: Some(5),
                }],
                culled: vec![CulledKeyFrame { id: 0, anchor: 1, anchor_from_culled: iso(0.1) }],
            }),
            Body::Scalars(Scalars { values: vec![("ate".into(), 0.01), ("nan".into(), f64::NAN)] }),
            Body::StereoRig(StereoRig { baseline: 0.12 }),
            Body::Imu(ImuBatch {
                samples: vec![
                    ImuSample {
                        stamp: 0.005,
                        gyro: nalgebra::Vector3::new(0.1, -0.2, 0.3),
                        accel: nalgebra::Vector3::new(0.0, 0.1, 9.8),
                    },
                    ImuSample {
                        stamp: 0.01,
                        gyro: nalgebra::Vector3::new(0.2, -0.1, f64::NAN),
                        accel: nalgebra::Vector3::new(-0.1, 0.2, 9.7),
                    },
                ],
                calibration: ImuCalibration { body_from_cam: iso(0.2), ..ImuCalibration::adis16448() },
            }),
        ]
    }

    #[test]
    fn every_payload_type_round_trips_with_its_digest() {
        let bodies = every_body();
        let covered: std::collections::BTreeSet<u8> = bodies.iter().map(|b| tag(b.port_type())).collect();
        assert_eq!(covered.len(), TYPES.len(), "a test message of every payload type");
        for (i, b) in bodies.into_iter().enumerate() {
            let msg = Message::new(Header { seq: i as u64, stamp: 0.25 * i as f64, frame_id: "cämera".into() }, b);
            let bytes = encode(&msg);
            let back = decode(&bytes).unwrap_or_else(|e| panic!("{:?}: {e}", msg.body.port_type()));
            assert_eq!(back.digest(), msg.digest(), "{:?}", msg.body.port_type());
            // Bit for bit: encoding the decoded message gives the same bytes (NaNs included,
            // which `==` would not show).
            assert_eq!(encode(&back), bytes, "{:?}", msg.body.port_type());
        }
    }

    #[test]
    fn truncated_or_corrupt_bytes_are_errors_not_panics() {
        for b in every_body() {
            let msg = Message::new(Header { seq: 1, stamp: 0.0, frame_id: "c".into() }, b);
            let bytes = encode(&msg);
            for n in 0..bytes.len() {
                assert!(decode(&bytes[..n]).is_err(), "{:?} cut to {n} of {} bytes", msg.body.port_type(), bytes.len());
            }
            let mut longer = bytes.clone();
            longer.push(0);
            assert!(decode(&longer).unwrap_err().0.contains("left after"));
            // Every byte flipped in turn: an error or some message, never a panic.
            for i in 0..bytes.len() {
                let mut bad = bytes.clone();
                bad[i] ^= 0xff;
                let _ = decode(&bad);
            }
        }
        let mut huge = encode(&Message::new(
            Header { seq: 1, stamp: 0.0, frame_id: "c".into() },
            Body::Depth(DepthImage { width: 1, height: 1, data: vec![1.0] }),
        ));
        // The depth's sample count (after version, header, tag, width and height) set to 2^60.
        let at = 1 + 8 + 8 + 4 + 1 + 1 + 8;
        huge[at..at + 8].copy_from_slice(&(1u64 << 60).to_le_bytes());
        assert!(decode(&huge).unwrap_err().0.contains("more than"), "no allocation of a corrupt count");
        let other = VERSION + 1;
        assert!(decode(&[other]).unwrap_err().0.contains(&format!("version {other}")));
    }
}
