//! The reader operators: TUM RGB-D folders (`tum_rgbd`), image folders (`image_folder`),
//! KITTI odometry sequences (`kitti_odometry`), EuRoC MAV folders (`euroc`), ROS 1 and ROS 2 bags (`rosbag`), and layout detection for `--input`. Each is a
//! thin wrapper over its reader in `dynaflow-datasets`, which does the file work, streamed by
//! the one source skeleton in `sequence` (which `synth` uses too).

mod euroc;
mod folder;
mod kitti;
mod rosbag;
mod sequence;
mod tum;

use dynaflow_datasets::intrinsics::Intrinsics;
use dynaflow_engine::op::{Param, ParamType, Params};

pub(crate) use euroc::EUROC;
pub(crate) use folder::{IMAGE_FOLDER, RGBD_FOLDER};
pub use folder::{Layout, detect_layout};
pub(crate) use kitti::KITTI_ODOMETRY;
pub(crate) use rosbag::ROSBAG;
pub(crate) use sequence::{OnError, SequenceSource, ground_truth_pose};
pub(crate) use tum::TUM_RGBD;

/// The `intrinsics` parameter of the readers: `auto` (from the folder) or given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraParam {
    /// From the folder: its name (TUM) or its `calibration.txt`.
    Auto,
    /// As written.
    Given(Intrinsics),
}

impl Param for CameraParam {
    const TYPE: ParamType = ParamType::Text {
        what: "`auto`, `fr1`, `fr2`, `fr3`, `fx,fy,cx,cy` or `fx,fy,cx,cy,k1,k2,p1,p2,k3`",
        check: |s| {
            if s.trim() == "auto" { Ok(()) } else { Intrinsics::parse(s).map(|_| ()).map_err(|e| e.to_string()) }
        },
    };
    fn from_json(value: &serde_json::Value, _: &Params) -> Result<Self, String> {
        match value.as_str().map(str::trim) {
            Some("auto") => Ok(CameraParam::Auto),
            Some(s) => Intrinsics::parse(s).map(CameraParam::Given).map_err(|e| e.to_string()),
            None => Err(format!("expected intrinsics, found {value}")),
        }
    }
    fn to_json(&self) -> serde_json::Value {
        match self {
            CameraParam::Auto => "auto".into(),
            CameraParam::Given(k) => {
                let p = k.pinhole;
                let mut v = vec![p.fx, p.fy, p.cx, p.cy];
                let fisheye = k.model == dynaflow_engine::msg::LensModel::KannalaBrandt;
                if fisheye {
                    v.extend(&k.distortion[..4]);
                } else if k.distortion != [0.0; 5] {
                    v.extend(k.distortion);
                }
                let text = v.iter().map(f64::to_string).collect::<Vec<_>>().join(",");
                if fisheye { format!("kb:{text}").into() } else { text.into() }
            }
        }
    }
}
