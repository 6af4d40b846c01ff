//! Pixels and intrinsics.

use super::Digest;

/// Pixel layout of an [`Image`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PixelFormat {
    /// 3 bytes per pixel, R G B.
    Rgb8,
    /// 1 byte per pixel.
    Gray8,
}

impl PixelFormat {
    /// Bytes per pixel.
    pub fn channels(self) -> usize {
        match self {
            PixelFormat::Rgb8 => 3,
            PixelFormat::Gray8 => 1,
        }
    }
    /// Name for logs and schemas.
    pub fn name(self) -> &'static str {
        match self {
            PixelFormat::Rgb8 => "rgb8",
            PixelFormat::Gray8 => "gray8",
        }
    }
}

/// An 8-bit image, row-major, tightly packed.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixel layout.
    pub format: PixelFormat,
    /// `width * height * channels` bytes.
    pub data: Vec<u8>,
}

impl Image {
    /// An image of zeros.
    pub fn zeros(width: u32, height: u32, format: PixelFormat) -> Self {
        let len = width as usize * height as usize * format.channels();
        Self { width, height, format, data: vec![0; len] }
    }
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(u64::from(self.width));
        d.u64(u64::from(self.height));
        d.str(self.format.name());
        d.bytes(&self.data);
    }
}

/// A depth image in metres; `0.0` marks a missing measurement.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height` depths in metres.
    pub data: Vec<f32>,
}

impl DepthImage {
    /// Depth in metres at the pixel nearest `(x, y)`; 0 (no measurement) outside the image.
    pub fn at_nearest(&self, x: f32, y: f32) -> f32 {
        let (xi, yi) = (x.round(), y.round());
        if !(xi >= 0.0 && yi >= 0.0) || xi as usize >= self.width as usize || yi as usize >= self.height as usize {
            return 0.0;
        }
        self.data.get(yi as usize * self.width as usize + xi as usize).copied().unwrap_or(0.0)
    }

    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(u64::from(self.width));
        d.u64(u64::from(self.height));
        d.f32s(&self.data);
    }
}

/// How a camera's lens bends rays beyond the pinhole, as ROS's `CameraInfo.distortion_model`
/// names it; the coefficients are [`CameraInfo::distortion`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LensModel {
    /// Brown-Conrady `[k1, k2, p1, p2, k3]` (OpenCV's, ROS's `plumb_bob`); all zero: an ideal
    /// pinhole.
    #[default]
    BrownConrady,
    /// Kannala-Brandt fisheye `[k1, k2, k3, k4, 0]` (OpenCV's `fisheye`, ROS's `equidistant`,
    /// EuRoC/Kalibr's `equidistant`).
    KannalaBrandt,
}

/// Pinhole intrinsics with the lens's distortion: Brown–Conrady `[k1, k2, p1, p2, k3]` (OpenCV
/// order) or Kannala-Brandt `[k1, k2, k3, k4, 0]` ([`LensModel`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CameraInfo {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Focal length x (pixels).
    pub fx: f64,
    /// Focal length y (pixels).
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
    /// Distortion coefficients, OpenCV order, of `model`.
    pub distortion: [f64; 5],
    /// The lens model the coefficients belong to.
    pub model: LensModel,
}

impl CameraInfo {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(u64::from(self.width));
        d.u64(u64::from(self.height));
        for v in [self.fx, self.fy, self.cx, self.cy].iter().chain(&self.distortion) {
            d.f64(*v);
        }
        // Brown-Conrady adds nothing, so digests from before the lens model stay valid.
        if self.model == LensModel::KannalaBrandt {
            d.u64(1);
        }
    }
}

/// A rectified stereo pair: the right camera lies `baseline` metres along the left camera's x
/// axis, and both images share the left camera's intrinsics ([`CameraInfo`]), so a match at
/// disparity `d` pixels lies at depth `fx * baseline / d`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct StereoRig {
    /// Distance between the optical centres, metres (positive).
    pub baseline: f64,
}

impl StereoRig {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.f64(self.baseline);
    }
}
