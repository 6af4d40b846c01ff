//! Helpers of the vision tests: the peers, a temporary folder, the front-end's images and the
//! OpenCV side.
#![allow(dead_code)]

pub mod frontend;
#[path = "../../../tests/common/peers.rs"]
pub mod peers;
pub mod stereo;
#[path = "../../../tests/common/tempdir.rs"]
mod tempdir;
pub use tempdir::TempDir;
