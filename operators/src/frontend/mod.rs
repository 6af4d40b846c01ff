//! The geometric front-end operators: thin wrappers over `dynaflow-vision`.
//!
//! - `orb`: `orb_extract` (ORB-SLAM-style ORB features).
//! - `matching`: `match_descriptors` (frame-to-frame Hamming matching with stable track ids).
//! - `flow`: `lk_flow` (pyramidal Lucas-Kanade tracking with re-seeding).
//! - `stereo`: `stereo_match` (ORB-SLAM2's sparse stereo matching into a right image).

mod flow;
mod matching;
mod orb;
mod stereo;

pub use flow::LK_FLOW;
pub use matching::MATCH_DESCRIPTORS;
pub use orb::ORB_EXTRACT;
pub use stereo::STEREO_MATCH;

use dynaflow_engine::msg::{Image, PixelFormat};
use dynaflow_engine::op::OpError;
use dynaflow_vision::GrayImage;

/// The grey image of an image (RGB converted with OpenCV's weights).
fn gray(image: &Image) -> Result<GrayImage, OpError> {
    let Image { width, height, format, data } = image;
    let (w, h) = (*width as usize, *height as usize);
    let img = match format {
        PixelFormat::Gray8 => GrayImage::from_vec(w, h, data.clone()),
        PixelFormat::Rgb8 => GrayImage::from_rgb8(w, h, data),
    };
    img.ok_or_else(|| OpError::Input(format!("image {w}x{h} {format:?} has {} bytes", data.len())))
}
