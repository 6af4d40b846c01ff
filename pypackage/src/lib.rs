//! `dynaflow._native`: what the `dynaflow` Python package (`pypackage/python/dynaflow`) calls.
//! Each function is a thin wrapper over the library the CLI uses, run with the interpreter
//! released (a run's Python operators take it back on their own threads).
//!
//! - `cli(args)`: the `dynaflow` command line in this process (`dynaflow.run`), its exit status;
//! - `read_recording(path)`: an MCAP recording as JSON (`dynaflow.Recording`);
//! - `evaluate(gt, est, align, max_diff, rpe_delta)`: `dynaflow eval --json`'s report as JSON;
//! - `version()`.

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;

/// A trajectory from Python: a file (TUM, or a EuRoC ground-truth CSV) or rows of
/// `stamp tx ty tz qx qy qz qw`.
#[derive(FromPyObject)]
enum Trajectory {
    Path(String),
    Rows(Vec<[f64; 8]>),
}

impl Trajectory {
    fn poses(self) -> PyResult<Vec<dynaflow_slam::eval::Stamped>> {
        match self {
            // As `dynaflow eval` reads its ground truth: a EuRoC CSV or a TUM file.
            Self::Path(p) => dynaflow::cli::read_ground_truth(std::path::Path::new(&p)).map_err(PyOSError::new_err),
            Self::Rows(rows) => rows
                .iter()
                .map(|r| {
                    let q = nalgebra_quaternion(r[4], r[5], r[6], r[7])?;
                    Ok((r[0], nalgebra::Isometry3::from_parts(nalgebra::Translation3::new(r[1], r[2], r[3]), q)))
                })
                .collect(),
        }
    }
}

fn nalgebra_quaternion(x: f64, y: f64, z: f64, w: f64) -> PyResult<nalgebra::UnitQuaternion<f64>> {
    let q = nalgebra::Quaternion::new(w, x, y, z);
    let n = q.norm();
    if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
        return Err(PyValueError::new_err(format!("quaternion ({x}, {y}, {z}, {w}) is not unit (norm {n})")));
    }
    Ok(nalgebra::UnitQuaternion::from_quaternion(q))
}

/// The `dynaflow` command line with `args` (the first is the program name), in this process;
/// its exit status.
#[pyfunction]
fn cli(py: Python<'_>, args: Vec<String>) -> u8 {
    // Ctrl-C stays Python's: a run started from Python ends at its own pace.
    dynaflow::cli::leave_signals_to_the_host();
    py.detach(|| dynaflow::cli::main_with(args))
}

/// The recording at `path` as JSON: `metadata`, `truncated`, and `topics` (name to `type` and
/// `frames`, frame number to the message's dynaflow object).
#[pyfunction]
fn read_recording(py: Python<'_>, path: &str) -> PyResult<String> {
    let rec = py
        .detach(|| dynaflow_recordings::diff::read_mcap(std::path::Path::new(path)))
        .map_err(|e| PyOSError::new_err(e.to_string()))?;
    let topics: serde_json::Map<String, serde_json::Value> = rec
        .topics
        .into_iter()
        .map(|(name, t)| {
            let frames: serde_json::Map<String, serde_json::Value> =
                t.frames.into_iter().map(|(seq, v)| (seq.to_string(), v)).collect();
            (name, serde_json::json!({ "type": t.ty, "schema": t.schema, "frames": frames }))
        })
        .collect();
    Ok(serde_json::json!({ "metadata": rec.metadata, "truncated": rec.truncated, "topics": topics }).to_string())
}

/// `dynaflow eval --json`'s report of `est` against `gt`.
#[pyfunction]
fn evaluate(
    py: Python<'_>,
    gt: Trajectory,
    est: Trajectory,
    align: &str,
    max_diff: f64,
    rpe_delta: usize,
) -> PyResult<String> {
    use dynaflow_slam::eval::{Align, RpeDelta, evaluate_with};
    let align = match align {
        "se3" => Align::Se3,
        "sim3" => Align::Sim3,
        "none" => Align::None,
        other => return Err(PyValueError::new_err(format!("align `{other}`: se3, sim3 or none"))),
    };
    if !(max_diff.is_finite() && max_diff >= 0.0) || rpe_delta == 0 {
        return Err(PyValueError::new_err("max_diff must be >= 0 seconds and rpe_delta >= 1 frame"));
    }
    let (gt, est) = (gt.poses()?, est.poses()?);
    let report = py
        .detach(|| evaluate_with(&gt, &est, max_diff, align, RpeDelta::Frames(rpe_delta)))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    serde_json::to_string(&report).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The version of dynaflow this module was built from.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(cli, m)?)?;
    m.add_function(wrap_pyfunction!(read_recording, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    Ok(())
}
