//! Readers of recorded sequences: TUM RGB-D folders (`tum_rgbd`), image folders
//! (`image_folder`), KITTI odometry sequences (`kitti_odometry`), layout detection for `--input`, and the pieces they share:
//! intrinsics presets, timestamp index files, PNG decoding with bit-depth checks.
//!
//! Split: `folder` (image folders, layout detection), `index` (timestamped list files, association, ground-truth interpolation),
//! `intrinsics` (presets and parsing), `kitti` (the KITTI reader), `png` (image loading), `tum` (the operator).

mod folder;
mod index;
mod intrinsics;
mod kitti;
mod png;
mod tum;

pub(crate) use folder::IMAGE_FOLDER;
pub use folder::{Layout, detect_layout};
pub use index::{Associated, IndexError, associate, interpolate_pose, nearest_pose, read_index, read_trajectory};
pub use intrinsics::{Intrinsics, preset_for_folder};
pub(crate) use kitti::KITTI_ODOMETRY;
pub use png::{load_depth, load_rgb};
pub(crate) use tum::TUM_RGBD;
