//! Pixel encodings shared by the recorders: JPEG for colour images, PNG for grey images,
//! 16-bit millimetre depth and class masks (lossless, and tiny for label images).

use std::io::Cursor;

use dynaflow_engine::msg::{DepthImage, Image, PixelFormat, SegmentationMask};
use image::{ExtendedColorType, ImageEncoder};

/// How colour images are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageCodec {
    /// JPEG at the given quality (1–100): small, lossy.
    Jpeg(u8),
    /// PNG: lossless.
    Png,
}

/// An encoded image: bytes plus the format name (`jpeg` or `png`).
pub struct Encoded {
    /// File contents.
    pub bytes: Vec<u8>,
    /// `jpeg` or `png`.
    pub format: &'static str,
}

fn png(data: &[u8], w: u32, h: u32, color: ExtendedColorType) -> Result<Encoded, String> {
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut bytes,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(data, w, h, color)
    .map_err(|e| e.to_string())?;
    Ok(Encoded { bytes, format: "png" })
}

/// Encode an 8-bit image.
pub fn image(img: &Image, codec: ImageCodec) -> Result<Encoded, String> {
    let color = match img.format {
        PixelFormat::Rgb8 => ExtendedColorType::Rgb8,
        PixelFormat::Gray8 => ExtendedColorType::L8,
    };
    match codec {
        ImageCodec::Jpeg(q) => {
            let mut cursor = Cursor::new(Vec::new());
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut cursor, q)
                .write_image(&img.data, img.width, img.height, color)
                .map_err(|e| e.to_string())?;
            Ok(Encoded { bytes: cursor.into_inner(), format: "jpeg" })
        }
        ImageCodec::Png => png(&img.data, img.width, img.height, color),
    }
}

/// Depth in metres → 16-bit PNG in millimetres (0 = no measurement, saturates at 65.535 m).
pub fn depth_png_mm(depth: &DepthImage) -> Result<Encoded, String> {
    let mut be = Vec::with_capacity(depth.data.len() * 2);
    for &d in &depth.data {
        let mm = if d.is_finite() && d > 0.0 { (d * 1000.0).round().clamp(0.0, 65535.0) as u16 } else { 0 };
        // The PNG encoder takes 16-bit samples in native byte order.
        be.extend_from_slice(&mm.to_ne_bytes());
    }
    png(&be, depth.width, depth.height, ExtendedColorType::L16)
}

/// Class mask → 8-bit PNG when ids fit, else 16-bit.
pub fn mask_png(mask: &SegmentationMask) -> Result<Encoded, String> {
    if mask.classes.iter().all(|&c| c <= 255) {
        let bytes: Vec<u8> = mask.classes.iter().map(|&c| c as u8).collect();
        png(&bytes, mask.width, mask.height, ExtendedColorType::L8)
    } else {
        let bytes: Vec<u8> = mask.classes.iter().flat_map(|c| c.to_ne_bytes()).collect();
        png(&bytes, mask.width, mask.height, ExtendedColorType::L16)
    }
}
