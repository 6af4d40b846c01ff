//! `image_folder`: a sorted list of images (optionally with a matching depth folder) played
//! at a fixed rate, and layout detection for `dynaflow run --input DIR`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use dynaflow_engine::msg::{Body, CameraInfo, Header, PortType};
use dynaflow_engine::op::{
    Context, Default, Instance, OpError, OpKind, OpSpec, Outputs, ParamSpec, ParamType, Params, PortSpec, Source,
};

use super::intrinsics::{Intrinsics, read_calibration};
use super::png::{load_depth, load_rgb, same_size};

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    path: String,
    pattern: String,
    rate_hz: f64,
    intrinsics: String,
    depth_path: String,
    depth_factor: f64,
}

pub(crate) const IMAGE_FOLDER: OpSpec = OpSpec {
    name: "image_folder",
    family: "decode",
    doc: "Plays the images of a folder that match `pattern` in file-name order at `rate_hz`, with the given intrinsics; with `depth_path`, the n-th depth PNG (in name order) pairs with the n-th image.",
    kind: OpKind::Source,
    inputs: &[],
    outputs: &[
        PortSpec::output("rgb", PortType::Image, "the image (RGB8 or Gray8)"),
        PortSpec::output("depth", PortType::Depth, "depth in metres, when `depth_path` is set"),
        PortSpec::output("camera_info", PortType::CameraInfo, "intrinsics"),
    ],
    params: &[
        ParamSpec { name: "path", ty: ParamType::Path, default: Default::Required, doc: "image folder" },
        ParamSpec {
            name: "pattern",
            ty: ParamType::Str,
            default: Default::Str("*.png"),
            doc: "file-name glob (`*` and `?`), e.g. `*.jpg`",
        },
        ParamSpec {
            name: "rate_hz",
            ty: ParamType::Float { min: 0.001, max: 10_000.0 },
            default: Default::Float(30.0),
            doc: "frame rate that sets the stamps",
        },
        ParamSpec {
            name: "intrinsics",
            ty: ParamType::Str,
            default: Default::Str("auto"),
            doc: "`fr1`/`fr2`/`fr3`, `fx,fy,cx,cy[,k1,k2,p1,p2,k3]`, or `auto` (the folder's calibration.txt)",
        },
        ParamSpec {
            name: "depth_path",
            ty: ParamType::Str,
            default: Default::Str(""),
            doc: "folder of 16-bit depth PNGs (empty: no depth)",
        },
        ParamSpec {
            name: "depth_factor",
            ty: ParamType::Float { min: 1e-6, max: 1e9 },
            default: Default::Float(5000.0),
            doc: "depth PNG value per metre",
        },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build,
};

/// Glob match on a file name: `*` any run, `?` one character.
fn matches(pattern: &[char], name: &[char]) -> bool {
    match (pattern.split_first(), name.split_first()) {
        (None, None) => true,
        (Some(('*', rest)), _) => matches(rest, name) || name.split_first().is_some_and(|(_, n)| matches(pattern, n)),
        (Some(('?', rest)), Some((_, n))) => matches(rest, n),
        (Some((p, rest)), Some((c, n))) if p == c => matches(rest, n),
        _ => false,
    }
}

/// Files of `dir` whose name matches `pattern`, sorted by name.
pub fn list(dir: &Path, pattern: &str) -> Result<Vec<PathBuf>, OpError> {
    let p: Vec<char> = pattern.chars().collect();
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| OpError::Io { path: dir.to_path_buf(), source })?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|f| {
            f.is_file() && f.file_name().is_some_and(|n| matches(&p, &n.to_string_lossy().chars().collect::<Vec<_>>()))
        })
        .collect();
    files.sort();
    Ok(files)
}

fn build(params: &Params) -> Result<Instance, OpError> {
    let c: Config = params.parse()?;
    let dir = params.resolve_path(&c.path);
    if !dir.is_dir() {
        return Err(OpError::Input(format!("{}: not a folder", dir.display())));
    }
    let images = list(&dir, &c.pattern)?;
    if images.is_empty() {
        return Err(OpError::Input(format!("{}: no file matches `{}`", dir.display(), c.pattern)));
    }
    let depth = if c.depth_path.is_empty() {
        None
    } else {
        let ddir = params.resolve_path(&c.depth_path);
        let d = list(&ddir, "*.png")?;
        if d.len() != images.len() {
            return Err(OpError::Input(format!(
                "{}: {} depth PNGs for {} images",
                ddir.display(),
                d.len(),
                images.len()
            )));
        }
        Some(d)
    };
    let intrinsics = if c.intrinsics == "auto" {
        read_calibration(&dir).unwrap_or_else(|| {
            Err(OpError::Config {
                key: "intrinsics".into(),
                message: format!(
                    "{}: no calibration.txt; set `intrinsics: fx,fy,cx,cy` (or `--intrinsics`)",
                    dir.display()
                ),
            })
        })?
    } else {
        Intrinsics::parse(&c.intrinsics).map_err(|e| OpError::Config { key: "intrinsics".into(), message: e })?
    };
    Ok(Instance::Source(Box::new(Folder {
        images,
        depth,
        intrinsics,
        rate: c.rate_hz,
        factor: c.depth_factor,
        frame_id: "camera".into(),
        size: None,
    })))
}

struct Folder {
    images: Vec<PathBuf>,
    depth: Option<Vec<PathBuf>>,
    intrinsics: Intrinsics,
    rate: f64,
    factor: f64,
    frame_id: Arc<str>,
    /// The first image's size: every later one must have it (the intrinsics are for it).
    size: Option<(u32, u32)>,
}

impl Source for Folder {
    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        let Some(path) = self.images.get(seq as usize) else { return Ok(None) };
        let img = load_rgb(path).map_err(OpError::Input)?;
        if let Some((w, h)) = self.size
            && (w, h) != (img.width, img.height)
        {
            let first = self.images.first().and_then(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned());
            return Err(OpError::Input(format!(
                "{}: {}x{} but the first image ({}) is {w}x{h}",
                path.display(),
                img.width,
                img.height,
                first.unwrap_or_default()
            )));
        }
        self.size = Some((img.width, img.height));
        let header = Header { seq, stamp: seq as f64 / self.rate, frame_id: self.frame_id.clone() };
        let k = &self.intrinsics;
        let info = CameraInfo {
            width: img.width,
            height: img.height,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            distortion: k.distortion,
        };
        let mut out = Outputs::new().with("camera_info", header.clone(), Body::CameraInfo(info));
        if let Some(d) = self.depth.as_ref().and_then(|d| d.get(seq as usize)) {
            let depth = load_depth(d, self.factor).map_err(OpError::Input)?;
            same_size(d.display(), (depth.width, depth.height), path.display(), (img.width, img.height))
                .map_err(OpError::Input)?;
            out.push("depth", header.clone(), Body::Depth(depth));
        }
        out.push("rgb", header, Body::Image(img));
        Ok(Some(out))
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.images.len() as u64)
    }
}

/// What `dynaflow run --input DIR` found in a folder: the reader op and its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// Reader operator.
    pub op: &'static str,
    /// `(param, value)` pairs.
    pub params: Vec<(&'static str, String)>,
}

/// Detect a TUM RGB-D folder, a KITTI odometry sequence or an image folder; the error says
/// what was expected.
pub fn detect_layout(dir: &Path, intrinsics: Option<&str>) -> Result<Layout, String> {
    if !dir.is_dir() {
        return Err(format!("{}: not a folder", dir.display()));
    }
    let path = dir.display().to_string();
    let mut params = vec![("path", path)];
    if let Some(i) = intrinsics {
        params.push(("intrinsics", i.to_owned()));
    }
    if dir.join("rgb.txt").is_file() && dir.join("depth.txt").is_file() {
        return Ok(Layout { op: "tum_rgbd", params });
    }
    if dir.join("calib.txt").is_file() && dir.join("times.txt").is_file() {
        params.retain(|(k, _)| *k != "intrinsics"); // KITTI carries its own calibration
        return Ok(Layout { op: "kitti_odometry", params });
    }
    for pattern in ["*.png", "*.jpg", "*.jpeg"] {
        if list(dir, pattern).is_ok_and(|l| !l.is_empty()) {
            params.push(("pattern", pattern.to_owned()));
            return Ok(Layout { op: "image_folder", params });
        }
    }
    Err(format!(
        "{}: not a TUM RGB-D folder (rgb.txt + depth.txt), a KITTI odometry sequence (calib.txt + times.txt) or a folder of images (*.png, *.jpg)",
        dir.display()
    ))
}

#[cfg(test)]
mod tests {
    #[test]
    fn globs() {
        let m = |p: &str, n: &str| super::matches(&p.chars().collect::<Vec<_>>(), &n.chars().collect::<Vec<_>>());
        assert!(m("*.png", "a.png"));
        assert!(!m("*.png", "a.jpg"));
        assert!(m("img_??.png", "img_01.png"));
        assert!(!m("img_??.png", "img_1.png"));
    }
}
