//! Camera intrinsics for TUM sequences: the published presets, explicit values, or the
//! `calibration.txt` written by `dynaflow synth`.

use std::path::Path;

use dynaflow_msg::{CameraInfo, LensModel};
use dynaflow_vision::camera::Pinhole;

use crate::Error;

/// A calibrated camera without its image size: the pinhole and the lens's distortion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal lengths and principal point.
    pub pinhole: Pinhole,
    /// `[k1, k2, p1, p2, k3]` (see `dynaflow_vision::camera::distort`), or for a
    /// Kannala-Brandt lens `[k1, k2, k3, k4, 0]`.
    pub distortion: [f64; 5],
    /// The lens model of `distortion`.
    pub model: LensModel,
}

const fn preset(fx: f64, fy: f64, cx: f64, cy: f64, distortion: [f64; 5]) -> Intrinsics {
    Intrinsics { pinhole: Pinhole::new(fx, fy, cx, cy), distortion, model: LensModel::BrownConrady }
}

/// TUM fr1 (ROS default calibration as published with the dataset).
pub const FR1: Intrinsics = preset(517.3, 516.5, 318.6, 255.3, [0.2624, -0.9531, -0.0054, 0.0026, 1.1633]);
/// TUM fr2.
pub const FR2: Intrinsics = preset(520.9, 521.0, 325.1, 249.7, [0.2312, -0.7849, -0.0033, -0.0001, 0.9172]);
/// TUM fr3 (images are already undistorted).
pub const FR3: Intrinsics = preset(535.4, 539.2, 320.1, 247.6, [0.0; 5]);

impl Intrinsics {
    /// Without distortion.
    pub const fn pinhole(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        preset(fx, fy, cx, cy, [0.0; 5])
    }

    /// The message for images of `width` x `height`.
    pub const fn camera_info(&self, width: u32, height: u32) -> CameraInfo {
        let p = self.pinhole;
        CameraInfo {
            width,
            height,
            fx: p.fx,
            fy: p.fy,
            cx: p.cx,
            cy: p.cy,
            distortion: self.distortion,
            model: self.model,
        }
    }

    /// `fr1`, `fr2`, `fr3`, `fx,fy,cx,cy[,k1,k2,p1,p2,k3]`, or a Kannala-Brandt fisheye
    /// `kb:fx,fy,cx,cy,k1,k2,k3,k4`.
    pub fn parse(text: &str) -> Result<Self, Error> {
        Self::parse_msg(text).map_err(Error::Intrinsics)
    }

    fn parse_msg(text: &str) -> Result<Self, String> {
        match text.trim() {
            "fr1" => return Ok(FR1),
            "fr2" => return Ok(FR2),
            "fr3" => return Ok(FR3),
            _ => {}
        }
        let (fisheye, numbers) = match text.trim().strip_prefix("kb:") {
            Some(rest) => (true, rest),
            None => (false, text),
        };
        let v = numbers_of(numbers)?;
        let ok = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if fisheye {
            return match v.as_slice() {
                [fx, fy, cx, cy, k1, k2, k3, k4] if ok(&v) && *fx > 0.0 && *fy > 0.0 => Ok(Intrinsics {
                    model: LensModel::KannalaBrandt,
                    ..preset(*fx, *fy, *cx, *cy, [*k1, *k2, *k3, *k4, 0.0])
                }),
                _ => Err(format!(
                    "expected `kb:fx,fy,cx,cy,k1,k2,k3,k4` (a Kannala-Brandt fisheye) with positive focal lengths, got `{text}`"
                )),
            };
        }
        match v.as_slice() {
            [fx, fy, cx, cy] if ok(&v) && *fx > 0.0 && *fy > 0.0 => Ok(preset(*fx, *fy, *cx, *cy, [0.0; 5])),
            [fx, fy, cx, cy, k1, k2, p1, p2, k3] if ok(&v) && *fx > 0.0 && *fy > 0.0 => {
                Ok(preset(*fx, *fy, *cx, *cy, [*k1, *k2, *p1, *p2, *k3]))
            }
            _ => Err(format!(
                "expected `fr1`, `fr2`, `fr3`, `fx,fy,cx,cy`, `fx,fy,cx,cy,k1,k2,p1,p2,k3` or `kb:fx,fy,cx,cy,k1,k2,k3,k4` with positive focal lengths, got `{text}`"
            )),
        }
    }
}

/// The numbers of a calibration written as text (`fx,fy,cx,cy`, `1 2 3`): separated by commas,
/// spaces or tabs; the first that is not a number is named.
pub fn numbers_of(text: &str) -> Result<Vec<f64>, String> {
    text.split([',', ' ', '\t'])
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<f64>().map_err(|_| format!("`{s}` is not a number")))
        .collect()
}

/// The preset a TUM folder name implies (`rgbd_dataset_freiburgN_*`), if any.
pub fn preset_for_folder(dir: &Path) -> Option<Intrinsics> {
    let name = dir.canonicalize().ok().unwrap_or_else(|| dir.to_path_buf());
    let name = name.file_name()?.to_string_lossy().to_lowercase();
    if name.contains("freiburg1") {
        Some(FR1)
    } else if name.contains("freiburg2") {
        Some(FR2)
    } else if name.contains("freiburg3") {
        Some(FR3)
    } else {
        None
    }
}

/// The intrinsics in `dir/calibration.txt` (first non-comment line, as [`Intrinsics::parse`]
/// reads it), or `None` when the folder has no such file.
pub fn read_calibration(dir: &Path) -> Option<Result<Intrinsics, Error>> {
    let calib = dir.join("calibration.txt");
    if !calib.is_file() {
        return None;
    }
    let text = match std::fs::read_to_string(&calib) {
        Ok(t) => t,
        Err(e) => return Some(Err(Error::file(&calib, e))),
    };
    let (n, line) = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .find(|(_, l)| !l.is_empty() && !l.starts_with('#'))
        .unwrap_or((0, ""));
    Some(Intrinsics::parse(line).map_err(|e| Error::line(&calib, n, e)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fisheye_is_written_kb_and_its_coefficients_kept() {
        let k = Intrinsics::parse("kb:190.97,190.97,254.93,256.90,0.0035,0.0007,-0.0021,0.0002").unwrap();
        assert_eq!(k.model, LensModel::KannalaBrandt);
        assert_eq!(k.distortion, [0.0035, 0.0007, -0.0021, 0.0002, 0.0]);
        assert_eq!(k.camera_info(512, 512).model, LensModel::KannalaBrandt);
        assert_eq!(Intrinsics::parse("fr1").unwrap().model, LensModel::BrownConrady);
        for bad in ["kb:190,190,250,250,0.1,0.2,0.3", "kb:0,190,250,250,0,0,0,0"] {
            let e = Intrinsics::parse(bad).unwrap_err().to_string();
            assert!(e.contains("kb:fx,fy,cx,cy,k1,k2,k3,k4"), "{bad}: {e}");
        }
        let e = Intrinsics::parse("kb:1,2,3,4,5,6,7,x").unwrap_err().to_string();
        assert!(e.contains("`x` is not a number"), "{e}");
    }
}
