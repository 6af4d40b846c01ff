//! Semantic results: detections and segmentation masks.

use std::sync::Arc;

use super::Digest;

/// One detected object, box in pixels `[x_min, y_min, x_max, y_max]`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Detection {
    /// Axis-aligned box, pixels.
    pub bbox: [f32; 4],
    /// Class index of the model (e.g. COCO-80).
    pub class_id: u32,
    /// Class name.
    pub label: Arc<str>,
    /// Confidence in `[0, 1]`.
    pub score: f32,
}

/// Detections of one image.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Detections {
    /// The detections, highest score first.
    pub detections: Vec<Detection>,
}

impl Detections {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(self.detections.len() as u64);
        for det in &self.detections {
            for v in det.bbox {
                d.f32(v);
            }
            d.u64(u64::from(det.class_id));
            d.str(&det.label);
            d.f32(det.score);
        }
    }
}

/// Per-pixel class ids (0 = background) and optional instance ids.
#[derive(Clone, Debug, PartialEq)]
pub struct SegmentationMask {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height` class ids.
    pub classes: Vec<u16>,
    /// `width * height` instance ids, if known.
    pub instances: Option<Vec<u16>>,
    /// Name of each class id.
    pub class_names: Vec<Arc<str>>,
}

impl SegmentationMask {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(u64::from(self.width));
        d.u64(u64::from(self.height));
        d.u16s(&self.classes);
        if let Some(inst) = &self.instances {
            d.u16s(inst);
        }
        for n in &self.class_names {
            d.str(n);
        }
    }
}

/// A distinct, stable colour per class id (golden-ratio hue steps): what every recorder and
/// the octree files use, so a class looks the same everywhere.
pub fn class_rgb(id: u16) -> [u8; 3] {
    let h = (f32::from(id) * 0.618_034).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    [(r * 220.0) as u8 + 35, (g * 220.0) as u8 + 35, (b * 220.0) as u8 + 35]
}
