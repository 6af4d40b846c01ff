//! Writing a generated sequence in the TUM RGB-D layout, read back by `tum_rgbd`:
//! `rgb/`, `depth/` (16-bit PNG, 5000 per metre), `rgb.txt`, `depth.txt`, `groundtruth.txt`
//! (`timestamp tx ty tz qx qy qz qw`, `world_from_cam`), plus dynaflow extras: `mask/`
//! (8-bit class: 0 static, 1 person), `instance/` (8-bit instance id), `flow/` (Middlebury
//! `.flo`, to the next frame), `calibration.txt` (`fx fy cx cy`) and `synth.json`.

use std::fmt::Write as _;
use std::fs;
use std::io::Write as _;
use std::path::Path;

use image::{ExtendedColorType, ImageEncoder};

use super::{Frame, Generator, Motion, PeopleMode};
use crate::Error;

/// TUM depth scale: PNG value per metre.
pub const DEPTH_FACTOR: f64 = 5000.0;
/// Depth images are stamped this much after the colour image, as a Kinect's streams are.
const DEPTH_STAMP_OFFSET: f64 = 0.004;

/// What to write.
#[derive(Clone, Debug)]
pub struct WriteOptions {
    /// Number of frames.
    pub frames: u64,
    /// Also write ground-truth optical flow.
    pub flow: bool,
}

fn err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::file(path, e)
}

pub(super) fn png(path: &Path, data: &[u8], w: u32, h: u32, color: ExtendedColorType) -> Result<(), Error> {
    let file = fs::File::create(path).map_err(|e| err(path, e))?;
    image::codecs::png::PngEncoder::new_with_quality(
        std::io::BufWriter::new(file),
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(data, w, h, color)
    .map_err(|e| err(path, e))
}

/// Depth in metres as a TUM 16-bit PNG ([`DEPTH_FACTOR`] per metre, 0 = no measurement).
pub(super) fn depth_png(path: &Path, depth: &[f32], w: u32, h: u32) -> Result<(), Error> {
    let bytes: Vec<u8> = depth
        .iter()
        .flat_map(|&d| ((f64::from(d) * DEPTH_FACTOR).round().clamp(0.0, 65535.0) as u16).to_ne_bytes())
        .collect();
    png(path, &bytes, w, h, ExtendedColorType::L16)
}

fn write_flo(path: &Path, flow: &[[f32; 2]], w: u32, h: u32) -> Result<(), Error> {
    let mut bytes = Vec::with_capacity(12 + flow.len() * 8);
    bytes.extend_from_slice(&202_021.25f32.to_le_bytes());
    bytes.extend_from_slice(&(w as i32).to_le_bytes());
    bytes.extend_from_slice(&(h as i32).to_le_bytes());
    for [u, v] in flow {
        // Middlebury marks unknown flow with values above 1e9.
        let (u, v) = if u.is_finite() && v.is_finite() { (*u, *v) } else { (1e10, 1e10) };
        bytes.extend_from_slice(&u.to_le_bytes());
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    fs::write(path, bytes).map_err(|e| err(path, e))
}

/// Format a TUM timestamp.
pub fn stamp_name(stamp: f64) -> String {
    format!("{stamp:.6}")
}

fn write_frame(dir: &Path, f: &Frame, w: u32, h: u32) -> Result<(), Error> {
    let s = stamp_name(f.stamp);
    let sd = stamp_name(f.stamp + DEPTH_STAMP_OFFSET);
    png(&dir.join(format!("rgb/{s}.png")), &f.rgb, w, h, ExtendedColorType::Rgb8)?;
    depth_png(&dir.join(format!("depth/{sd}.png")), &f.depth, w, h)?;
    let class: Vec<u8> = f.class.iter().map(|&c| c.min(255) as u8).collect();
    png(&dir.join(format!("mask/{s}.png")), &class, w, h, ExtendedColorType::L8)?;
    let inst: Vec<u8> = f.instance.iter().map(|&c| c.min(255) as u8).collect();
    png(&dir.join(format!("instance/{s}.png")), &inst, w, h, ExtendedColorType::L8)?;
    if let Some(flow) = &f.flow {
        write_flo(&dir.join(format!("flow/{s}.flo")), flow, w, h)?;
    }
    Ok(())
}

/// Write `opts.frames` frames of `generator` to `dir` in the TUM layout.
pub fn write_tum(generator: &Generator, dir: &Path, opts: &WriteOptions) -> Result<(), Error> {
    let c = generator.config();
    let k = &c.intrinsics;
    for sub in ["rgb", "depth", "mask", "instance"].iter().chain(opts.flow.then_some(&"flow")) {
        fs::create_dir_all(dir.join(sub)).map_err(|e| err(&dir.join(sub), e))?;
    }
    let name = dir.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let mut rgb_txt = format!("# color images\n# file: '{name}'\n# timestamp filename\n");
    let mut depth_txt = format!("# depth maps\n# file: '{name}'\n# timestamp filename\n");
    let mut gt_txt = format!("# ground truth trajectory\n# file: '{name}'\n# timestamp tx ty tz qx qy qz qw\n");
    for i in 0..opts.frames {
        let f = generator.frame(i, opts.flow);
        write_frame(dir, &f, k.width, k.height)?;
        let s = stamp_name(f.stamp);
        let sd = stamp_name(f.stamp + DEPTH_STAMP_OFFSET);
        let _ = writeln!(rgb_txt, "{s} rgb/{s}.png");
        let _ = writeln!(depth_txt, "{sd} depth/{sd}.png");
        let t = f.world_from_cam.translation.vector;
        let q = f.world_from_cam.rotation.coords;
        let _ = writeln!(gt_txt, "{s} {:.6} {:.6} {:.6} {:.9} {:.9} {:.9} {:.9}", t.x, t.y, t.z, q.x, q.y, q.z, q.w);
    }
    for (file, text) in [("rgb.txt", &rgb_txt), ("depth.txt", &depth_txt), ("groundtruth.txt", &gt_txt)] {
        fs::write(dir.join(file), text).map_err(|e| err(&dir.join(file), e))?;
    }
    let calib = if k.model == dynaflow_msg::LensModel::KannalaBrandt {
        let [k1, k2, k3, k4, _] = k.distortion;
        format!(
            "# kb:fx,fy,cx,cy,k1,k2,k3,k4 (dynaflow synth, a Kannala-Brandt fisheye)\nkb:{},{},{},{},{k1},{k2},{k3},{k4}\n",
            k.fx, k.fy, k.cx, k.cy
        )
    } else {
        format!(
            "# fx fy cx cy [k1 k2 p1 p2 k3] (dynaflow synth, pinhole without distortion)\n{} {} {} {}\n",
            k.fx, k.fy, k.cx, k.cy
        )
    };
    fs::write(dir.join("calibration.txt"), calib).map_err(|e| err(&dir.join("calibration.txt"), e))?;
    let info = serde_json::json!({
        "generator": "dynaflow synth",
        "version": env!("CARGO_PKG_VERSION"),
        "motion": Motion::NAMES.iter().find(|n| Motion::from_name(n) == Some(c.motion)),
        "people": c.people,
        "sitting": c.mode == PeopleMode::Sitting,
        "seed": c.seed,
        "rate_hz": c.rate_hz,
        "frames": opts.frames,
        "width": k.width, "height": k.height, "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
        "lens": if k.model == dynaflow_msg::LensModel::KannalaBrandt { "kannala_brandt" } else { "pinhole" },
        "distortion": k.distortion,
        "depth_factor": DEPTH_FACTOR,
        "depth_noise": c.depth_noise, "image_noise": c.image_noise, "blur": c.blur,
        "mask_classes": ["static", "person"],
    });
    let path = dir.join("synth.json");
    let mut file = fs::File::create(&path).map_err(|e| err(&path, e))?;
    file.write_all(serde_json::to_string_pretty(&info).unwrap_or_default().as_bytes()).map_err(|e| err(&path, e))?;
    Ok(())
}
