//! ROS 2 messages out: a CDR writer (little-endian plain CDR, the encapsulation rmw writes for
//! ROS 2 messages: 4 header bytes `00 01 00 00`, each primitive aligned to its size from the
//! end of the header) and the ROS 2 types dynaflow records, each from plain values. The
//! definitions recorded beside them are [`crate::known`]'s, so what is written here is decoded
//! back by this crate's own reader in the tests, and by the `rosbags` package in the
//! integration tests.

use dynaflow_msg::{CameraInfo, DepthImage, Image, LensModel, PixelFormat};
use nalgebra::Isometry3;

/// A CDR message being written.
#[derive(Debug)]
pub struct Cdr {
    buf: Vec<u8>,
}

impl Default for Cdr {
    fn default() -> Self {
        Self::new()
    }
}

impl Cdr {
    /// An empty little-endian CDR message (its encapsulation header written).
    pub fn new() -> Self {
        Self { buf: vec![0x00, 0x01, 0x00, 0x00] }
    }

    fn align(&mut self, n: usize) {
        let rel = self.buf.len() - 4;
        let pad = (n - rel % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    /// A `uint8` (or `bool`, `byte`).
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// A `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `float32`.
    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A `string`: its length with the terminating NUL, the bytes, the NUL.
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// An unbounded sequence's length.
    pub fn seq_len(&mut self, n: usize) {
        self.u32(n as u32);
    }

    /// A `uint8[]`, filled by `fill` with exactly `n` bytes.
    pub fn bytes_with(&mut self, n: usize, fill: impl FnOnce(&mut Vec<u8>)) {
        self.seq_len(n);
        let start = self.buf.len();
        self.buf.reserve(n);
        fill(&mut self.buf);
        debug_assert_eq!(self.buf.len() - start, n, "bytes_with wrote another length than it declared");
    }

    /// The serialised message.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// A stamp in seconds as ROS 2's `builtin_interfaces/Time` (`sec`, `nanosec`): the decimal
/// the double stands for (its shortest representation, rounded to nanoseconds), so a stamp
/// read from `1305031102.175304` is written as 175304000 ns, the inverse of
/// [`crate::sensor::seconds`] (the double itself is 1305031102.175303936...). Negative and
/// non-finite stamps are written as 0.
pub fn time(stamp: f64) -> (i32, u32) {
    if !(stamp.is_finite() && stamp > 0.0) {
        return (0, 0);
    }
    let text = format!("{stamp}");
    let (whole, frac) = text.split_once('.').unwrap_or((&text, ""));
    let mut sec: i64 = whole.parse().unwrap_or(0);
    let digits: String = frac.chars().chain(std::iter::repeat('0')).take(10).collect();
    let tenth = digits.as_bytes()[9] - b'0';
    let mut ns: i64 = digits[..9].parse().unwrap_or(0) + i64::from(tenth >= 5);
    if ns == 1_000_000_000 {
        sec += 1;
        ns = 0;
    }
    (sec.min(i64::from(i32::MAX)) as i32, ns as u32)
}

/// `std_msgs/Header`.
pub fn header(w: &mut Cdr, stamp: f64, frame: &str) {
    let (sec, nanosec) = time(stamp);
    w.i32(sec);
    w.u32(nanosec);
    w.string(frame);
}

fn pose(w: &mut Cdr, p: &Isometry3<f64>) {
    let t = p.translation.vector;
    let q = p.rotation.coords;
    for v in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
        w.f64(v);
    }
}

/// `sensor_msgs/msg/Image` of a colour (`rgb8`) or grey (`mono8`) image.
pub fn image(stamp: f64, frame: &str, img: &Image) -> Vec<u8> {
    let (encoding, channels) = match img.format {
        PixelFormat::Rgb8 => ("rgb8", 3),
        PixelFormat::Gray8 => ("mono8", 1),
    };
    raw_image(stamp, frame, img.width, img.height, encoding, img.width * channels, |b| b.extend_from_slice(&img.data))
}

/// `sensor_msgs/msg/Image` of a depth image: `32FC1`, metres (REP 118).
pub fn depth_image(stamp: f64, frame: &str, d: &DepthImage) -> Vec<u8> {
    raw_image(stamp, frame, d.width, d.height, "32FC1", d.width * 4, |b| {
        for v in &d.data {
            b.extend_from_slice(&v.to_le_bytes());
        }
    })
}

/// `sensor_msgs/msg/Image` with `height * step` bytes from `fill`.
pub fn raw_image(
    stamp: f64,
    frame: &str,
    width: u32,
    height: u32,
    encoding: &str,
    step: u32,
    fill: impl FnOnce(&mut Vec<u8>),
) -> Vec<u8> {
    let mut w = Cdr::new();
    header(&mut w, stamp, frame);
    w.u32(height);
    w.u32(width);
    w.string(encoding);
    w.u8(0); // is_bigendian
    w.u32(step);
    w.bytes_with(step as usize * height as usize, fill);
    w.finish()
}

/// `sensor_msgs/msg/CompressedImage`; `format` as image_transport writes it (`jpeg`, `png`).
pub fn compressed_image(stamp: f64, frame: &str, format: &str, data: &[u8]) -> Vec<u8> {
    let mut w = Cdr::new();
    header(&mut w, stamp, frame);
    w.string(format);
    w.bytes_with(data.len(), |b| b.extend_from_slice(data));
    w.finish()
}

/// `sensor_msgs/msg/CameraInfo`: `plumb_bob` with dynaflow's five coefficients (or
/// `equidistant` with a Kannala-Brandt lens's four), `R` the identity and `P` the intrinsics
/// with no baseline (a monocular or left camera).
pub fn camera_info(stamp: f64, frame: &str, c: &CameraInfo) -> Vec<u8> {
    let mut w = Cdr::new();
    header(&mut w, stamp, frame);
    w.u32(c.height);
    w.u32(c.width);
    let d = match c.model {
        LensModel::BrownConrady => &c.distortion[..],
        LensModel::KannalaBrandt => &c.distortion[..4],
    };
    w.string(match c.model {
        LensModel::BrownConrady => "plumb_bob",
        LensModel::KannalaBrandt => "equidistant",
    });
    w.seq_len(d.len());
    for v in d {
        w.f64(*v);
    }
    for v in [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
    for v in [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
    for v in [c.fx, 0.0, c.cx, 0.0, 0.0, c.fy, c.cy, 0.0, 0.0, 0.0, 1.0, 0.0] {
        w.f64(v);
    }
    w.u32(0); // binning_x
    w.u32(0); // binning_y
    for _ in 0..4 {
        w.u32(0); // roi x_offset, y_offset, height, width
    }
    w.u8(0); // roi do_rectify
    w.finish()
}

/// `geometry_msgs/msg/PoseStamped`.
pub fn pose_stamped(stamp: f64, frame: &str, p: &Isometry3<f64>) -> Vec<u8> {
    let mut w = Cdr::new();
    header(&mut w, stamp, frame);
    pose(&mut w, p);
    w.finish()
}

/// `nav_msgs/msg/Path`: `(stamp, pose)` in `frame`, oldest first.
pub fn path(stamp: f64, frame: &str, poses: &[(f64, Isometry3<f64>)]) -> Vec<u8> {
    let mut w = Cdr::new();
    header(&mut w, stamp, frame);
    w.seq_len(poses.len());
    for (s, p) in poses {
        header(&mut w, *s, frame);
        pose(&mut w, p);
    }
    w.finish()
}

/// One transform of a `tf2_msgs/msg/TFMessage`: `parent_from_child` at `stamp`.
#[derive(Clone, Debug)]
pub struct Transform<'a> {
    /// Seconds.
    pub stamp: f64,
    /// `header.frame_id`.
    pub parent: &'a str,
    /// `child_frame_id`.
    pub child: &'a str,
    /// The child frame's pose in the parent frame.
    pub parent_from_child: Isometry3<f64>,
}

/// `tf2_msgs/msg/TFMessage`.
pub fn tf(transforms: &[Transform<'_>]) -> Vec<u8> {
    let mut w = Cdr::new();
    w.seq_len(transforms.len());
    for t in transforms {
        header(&mut w, t.stamp, t.parent);
        w.string(t.child);
        pose(&mut w, &t.parent_from_child);
    }
    w.finish()
}

/// `sensor_msgs/PointField` datatype `FLOAT32`.
const FLOAT32: u8 = 7;

/// `sensor_msgs/msg/PointCloud2`, unorganised: `x y z` as `float32`, and with colours PCL's
/// `rgb` field (a `float32` holding `0x00RRGGBB`, what rviz2 and rerun read as colour).
pub fn point_cloud(stamp: f64, frame: &str, points: &[[f32; 3]], colours: Option<&[[u8; 3]]>) -> Vec<u8> {
    let mut w = Cdr::new();
    header(&mut w, stamp, frame);
    let colours = colours.filter(|c| c.len() == points.len());
    let mut fields = vec![("x", 0u32), ("y", 4), ("z", 8)];
    if colours.is_some() {
        fields.push(("rgb", 12));
    }
    let point_step = 4 * fields.len() as u32;
    w.u32(1); // height
    w.u32(points.len() as u32); // width
    w.seq_len(fields.len());
    for (name, offset) in &fields {
        w.string(name);
        w.u32(*offset);
        w.u8(FLOAT32);
        w.u32(1);
    }
    w.u8(0); // is_bigendian
    w.u32(point_step);
    w.u32(point_step * points.len() as u32); // row_step
    w.bytes_with(point_step as usize * points.len(), |b| {
        for (i, p) in points.iter().enumerate() {
            for v in p {
                b.extend_from_slice(&v.to_le_bytes());
            }
            if let Some(c) = colours {
                let [r, g, bl] = c[i];
                let packed = (u32::from(r) << 16) | (u32::from(g) << 8) | u32::from(bl);
                b.extend_from_slice(&packed.to_le_bytes());
            }
        }
    });
    w.u8(1); // is_dense: no NaN points are written
    w.finish()
}

/// `visualization_msgs/msg/ImageMarker` types.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MarkerKind {
    /// `LINE_LIST`: point pairs.
    LineList = 2,
    /// `POINTS`.
    Points = 4,
}

/// `visualization_msgs/msg/ImageMarker`: `points` (pixels) of one kind, each with its RGBA
/// colour, `scale` pixels wide, added (`ADD`) in namespace `ns` with `id`, kept until replaced.
pub fn image_marker(
    stamp: f64,
    frame: &str,
    ns: &str,
    kind: MarkerKind,
    scale: f32,
    points: &[[f32; 2]],
    colours: &[[f32; 4]],
) -> Vec<u8> {
    let mut w = Cdr::new();
    header(&mut w, stamp, frame);
    w.string(ns);
    w.i32(0); // id
    w.i32(kind as i32);
    w.i32(0); // action ADD
    for _ in 0..3 {
        w.f64(0.0); // position
    }
    w.f32(scale);
    let first = colours.first().copied().unwrap_or([1.0; 4]);
    for v in first {
        w.f32(v); // outline_color
    }
    w.u8(0); // filled
    for _ in 0..4 {
        w.f32(0.0); // fill_color
    }
    w.i32(0); // lifetime: forever
    w.u32(0);
    w.seq_len(points.len());
    for p in points {
        w.f64(f64::from(p[0]));
        w.f64(f64::from(p[1]));
        w.f64(0.0);
    }
    w.seq_len(colours.len());
    for c in colours {
        for v in c {
            w.f32(*v);
        }
    }
    w.finish()
}

/// `sensor_msgs/msg/Imu`: one sample, orientation unknown (its covariance's first element -1,
/// as the message's documentation asks), covariances of the rates unknown (zeros).
pub fn imu(stamp: f64, frame: &str, gyro: [f64; 3], accel: [f64; 3]) -> Vec<u8> {
    let mut w = Cdr::new();
    header(&mut w, stamp, frame);
    for v in [0.0, 0.0, 0.0, 1.0] {
        w.f64(v);
    }
    for i in 0..9 {
        w.f64(if i == 0 { -1.0 } else { 0.0 });
    }
    for v in gyro {
        w.f64(v);
    }
    for _ in 0..9 {
        w.f64(0.0);
    }
    for v in accel {
        w.f64(v);
    }
    for _ in 0..9 {
        w.f64(0.0);
    }
    w.finish()
}

/// `std_msgs/msg/String`.
pub fn string(text: &str) -> Vec<u8> {
    let mut w = Cdr::new();
    w.string(text);
    w.finish()
}

#[cfg(test)]
mod tests;
