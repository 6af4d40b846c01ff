//! Readers of recorded sequences: TUM RGB-D folders (`tum_rgbd`), and the pieces they share:
//! intrinsics presets, timestamp index files, PNG decoding with bit-depth checks.
//!
//! Split: `index` (timestamped list files, association, ground-truth interpolation),
//! `intrinsics` (presets and parsing), `png` (image loading), `tum` (the operator).

mod index;
mod intrinsics;
mod png;
mod tum;

pub use index::{Associated, IndexError, associate, interpolate_pose, read_index, read_trajectory};
pub use intrinsics::{Intrinsics, preset_for_folder};
pub use png::{load_depth, load_rgb};
pub(crate) use tum::TUM_RGBD;
