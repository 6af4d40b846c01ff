//! The geometric front-end operators: thin wrappers over `dynaflow-vision`.
//!
//! - `orb`: `orb_extract` (ORB-SLAM-style ORB features).
//! - `matching`: `match_descriptors` (frame-to-frame Hamming matching with stable track ids).
//! - `flow`: `lk_flow` (pyramidal Lucas-Kanade tracking with re-seeding).
//! - `stereo`: `stereo_match` (ORB-SLAM2's sparse stereo matching into a right image).
//! - `undistort`: a distorted or fisheye camera's images resampled to an ideal pinhole.

mod flow;
mod matching;
mod orb;
mod stereo;
mod undistort;

pub use flow::LK_FLOW;
pub use matching::MATCH_DESCRIPTORS;
pub use orb::ORB_EXTRACT;
pub use stereo::STEREO_MATCH;
pub use undistort::UNDISTORT;

use dynaflow_engine::msg::{Image, Keypoints, PixelFormat, StereoRig};
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

/// The 32-byte ORB descriptors of `keypoints`, one per keypoint, as one byte slice (empty
/// when there are no keypoints); an error naming the fix for anything else.
pub(crate) fn orb_descriptors(keypoints: &Keypoints) -> Result<&[u8], OpError> {
    match &keypoints.descriptors {
        Some(d) if d.bytes_per == 32 && d.data.len() == 32 * keypoints.points.len() => Ok(&d.data),
        Some(d) if keypoints.points.is_empty() || d.data.is_empty() => Ok(&d.data),
        _ => Err(OpError::Input("`keypoints` need 32-byte ORB descriptors (connect `orb_extract.keypoints`)".into())),
    }
}

/// Refuses a Kannala-Brandt (fisheye) camera where `what` needs pinhole geometry: the model
/// is read and recorded, and ORB and LK run on fisheye images, but tracking, stereo matching
/// and the depth-based operators project through a pinhole.
pub(crate) fn pinhole_only(k: &dynaflow_engine::msg::CameraInfo, what: &str) -> Result<(), OpError> {
    if k.model == dynaflow_engine::msg::LensModel::KannalaBrandt {
        return Err(OpError::Input(format!(
            "`camera_info` is a Kannala-Brandt (fisheye) camera: {what} projects through a pinhole and would be wrong on it; put an `undistort` node before it (ORB and LK run on fisheye images)"
        )));
    }
    Ok(())
}

/// A stereo rig's baseline, metres: positive and finite, or an error saying what is wrong.
pub(crate) fn stereo_baseline(rig: &StereoRig) -> Result<f64, OpError> {
    let b = rig.baseline;
    if !(b > 0.0 && b.is_finite()) {
        return Err(OpError::Input(format!("the stereo baseline is {b} m; it must be positive")));
    }
    Ok(b)
}
