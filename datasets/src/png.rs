//! Loading colour and depth PNGs with explicit format checks.

use std::path::Path;

use dynaflow_msg::{DepthImage, Image, PixelFormat};
use image::{DynamicImage, ImageReader};

use crate::Error;

fn open(path: &Path) -> Result<DynamicImage, Error> {
    ImageReader::open(path)
        .map_err(|e| Error::file(path, e))?
        .with_guessed_format()
        .map_err(|e| Error::file(path, e))?
        .decode()
        .map_err(|e| Error::file(path, format!("cannot decode: {e}")))
}

/// An 8-bit colour (or grey, kept grey) image.
pub fn load_rgb(path: &Path) -> Result<Image, Error> {
    match open(path)? {
        DynamicImage::ImageRgb8(img) => {
            Ok(Image { width: img.width(), height: img.height(), format: PixelFormat::Rgb8, data: img.into_raw() })
        }
        DynamicImage::ImageRgba8(img) => {
            let rgb = DynamicImage::ImageRgba8(img).into_rgb8();
            Ok(Image { width: rgb.width(), height: rgb.height(), format: PixelFormat::Rgb8, data: rgb.into_raw() })
        }
        DynamicImage::ImageLuma8(img) => {
            Ok(Image { width: img.width(), height: img.height(), format: PixelFormat::Gray8, data: img.into_raw() })
        }
        other => Err(Error::file(path, format!("expected an 8-bit colour image, found {:?}", other.color()))),
    }
}

/// A 16-bit depth PNG, `value / factor` metres (0 = no measurement).
pub fn load_depth(path: &Path, factor: f64) -> Result<DepthImage, Error> {
    match open(path)? {
        DynamicImage::ImageLuma16(img) => {
            let (width, height) = (img.width(), img.height());
            let data = img.into_raw().into_iter().map(|v| (f64::from(v) / factor) as f32).collect();
            Ok(DepthImage { width, height, data })
        }
        other => Err(Error::file(
            path,
            format!(
                "expected a 16-bit single-channel depth PNG, found {:?} (TUM depth is 16-bit, {factor} per metre)",
                other.color()
            ),
        )),
    }
}

/// `a` (of `a_size`) must cover `b` (of `b_size`) pixel for pixel: a depth, mask or second
/// camera image read at another image's coordinates. The error names both files and sizes.
pub fn same_size(
    a: impl std::fmt::Display,
    a_size: (u32, u32),
    b: impl std::fmt::Display,
    b_size: (u32, u32),
) -> Result<(), Error> {
    if a_size == b_size {
        return Ok(());
    }
    Err(Error::Data(format!("{a}: {}x{} but {b} is {}x{}", a_size.0, a_size.1, b_size.0, b_size.1)))
}
