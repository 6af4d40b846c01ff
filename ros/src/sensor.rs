//! The sensor messages a SLAM run reads, from decoded ROS messages into dynaflow's message
//! types: `sensor_msgs/Image` (row padding in `step`, `is_bigendian`), `CompressedImage` (JPEG,
//! PNG, and image_transport's `compressedDepth`), `CameraInfo`, `Imu`, and the poses of
//! `PoseStamped`, `Odometry` and `TransformStamped`. Both ROS 1 and ROS 2 layouts (their headers
//! and stamps differ) are read. Errors say which field or encoding is wrong.

use dynaflow_msg::{CameraInfo, DepthImage, Image, ImuSample, LensModel, PixelFormat};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::decode::{Message, Value};

/// A header's stamp (nanoseconds) and frame id.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Stamped {
    /// `header.stamp`, nanoseconds.
    pub stamp_ns: i64,
    /// `header.frame_id`.
    pub frame_id: String,
}

impl Stamped {
    /// The stamp in seconds: [`seconds`].
    pub fn seconds(&self) -> f64 {
        seconds(self.stamp_ns)
    }
}

/// Nanoseconds as seconds: the double nearest the exact decimal `sec.nnnnnnnnn`, so a stamp
/// written to a bag from a text file's `1305031102.175304` reads back as the very double that
/// parsing the text gives (`ns as f64 * 1e-9` rounds twice and can miss it by an ulp, and a
/// TUM folder and its bag would then differ in every stamp).
pub fn seconds(ns: i64) -> f64 {
    stamp_text(ns).parse().unwrap_or(ns as f64 / 1e9)
}

/// Nanoseconds as the exact decimal `sec.nnnnnnnnn`, as errors name a stamp (a double near
/// 1.7e9 s holds only ~0.2 us, so printing [`seconds`] to nine places would show noise).
pub fn stamp_text(ns: i64) -> String {
    let (sign, abs) = if ns < 0 { ("-", ns.unsigned_abs()) } else { ("", ns.unsigned_abs()) };
    format!("{sign}{}.{:09}", abs / 1_000_000_000, abs % 1_000_000_000)
}

/// What an image message holds.
#[derive(Clone, Debug, PartialEq)]
pub enum Picture {
    /// 8-bit colour or grey.
    Colour(Image),
    /// Depth in metres (0 = no measurement).
    Depth(DepthImage),
}

fn field<'a>(m: &'a Message, name: &str) -> Result<&'a Value, String> {
    m.get(name).ok_or_else(|| format!("{}: no field `{name}`", m.ty))
}

fn sub<'a>(m: &'a Message, name: &str) -> Result<&'a Message, String> {
    match field(m, name)? {
        Value::Message(s) => Ok(s),
        _ => Err(format!("{}: `{name}` is not a message", m.ty)),
    }
}

fn uint(m: &Message, name: &str) -> Result<u64, String> {
    match field(m, name)? {
        Value::UInt(v) => Ok(*v),
        Value::Int(v) if *v >= 0 => Ok(*v as u64),
        _ => Err(format!("{}: `{name}` is not an unsigned integer", m.ty)),
    }
}

fn float(m: &Message, name: &str) -> Result<f64, String> {
    match field(m, name)? {
        Value::Float(v) => Ok(*v),
        Value::Int(v) => Ok(*v as f64),
        Value::UInt(v) => Ok(*v as f64),
        _ => Err(format!("{}: `{name}` is not a number", m.ty)),
    }
}

fn string<'a>(m: &'a Message, name: &str) -> Result<&'a str, String> {
    match field(m, name)? {
        Value::String(s) => Ok(s),
        _ => Err(format!("{}: `{name}` is not a string", m.ty)),
    }
}

fn bytes<'a>(m: &'a Message, name: &str) -> Result<&'a [u8], String> {
    match field(m, name)? {
        Value::Bytes(b) => Ok(b),
        _ => Err(format!("{}: `{name}` is not a byte array", m.ty)),
    }
}

fn floats(m: &Message, name: &str) -> Result<Vec<f64>, String> {
    match field(m, name)? {
        Value::Array(items) => items
            .iter()
            .map(|v| match v {
                Value::Float(f) => Ok(*f),
                _ => Err(format!("{}: `{name}` holds a non-number", m.ty)),
            })
            .collect(),
        _ => Err(format!("{}: `{name}` is not an array", m.ty)),
    }
}

/// A stamp: ROS 1 `time` or ROS 2 `builtin_interfaces/Time`, as nanoseconds.
fn stamp_ns(v: &Value) -> Result<i64, String> {
    match v {
        Value::Time { sec, nsec } => Ok(sec * 1_000_000_000 + nsec),
        Value::Message(t) => {
            let sec = match field(t, "sec")? {
                Value::Int(s) => *s,
                Value::UInt(s) => *s as i64,
                _ => return Err("stamp: `sec` is not an integer".into()),
            };
            Ok(sec * 1_000_000_000 + uint(t, "nanosec")? as i64)
        }
        _ => Err("stamp is neither `time` nor `builtin_interfaces/Time`".into()),
    }
}

/// A message's `header`.
pub fn header(m: &Message) -> Result<Stamped, String> {
    let h = sub(m, "header")?;
    Ok(Stamped { stamp_ns: stamp_ns(field(h, "stamp")?)?, frame_id: string(h, "frame_id")?.to_string() })
}

/// `sensor_msgs/Image`. 16-bit encodings (`16UC1`, `mono16`) are depth, `value / depth_factor`
/// metres (REP 118: millimetres, factor 1000); `32FC1` is depth in metres (NaN and infinities
/// mean no measurement). Colour comes out RGB8 (BGR swapped, alpha dropped), `mono8` grey.
pub fn image(m: &Message, depth_factor: f64) -> Result<Picture, String> {
    let (width, height, step) = (uint(m, "width")? as usize, uint(m, "height")? as usize, uint(m, "step")? as usize);
    let encoding = string(m, "encoding")?;
    let big_endian = uint(m, "is_bigendian")? != 0;
    let data = bytes(m, "data")?;
    let bpp = match encoding {
        "rgb8" | "bgr8" | "8UC3" => 3,
        "rgba8" | "bgra8" | "8UC4" => 4,
        "mono8" | "8UC1" => 1,
        "mono16" | "16UC1" => 2,
        "32FC1" => 4,
        other => {
            return Err(format!(
                "image encoding `{other}` (read: rgb8, bgr8, rgba8, bgra8, mono8, mono16, 16UC1, 32FC1; Bayer and YUV need a debayering node first)"
            ));
        }
    };
    if width == 0 || height == 0 || width > 1 << 16 || height > 1 << 16 {
        return Err(format!("image of {width}x{height} pixels"));
    }
    if step < width * bpp {
        return Err(format!("`step` {step} is less than width {width} x {bpp} bytes ({encoding})"));
    }
    let need = step * (height - 1) + width * bpp;
    if data.len() < need {
        return Err(format!(
            "`data` has {} bytes, {width}x{height} {encoding} with step {step} needs {need}",
            data.len()
        ));
    }
    let rows = (0..height).map(|y| &data[y * step..y * step + width * bpp]);
    let (w, h) = (width as u32, height as u32);
    Ok(match encoding {
        "mono8" | "8UC1" => Picture::Colour(Image {
            width: w,
            height: h,
            format: PixelFormat::Gray8,
            data: rows.flatten().copied().collect(),
        }),
        "rgb8" | "bgr8" | "rgba8" | "bgra8" | "8UC3" | "8UC4" => {
            let swap = encoding.starts_with("bgr") || encoding.starts_with("8UC");
            let mut out = Vec::with_capacity(width * height * 3);
            for row in rows {
                for px in row.chunks_exact(bpp) {
                    if swap {
                        out.extend([px[2], px[1], px[0]]);
                    } else {
                        out.extend([px[0], px[1], px[2]]);
                    }
                }
            }
            Picture::Colour(Image { width: w, height: h, format: PixelFormat::Rgb8, data: out })
        }
        "mono16" | "16UC1" => {
            let mut out = Vec::with_capacity(width * height);
            for row in rows {
                for px in row.chunks_exact(2) {
                    let v = if big_endian {
                        u16::from_be_bytes([px[0], px[1]])
                    } else {
                        u16::from_le_bytes([px[0], px[1]])
                    };
                    out.push((f64::from(v) / depth_factor) as f32);
                }
            }
            Picture::Depth(DepthImage { width: w, height: h, data: out })
        }
        _ => {
            let mut out = Vec::with_capacity(width * height);
            for row in rows {
                for px in row.chunks_exact(4) {
                    let b = [px[0], px[1], px[2], px[3]];
                    let v = if big_endian { f32::from_be_bytes(b) } else { f32::from_le_bytes(b) };
                    out.push(if v.is_finite() && v > 0.0 { v } else { 0.0 });
                }
            }
            Picture::Depth(DepthImage { width: w, height: h, data: out })
        }
    })
}

/// `sensor_msgs/CompressedImage`: JPEG or PNG colour (decoded to RGB8 or grey), a 16-bit PNG
/// as depth (`value / depth_factor` metres), or image_transport's `compressedDepth` (a 12-byte
/// configuration header, then a PNG of 16-bit depth, or of quantised inverse depth for `32FC1`).
pub fn compressed_image(m: &Message, depth_factor: f64) -> Result<Picture, String> {
    let format = string(m, "format")?.to_ascii_lowercase();
    let data = bytes(m, "data")?;
    if format.contains("compresseddepth") {
        let Some((config, png)) = data.split_at_checked(12) else {
            return Err("compressedDepth data shorter than its 12-byte header".into());
        };
        let quant_a = f32::from_le_bytes([config[4], config[5], config[6], config[7]]);
        let quant_b = f32::from_le_bytes([config[8], config[9], config[10], config[11]]);
        let img = image::load_from_memory_with_format(png, image::ImageFormat::Png)
            .map_err(|e| format!("compressedDepth PNG: {e}"))?
            .into_luma16();
        let (w, h) = img.dimensions();
        let data = if format.starts_with("32fc1") {
            // Inverse depth quantised: depth = a / (v - b); 0 is no measurement.
            img.into_raw().into_iter().map(|v| if v == 0 { 0.0 } else { quant_a / (f32::from(v) - quant_b) }).collect()
        } else {
            img.into_raw().into_iter().map(|v| (f64::from(v) / depth_factor) as f32).collect()
        };
        return Ok(Picture::Depth(DepthImage { width: w, height: h, data }));
    }
    let img = image::load_from_memory(data).map_err(|e| format!("compressed image (format `{format}`): {e}"))?;
    Ok(match img {
        image::DynamicImage::ImageLuma8(g) => Picture::Colour(Image {
            width: g.width(),
            height: g.height(),
            format: PixelFormat::Gray8,
            data: g.into_raw(),
        }),
        image::DynamicImage::ImageLuma16(d) => Picture::Depth(DepthImage {
            width: d.width(),
            height: d.height(),
            data: d.into_raw().into_iter().map(|v| (f64::from(v) / depth_factor) as f32).collect(),
        }),
        other => {
            let rgb = other.into_rgb8();
            Picture::Colour(Image {
                width: rgb.width(),
                height: rgb.height(),
                format: PixelFormat::Rgb8,
                data: rgb.into_raw(),
            })
        }
    })
}

/// `sensor_msgs/CameraInfo` as pinhole intrinsics with OpenCV's distortion (`plumb_bob`,
/// `rational_polynomial` with its last three terms zero, or none). The field names differ
/// between ROS 1 (`D`, `K`) and ROS 2 (`d`, `k`).
pub fn camera_info(m: &Message) -> Result<CameraInfo, String> {
    let pick = |a: &str, b: &str| if m.get(a).is_some() { a.to_string() } else { b.to_string() };
    let k = floats(m, &pick("k", "K"))?;
    let d = floats(m, &pick("d", "D"))?;
    let model = string(m, "distortion_model")?;
    if k.len() != 9 {
        return Err(format!("`k` has {} values, not 9", k.len()));
    }
    let mut distortion = [0.0; 5];
    let mut lens = LensModel::BrownConrady;
    match model {
        "" if d.iter().all(|v| *v == 0.0) => {}
        "plumb_bob" | "rational_polynomial" => {
            if d.iter().skip(5).any(|v| *v != 0.0) {
                return Err(format!(
                    "distortion `{model}` with {} coefficients: only the first five (k1 k2 p1 p2 k3) are modelled",
                    d.len()
                ));
            }
            for (o, v) in distortion.iter_mut().zip(&d) {
                *o = *v;
            }
        }
        "equidistant" | "fisheye" | "kannala_brandt" => {
            if d.iter().skip(4).any(|v| *v != 0.0) {
                return Err(format!("distortion `{model}` with {} coefficients: Kannala-Brandt has four", d.len()));
            }
            lens = LensModel::KannalaBrandt;
            for (o, v) in distortion.iter_mut().zip(&d) {
                *o = *v;
            }
        }
        other => {
            return Err(format!("distortion model `{other}` (read: plumb_bob, rational_polynomial, equidistant)"));
        }
    }
    let info = CameraInfo {
        width: uint(m, "width")? as u32,
        height: uint(m, "height")? as u32,
        fx: k[0],
        fy: k[4],
        cx: k[2],
        cy: k[5],
        distortion,
        model: lens,
    };
    if !(info.fx > 0.0 && info.fy > 0.0 && info.cx.is_finite() && info.cy.is_finite()) {
        return Err(format!("`k` has no positive focal lengths: {k:?} (an uncalibrated camera?)"));
    }
    Ok(info)
}

fn vector(m: &Message, name: &str) -> Result<Vector3<f64>, String> {
    let v = sub(m, name)?;
    Ok(Vector3::new(float(v, "x")?, float(v, "y")?, float(v, "z")?))
}

/// `sensor_msgs/Imu` as one sample at its header stamp.
pub fn imu(m: &Message) -> Result<ImuSample, String> {
    let h = header(m)?;
    Ok(ImuSample { stamp: h.seconds(), gyro: vector(m, "angular_velocity")?, accel: vector(m, "linear_acceleration")? })
}

fn pose_of(translation: Vector3<f64>, q: &Message) -> Result<Isometry3<f64>, String> {
    let q = Quaternion::new(float(q, "w")?, float(q, "x")?, float(q, "y")?, float(q, "z")?);
    let n = q.norm();
    if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
        return Err(format!("orientation quaternion of norm {n} (not a rotation)"));
    }
    Ok(Isometry3::from_parts(Translation3::from(translation), UnitQuaternion::from_quaternion(q)))
}

/// `geometry_msgs/Pose`.
fn pose(p: &Message) -> Result<Isometry3<f64>, String> {
    pose_of(vector(p, "position")?, sub(p, "orientation")?)
}

/// A pose message (`PoseStamped`, `Odometry`, `TransformStamped`, `PoseWithCovarianceStamped`)
/// as `header.frame_id`'s `from` the child (its `child_frame_id` where it has one).
pub fn stamped_pose(m: &Message) -> Result<(Stamped, Option<String>, Isometry3<f64>), String> {
    let h = header(m)?;
    let child = m.get("child_frame_id").and_then(|v| if let Value::String(s) = v { Some(s.clone()) } else { None });
    let p = if let Some(Value::Message(t)) = m.get("transform") {
        pose_of(vector(t, "translation")?, sub(t, "rotation")?)?
    } else {
        let p = sub(m, "pose")?;
        // PoseWithCovariance wraps the pose once more.
        match p.get("pose") {
            Some(Value::Message(inner)) => pose(inner)?,
            _ => pose(p)?,
        }
    };
    Ok((h, child, p))
}

/// `tf2_msgs/TFMessage`'s transforms.
pub fn transforms(m: &Message) -> Result<Vec<(Stamped, String, Isometry3<f64>)>, String> {
    match field(m, "transforms")? {
        Value::Array(items) => items
            .iter()
            .map(|t| match t {
                Value::Message(t) => {
                    let (h, child, p) = stamped_pose(t)?;
                    Ok((h, child.unwrap_or_default(), p))
                }
                _ => Err("tf: a transform is not a message".to_string()),
            })
            .collect(),
        _ => Err("tf: `transforms` is not an array".into()),
    }
}

#[cfg(test)]
mod tests;
