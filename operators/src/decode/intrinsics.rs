//! Camera intrinsics for TUM sequences: the published presets, explicit values, or the
//! `calibration.txt` written by `dynaflow synth`.

use std::path::Path;

/// Pinhole intrinsics with OpenCV-order distortion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Focal length x.
    pub fx: f64,
    /// Focal length y.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
    /// `[k1, k2, p1, p2, k3]`.
    pub distortion: [f64; 5],
}

/// TUM fr1 (ROS default calibration as published with the dataset).
pub const FR1: Intrinsics =
    Intrinsics { fx: 517.3, fy: 516.5, cx: 318.6, cy: 255.3, distortion: [0.2624, -0.9531, -0.0054, 0.0026, 1.1633] };
/// TUM fr2.
pub const FR2: Intrinsics =
    Intrinsics { fx: 520.9, fy: 521.0, cx: 325.1, cy: 249.7, distortion: [0.2312, -0.7849, -0.0033, -0.0001, 0.9172] };
/// TUM fr3 (images are already undistorted).
pub const FR3: Intrinsics = Intrinsics { fx: 535.4, fy: 539.2, cx: 320.1, cy: 247.6, distortion: [0.0; 5] };

impl Intrinsics {
    /// `fr1`, `fr2`, `fr3`, or `fx,fy,cx,cy[,k1,k2,p1,p2,k3]`.
    pub fn parse(text: &str) -> Result<Self, String> {
        match text.trim() {
            "fr1" => return Ok(FR1),
            "fr2" => return Ok(FR2),
            "fr3" => return Ok(FR3),
            _ => {}
        }
        let v: Vec<f64> = text
            .split([',', ' ', '\t'])
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<f64>().map_err(|_| format!("`{s}` is not a number")))
            .collect::<Result<_, _>>()?;
        let ok = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match v.as_slice() {
            [fx, fy, cx, cy] if ok(&v) && *fx > 0.0 && *fy > 0.0 => {
                Ok(Self { fx: *fx, fy: *fy, cx: *cx, cy: *cy, distortion: [0.0; 5] })
            }
            [fx, fy, cx, cy, k1, k2, p1, p2, k3] if ok(&v) && *fx > 0.0 && *fy > 0.0 => {
                Ok(Self { fx: *fx, fy: *fy, cx: *cx, cy: *cy, distortion: [*k1, *k2, *p1, *p2, *k3] })
            }
            _ => Err(format!(
                "expected `fr1`, `fr2`, `fr3`, `fx,fy,cx,cy` or `fx,fy,cx,cy,k1,k2,p1,p2,k3` with positive focal lengths, got `{text}`"
            )),
        }
    }
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
pub fn read_calibration(dir: &Path) -> Option<Result<Intrinsics, dynaflow_engine::op::OpError>> {
    use dynaflow_engine::op::OpError;
    let calib = dir.join("calibration.txt");
    if !calib.is_file() {
        return None;
    }
    let text = match std::fs::read_to_string(&calib) {
        Ok(t) => t,
        Err(source) => return Some(Err(OpError::Io { path: calib, source })),
    };
    let line = text.lines().map(str::trim).find(|l| !l.is_empty() && !l.starts_with('#')).unwrap_or("");
    Some(
        Intrinsics::parse(line)
            .map_err(|e| OpError::Config { key: "intrinsics".into(), message: format!("{}: {e}", calib.display()) }),
    )
}
