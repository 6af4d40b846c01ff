//! The crate's one error type.

use std::path::PathBuf;

/// What can go wrong encoding pixels, reaching a live viewer, or diffing recordings.
#[derive(Clone, Debug, thiserror::Error)]
pub enum Error {
    /// A pixel codec refused an image.
    #[error("{0}")]
    Encode(String),
    /// The live viewer's URL is malformed or nothing answers there.
    #[error("{0}")]
    Viewer(String),
    /// A recording is missing, unreadable or not a dynaflow MCAP.
    #[error("{}: {message}", path.display())]
    BadInput {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A `--tol` argument is malformed.
    #[error("bad tolerance `{0}`: expected PATTERN=VALUE or PATTERN:METRIC=VALUE, e.g. `/orb/*=0.5`")]
    BadTolerance(String),
    /// The overlay recording could not be written.
    #[error("{0}")]
    Overlay(String),
}
