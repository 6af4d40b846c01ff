//! dynaflow's sequences as a plain library, usable without the engine, an async runtime, a
//! GPU or an inference backend: generate a dynamic scene or read a recorded one.
//!
//! - [`synth`]: the semi-synthetic dynamic RGB-D generator with exact ground truth, and its
//!   writer in the TUM RGB-D layout.
//! - [`tum`]: TUM RGB-D sequence folders: index files, association, ground truth, frames.
//! - [`kitti`]: KITTI odometry sequence folders: calibration, times, poses, stereo frames.
//! - [`euroc`]: EuRoC MAV (ASL) folders: cameras, IMU, ground truth, `sensor.yaml` extrinsics.
//! - [`folder`]: folders of images (and depth PNGs) in name order.
//! - [`imu`]: an IMU stream checked against stated rules and cut into one batch per frame.
//! - [`intrinsics`]: camera intrinsics (TUM's published presets, explicit values,
//!   `calibration.txt`).
//! - [`png`]: colour and depth PNG loading with format checks.
//!
//! Frames come as `dynaflow-msg` payloads, so the operators that stream them into a graph
//! only wrap them. Every error names the file (and line) it is about: [`Error`].

#![warn(missing_docs)]

pub mod euroc;
pub mod folder;
pub mod imu;
pub mod intrinsics;
pub mod kitti;
pub mod png;
pub mod synth;
pub mod tum;

use std::path::{Path, PathBuf};

/// A recorded (or generated) sequence, read frame by frame: what a source operator streams.
/// The readers differ in their files; the operators stream all of them the same way.
pub trait Sequence: Send + 'static {
    /// One frame.
    type Frame;
    /// Frames in the sequence.
    fn len(&self) -> usize;
    /// Whether it has no frame.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Frame `index`; `None` past the end. An error names the file.
    fn read(&mut self, index: usize) -> Result<Option<Self::Frame>, Error>;
    /// A frame's sensor time, seconds.
    fn stamp(frame: &Self::Frame) -> f64;
    /// At the start of a run, the seed a generated sequence draws from (a recorded one has
    /// nothing to draw and ignores it).
    fn seed(&mut self, _seed: u64) {}
}

/// A reader with inherent `len` and `frame` and a frame with a `stamp` is a [`Sequence`].
macro_rules! sequence {
    ($reader:ty, $frame:ty) => {
        impl Sequence for $reader {
            type Frame = $frame;
            fn len(&self) -> usize {
                <$reader>::len(self)
            }
            fn read(&mut self, index: usize) -> Result<Option<$frame>, Error> {
                self.frame(index)
            }
            fn stamp(frame: &$frame) -> f64 {
                frame.stamp
            }
        }
    };
}

sequence!(tum::TumSequence, tum::TumFrame);
sequence!(kitti::KittiSequence, kitti::KittiFrame);
sequence!(folder::ImageFolder, folder::FolderFrame);
sequence!(euroc::EurocSequence, euroc::EurocFrame);

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
