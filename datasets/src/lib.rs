//! dynaflow's sequences as a plain library, usable without the engine, an async runtime, a
//! GPU or an inference backend: generate a dynamic scene or read a recorded one.
//!
//! - [`synth`]: the semi-synthetic dynamic RGB-D generator with exact ground truth, and its
//!   writer in the TUM RGB-D layout.
//! - [`tum`]: TUM RGB-D sequence folders: index files, association, ground truth, frames.
//! - [`kitti`]: KITTI odometry sequence folders: calibration, times, poses, stereo frames.
//! - [`folder`]: folders of images (and depth PNGs) in name order.
//! - [`intrinsics`]: camera intrinsics (TUM's published presets, explicit values,
//!   `calibration.txt`).
//! - [`png`]: colour and depth PNG loading with format checks.
//!
//! Frames come as `dynaflow-msg` payloads, so the operators that stream them into a graph
//! only wrap them. Every error names the file (and line) it is about: [`Error`].

#![warn(missing_docs)]

pub mod folder;
pub mod intrinsics;
pub mod kitti;
pub mod png;
pub mod synth;
pub mod tum;

use std::path::{Path, PathBuf};

/// What reading or writing a sequence can fail with.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file is missing, unreadable or malformed: `file:line: message` (no line when the
    /// whole file is meant).
    #[error("{}{}: {message}", path.display(), if *line == 0 { String::new() } else { format!(":{line}") })]
    File {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 for the whole file).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// Files that do not fit together (sizes, stamps); the message names them.
    #[error("{0}")]
    Data(String),
    /// Intrinsics written by a user (a graph parameter, a flag, a `calibration.txt` line) are
    /// not a preset name or positive focal lengths and a principal point.
    #[error("{0}")]
    Intrinsics(String),
    /// A folder's camera cannot be told (no known name, no `calibration.txt`): the caller has
    /// to give the intrinsics.
    #[error("{}: cannot tell the camera: the folder is not named `rgbd_dataset_freiburgN_*` and has no calibration.txt; set `intrinsics: fr1|fr2|fr3|fx,fy,cx,cy` (or `--intrinsics`)", dir.display())]
    UnknownCamera {
        /// The folder.
        dir: PathBuf,
    },
}

impl Error {
    /// A problem with `path` as a whole.
    pub fn file(path: &Path, message: impl std::fmt::Display) -> Self {
        Error::File { path: path.to_path_buf(), line: 0, message: message.to_string() }
    }
    /// A problem at `line` of `path`.
    pub fn line(path: &Path, line: usize, message: impl std::fmt::Display) -> Self {
        Error::File { path: path.to_path_buf(), line, message: message.to_string() }
    }
}
