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
#[derive(Debug)]
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

/// Encodings shared between recorders: the rerun and MCAP recorders both store colour images
/// as JPEG/PNG and depth as 16-bit PNG; with a shared cache each message is encoded once.
///
/// Entries are keyed by the message's address (both recorders receive the same `Arc`, so the
/// address cannot be reused while an entry is pending) plus frame and kind, and removed once
/// every user has taken them; a bounded size guards against a recorder that stopped.
#[derive(Clone, Debug, Default)]
pub struct EncodeCache {
    inner: std::sync::Arc<std::sync::Mutex<CacheState>>,
    users: usize,
}

type Slot = std::sync::Arc<std::sync::OnceLock<Result<std::sync::Arc<Encoded>, String>>>;

#[derive(Debug, Default)]
struct CacheState {
    entries: std::collections::HashMap<(usize, u64, u8), (Slot, usize)>,
    order: std::collections::VecDeque<(usize, u64, u8)>,
}

/// Most pending encodings kept (frames × kinds) before the oldest are dropped.
const CACHE_CAPACITY: usize = 256;

impl EncodeCache {
    /// A cache shared by `users` recorders.
    pub fn new(users: usize) -> Self {
        Self { inner: std::sync::Arc::default(), users }
    }

    /// Encodings waiting for a user that has not taken them yet (0 once every recorder has
    /// taken every encoding).
    pub fn pending(&self) -> usize {
        self.inner.lock().unwrap_or_else(std::sync::PoisonError::into_inner).entries.len()
    }

    /// The encoding of `msg` (kind `kind`), computed by `encode` by the first user to ask.
    pub fn get_or_encode(
        &self,
        msg: &dynaflow_engine::msg::Message,
        kind: u8,
        encode: impl FnOnce() -> Result<Encoded, String>,
    ) -> Result<std::sync::Arc<Encoded>, String> {
        if self.users <= 1 {
            return encode().map(std::sync::Arc::new);
        }
        let key = (std::ptr::from_ref(msg) as usize, msg.header.seq, kind);
        let slot = {
            let mut st = self.inner.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            let slot = match st.entries.get_mut(&key) {
                Some((slot, taken)) => {
                    *taken += 1;
                    slot.clone()
                }
                None => {
                    let slot: Slot = std::sync::Arc::default();
                    st.entries.insert(key, (slot.clone(), 1));
                    st.order.push_back(key);
                    while st.order.len() > CACHE_CAPACITY {
                        if let Some(old) = st.order.pop_front() {
                            st.entries.remove(&old);
                        }
                    }
                    slot
                }
            };
            if st.entries.get(&key).is_some_and(|(_, taken)| *taken >= self.users) {
                st.entries.remove(&key);
                st.order.retain(|k| *k != key);
            }
            slot
        };
        slot.get_or_init(|| encode().map(std::sync::Arc::new)).clone()
    }
}
