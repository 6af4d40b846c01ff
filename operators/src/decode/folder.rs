//! `image_folder`: a sorted list of images played at a fixed rate (a monocular source: it
//! has no depth port, so a graph that judges with depth fails validation on it), `rgbd_folder`:
//! the same with a matching folder of depth PNGs,
//! at a fixed rate, and layout detection for `dynaflow run --input DIR`.

use std::path::{Path, PathBuf};

use dynaflow_datasets::folder::{FolderFrame, ImageFolder, list};
use dynaflow_datasets::intrinsics::read_calibration;

use dynaflow_engine::msg::{CameraInfo, DepthImage, Header, Image};
use dynaflow_engine::op::{Instance, OpError, OpSpec, Out, Outputs, ParamSpec, concat_params};
use dynaflow_engine::params;

use super::CameraParam;
use super::sequence::{OnError, SequenceSource};

params! {
    /// Both folder readers' parameters.
    struct Config {
        /// image folder
        path: PathBuf,
        /// file-name glob (`*` and `?`), e.g. `*.jpg`
        pattern: String = "*.png".into(),
        /// frame rate that sets the stamps
        rate_hz: f64 [0.001, 10_000.0] = 30.0,
        /// `fr1`/`fr2`/`fr3`, `fx,fy,cx,cy[,k1,k2,p1,p2,k3]`, `kb:fx,fy,cx,cy,k1,k2,k3,k4`, or `auto` (the folder's calibration.txt)
        intrinsics: CameraParam = CameraParam::Auto,
        /// an unreadable image: fail the run, or skip the frame (counted, logged)
        on_error: OnError = OnError::Fail,
    }
}

params! {
    /// `rgbd_folder`'s own: the depth folder.
    struct DepthFolder {
        /// folder of 16-bit depth PNGs, the n-th (in name order) paired with the n-th image
        depth_path: PathBuf,
        /// depth PNG value per metre
        depth_factor: f64 [1e-6, 1e9] = 5000.0,
    }
}

const RGBD_PARAMS: [ParamSpec; Config::PARAMS.len() + DepthFolder::PARAMS.len()] =
    concat_params(Config::PARAMS, DepthFolder::PARAMS);

const RGB: Out<Image> = Out::new("rgb", "the image (RGB8 or Gray8)");
const DEPTH: Out<DepthImage> = Out::new("depth", "depth in metres");
const CAMERA_INFO: Out<CameraInfo> = Out::new("camera_info", "intrinsics");

const IMAGE_FOLDER_DOC: &str = "Plays the images of a folder that match `pattern` in file-name order at `rate_hz`, with the given intrinsics: a monocular source (no depth port; `rgbd_folder` adds a depth folder).";
const RGBD_FOLDER_DOC: &str = "Plays the images of a folder that match `pattern` in file-name order at `rate_hz`, with the given intrinsics, each with the depth PNG of the same rank in `depth_path`.";

pub(crate) const IMAGE_FOLDER: OpSpec =
    OpSpec::source("image_folder", "decode", IMAGE_FOLDER_DOC, |params| open(&Config::from_params(params)?, None))
        .outputs(&[RGB.spec, CAMERA_INFO.spec])
        .params(Config::PARAMS)
        .cpu_heavy();

pub(crate) const RGBD_FOLDER: OpSpec = OpSpec::source("rgbd_folder", "decode", RGBD_FOLDER_DOC, |params| {
    open(&Config::from_params(params)?, Some(&DepthFolder::from_params(params)?))
})
.outputs(&[RGB.spec, DEPTH.spec, CAMERA_INFO.spec])
.params(&RGBD_PARAMS)
.cpu_heavy();

fn open(c: &Config, depth: Option<&DepthFolder>) -> Result<Instance, OpError> {
    let path = c.path.as_path();
    let intrinsics = match c.intrinsics {
        CameraParam::Auto => read_calibration(path).unwrap_or_else(|| {
            Err(dynaflow_datasets::Error::file(
                path,
                "no calibration.txt; set `intrinsics: fx,fy,cx,cy` (or `--intrinsics`)",
            ))
        }),
        CameraParam::Given(k) => Ok(k),
    }
    .map_err(|e| OpError::Config { key: "intrinsics".into(), message: e.to_string() })?;
    let (depth_dir, depth_factor) = depth.map_or((None, 1.0), |d| (Some(d.depth_path.as_path()), d.depth_factor));
    let folder = ImageFolder::open(path, &c.pattern, depth_dir, intrinsics, c.rate_hz, depth_factor)
        .map_err(OpError::library)?;
    Ok(Instance::Source(Box::new(SequenceSource::new(folder, emit, path, c.on_error))))
}

fn emit(_: &ImageFolder, f: FolderFrame, header: &Header) -> Outputs {
    let mut out = Outputs::new().send(&CAMERA_INFO, header.clone(), f.camera);
    if let Some(depth) = f.depth {
        DEPTH.push(&mut out, header.clone(), depth);
    }
    RGB.push(&mut out, header.clone(), f.image);
    out
}

/// What `dynaflow run --input DIR` found in a folder: the reader op and its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    /// Reader operator.
    pub op: &'static str,
    /// `(param, value)` pairs.
    pub params: Vec<(&'static str, String)>,
}

/// Detect a ROS bag (a `.bag`, `.mcap` or `.db3` file, or a rosbag2 folder), a TUM RGB-D
/// folder, a KITTI odometry sequence, a EuRoC MAV folder or an image folder; the error says
/// what was expected. `topics` (a bag's `role=topic` pairs) is an error for anything else.
pub fn detect_layout(
    dir: &Path,
    intrinsics: Option<&str>,
    topics: Option<&str>,
) -> Result<Layout, dynaflow_datasets::Error> {
    let path = dir.display().to_string();
    let mut params = vec![("path", path)];
    if let Some(i) = intrinsics {
        params.push(("intrinsics", i.to_owned()));
    }
    let is_bag = if dir.is_dir() { dir.join("metadata.yaml").is_file() } else { dir.is_file() };
    if is_bag {
        // Its first bytes tell the format; what they are not is said naming the file.
        dynaflow_ros::Bag::open(dir).map_err(|e| dynaflow_datasets::Error::Data(e.to_string()))?;
        if let Some(t) = topics {
            params.push(("topics", t.to_owned()));
        }
        return Ok(Layout { op: "rosbag", params });
    }
    if let Some(t) = topics {
        return Err(dynaflow_datasets::Error::file(
            dir,
            format!("`--topics {t}` names the topics of a ROS bag, and this is not one"),
        ));
    }
    if !dir.is_dir() {
        return Err(dynaflow_datasets::Error::file(dir, "not a folder or a bag"));
    }
    if dir.join("rgb.txt").is_file() && dir.join("depth.txt").is_file() {
        return Ok(Layout { op: "tum_rgbd", params });
    }
    if dir.join("calib.txt").is_file() && dir.join("times.txt").is_file() {
        params.retain(|(k, _)| *k != "intrinsics"); // KITTI carries its own calibration
        // The grey pair when there is one (what ORB-SLAM2's KITTI examples read), else colour.
        if !dir.join("image_0").is_dir() && dir.join("image_2").is_dir() {
            params.push(("camera", "color".to_owned()));
        }
        return Ok(Layout { op: "kitti_odometry", params });
    }
    let mav0 = if dir.join("mav0").is_dir() { dir.join("mav0") } else { dir.to_path_buf() };
    if mav0.join("cam0").join("data.csv").is_file() && mav0.join("imu0").join("data.csv").is_file() {
        params.retain(|(k, _)| *k != "intrinsics"); // cam0/sensor.yaml carries the calibration
        return Ok(Layout { op: "euroc", params });
    }
    for pattern in ["*.png", "*.jpg", "*.jpeg"] {
        if list(dir, pattern).is_ok_and(|l| !l.is_empty()) {
            params.push(("pattern", pattern.to_owned()));
            return Ok(Layout { op: "image_folder", params });
        }
    }
    Err(dynaflow_datasets::Error::file(
        dir,
        "not a TUM RGB-D folder (rgb.txt + depth.txt), a KITTI odometry sequence (calib.txt + times.txt), a EuRoC MAV folder (mav0/cam0 + mav0/imu0), a rosbag2 folder (metadata.yaml) or a folder of images (*.png, *.jpg)",
    ))
}
