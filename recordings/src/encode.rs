//! Pixel encodings shared by the recorders: JPEG (SIMD, `jpeg-encoder`) or PNG for colour
//! images; raw little-endian samples for depth and masks, which the containers compress
//! (MCAP chunks with zstd, `.rrd` chunks with LZ4).

use crate::Error;
use dynaflow_engine::msg::{DepthImage, Image, PixelFormat, SegmentationMask};
use image::{ExtendedColorType, ImageEncoder};

/// How colour images are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageCodec {
    /// JPEG at the given quality (1–100): small, lossy.
    Jpeg(u8),
    /// PNG: lossless, slow.
    Png,
    /// Raw pixels (`foxglove.RawImage` `rgb8`/`mono8`, rerun `Image`): lossless, fast,
    /// compressed only by the container.
    Raw,
}

impl ImageCodec {
    /// The codec a `--image-format` name selects (`jpeg`, `png`, `raw`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "jpeg" | "jpg" => Some(Self::Jpeg(90)),
            "png" => Some(Self::Png),
            "raw" => Some(Self::Raw),
            _ => None,
        }
    }
}

/// An encoded image: bytes plus the format name (`jpeg` or `png`).
#[derive(Debug)]
pub struct Encoded {
    /// File contents.
    pub bytes: Vec<u8>,
    /// `jpeg` or `png`.
    pub format: &'static str,
}

/// PNG (fast compression, adaptive filter) of 8- or 16-bit samples in native byte order.
pub fn png(data: &[u8], w: u32, h: u32, color: ExtendedColorType) -> Result<Encoded, Error> {
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new_with_quality(
        &mut bytes,
        image::codecs::png::CompressionType::Fast,
        image::codecs::png::FilterType::Adaptive,
    )
    .write_image(data, w, h, color)
    .map_err(|e| Error::Encode(e.to_string()))?;
    Ok(Encoded { bytes, format: "png" })
}

/// JPEG through `jpeg-encoder` (AVX2 when the CPU has it; 2.1x faster than `image`'s encoder
/// on 640×480 colour, docs/benchmarks.md), `image`'s encoder beyond 65535 pixels a side.
///
/// Chroma is subsampled 2×2 (4:2:0) at every quality: libjpeg's default, what OpenCV's
/// `imwrite` and Pillow write (`jpeg-encoder` alone keeps full chroma from q90 up, which
/// costs twice the blocks).
fn jpeg(img: &Image, quality: u8) -> Result<Encoded, Error> {
    jpeg_with(img, quality, true)
}

/// [`jpeg`] with chroma subsampled 2×2 (`true`) or kept whole (4:4:4; for the recording
/// bench's comparison).
pub fn jpeg_with(img: &Image, quality: u8, subsample_chroma: bool) -> Result<Encoded, Error> {
    let sampling =
        if subsample_chroma { jpeg_encoder::SamplingFactor::F_2_2 } else { jpeg_encoder::SamplingFactor::F_1_1 };
    let (color, fallback) = match img.format {
        PixelFormat::Rgb8 => (jpeg_encoder::ColorType::Rgb, ExtendedColorType::Rgb8),
        PixelFormat::Gray8 => (jpeg_encoder::ColorType::Luma, ExtendedColorType::L8),
    };
    let mut bytes = Vec::with_capacity(img.data.len() / 6);
    match (u16::try_from(img.width), u16::try_from(img.height)) {
        (Ok(w), Ok(h)) => {
            let mut encoder = jpeg_encoder::Encoder::new(&mut bytes, quality.clamp(1, 100));
            encoder.set_sampling_factor(sampling);
            encoder.encode(&img.data, w, h, color).map_err(|e| Error::Encode(e.to_string()))?
        }
        _ => image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality)
            .write_image(&img.data, img.width, img.height, fallback)
            .map_err(|e| Error::Encode(e.to_string()))?,
    }
    Ok(Encoded { bytes, format: "jpeg" })
}

/// Encode an 8-bit image (JPEG or PNG; `Raw` has no file encoding and gives PNG).
pub fn image(img: &Image, codec: ImageCodec) -> Result<Encoded, Error> {
    let color = match img.format {
        PixelFormat::Rgb8 => ExtendedColorType::Rgb8,
        PixelFormat::Gray8 => ExtendedColorType::L8,
    };
    match codec {
        ImageCodec::Jpeg(q) => jpeg(img, q),
        ImageCodec::Png | ImageCodec::Raw => png(&img.data, img.width, img.height, color),
    }
}

/// The ROS/Foxglove encoding name of an 8-bit image's raw pixels.
pub fn raw_image_encoding(img: &Image) -> (&'static str, u32) {
    match img.format {
        PixelFormat::Rgb8 => ("rgb8", img.width * 3),
        PixelFormat::Gray8 => ("mono8", img.width),
    }
}

/// Depth as `32FC1` samples (metres, little-endian): exactly the message's values, whatever
/// the source's quantisation (TUM's 1/5000 m, Kinect disparity steps, float renderers).
pub fn depth_f32_le(depth: &DepthImage) -> Vec<u8> {
    let mut out = Vec::with_capacity(depth.data.len() * 4);
    depth_f32_le_into(depth, &mut out);
    out
}

/// [`depth_f32_le`], appended to `out`.
pub fn depth_f32_le_into(depth: &DepthImage, out: &mut Vec<u8>) {
    out.reserve(depth.data.len() * 4);
    for d in &depth.data {
        out.extend_from_slice(&d.to_le_bytes());
    }
}

/// Depth in whole millimetres (0 = no measurement, saturating at 65.535 m): what the viewer
/// shows, half the bytes of `32FC1`.
pub fn depth_mm(depth: &DepthImage) -> Vec<u16> {
    depth.data.iter().map(|&d| metres_to_mm(d)).collect()
}

/// [`depth_mm`] as little-endian bytes, built in one buffer (a frame's depth is 600 KB).
pub fn depth_mm_le(depth: &DepthImage) -> Vec<u8> {
    let mut out = vec![0u8; depth.data.len() * 2];
    for (o, &d) in out.chunks_exact_mut(2).zip(&depth.data) {
        o.copy_from_slice(&metres_to_mm(d).to_le_bytes());
    }
    out
}

/// Rounded half up from the exact product (`f32` times 1000 is exact in `f64`), without the
/// library call `f32::round` is on baseline x86-64; saturating.
fn metres_to_mm(d: f32) -> u16 {
    if d.is_finite() && d > 0.0 { (f64::from(d) * 1000.0 + 0.5) as u16 } else { 0 }
}

/// A class mask's raw samples: `mono8` when every id fits a byte, else `16UC1` little-endian;
/// returns `(samples, encoding, step)`.
pub fn mask_raw(mask: &SegmentationMask) -> (Vec<u8>, &'static str, u32) {
    let (encoding, step) = mask_encoding(mask);
    let mut out = Vec::with_capacity(step as usize * mask.height as usize);
    mask_raw_into(mask, encoding, &mut out);
    (out, encoding, step)
}

/// The encoding and row step [`mask_raw`] uses.
pub fn mask_encoding(mask: &SegmentationMask) -> (&'static str, u32) {
    if mask.classes.iter().all(|&c| c <= 255) { ("mono8", mask.width) } else { ("16UC1", mask.width * 2) }
}

/// [`mask_raw`]'s samples in `encoding` (from [`mask_encoding`]), appended to `out`.
pub fn mask_raw_into(mask: &SegmentationMask, encoding: &str, out: &mut Vec<u8>) {
    if encoding == "mono8" {
        out.extend(mask.classes.iter().map(|&c| c as u8));
    } else {
        out.extend(mask.classes.iter().flat_map(|c| c.to_le_bytes()));
    }
}

/// Encodings shared between recorders: the rerun, MCAP and live recorders all store colour
/// images as JPEG/PNG; with a shared cache each image is encoded once.
///
/// Entries are keyed by the message's content digest and the encoding kind, so the same
/// pixels recorded on two ports (a gate forwarding its input, as MG-SLAM's key-frame gate
/// does) are encoded once too. An entry moves to a short list of recent encodings once every
/// user has taken it (where a later port with the same pixels still finds it), and a bounded
/// size guards against a recorder that stopped.
#[derive(Clone, Debug, Default)]
pub struct EncodeCache {
    inner: std::sync::Arc<std::sync::Mutex<CacheState>>,
    users: usize,
}

type Slot = std::sync::Arc<std::sync::OnceLock<Result<std::sync::Arc<Encoded>, Error>>>;
type Key = (u64, u8);

#[derive(Debug, Default)]
struct CacheState {
    entries: std::collections::HashMap<Key, (Slot, usize)>,
    order: std::collections::VecDeque<Key>,
    recent: std::collections::VecDeque<(Key, Slot)>,
}

/// Most pending encodings kept (frames × kinds) before the oldest are dropped.
const CACHE_CAPACITY: usize = 256;
/// Encodings every user took, kept for another port with the same pixels.
const RECENT: usize = 8;

impl EncodeCache {
    /// A cache shared by `users` recorders.
    pub fn new(users: usize) -> Self {
        Self { inner: std::sync::Arc::default(), users: users.max(1) }
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
        encode: impl FnOnce() -> Result<Encoded, Error>,
    ) -> Result<std::sync::Arc<Encoded>, Error> {
        let key = (msg.digest(), kind);
        let slot = {
            let mut st = self.inner.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            if let Some((_, slot)) = st.recent.iter().find(|(k, _)| *k == key) {
                slot.clone()
            } else {
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
                    st.recent.push_back((key, slot.clone()));
                    if st.recent.len() > RECENT {
                        st.recent.pop_front();
                    }
                }
                slot
            }
        };
        slot.get_or_init(|| encode().map(std::sync::Arc::new)).clone()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use dynaflow_engine::msg::{Body, Header, Image, Message, PixelFormat};

    use super::{EncodeCache, Encoded, depth_mm, depth_mm_le};

    #[test]
    fn depth_in_millimetres_rounds_saturates_and_zeroes_what_is_not_a_measurement() {
        let data = vec![f32::NAN, -1.0, 0.0, 0.0004, 0.001_953_125, 1.25, 70.0, f32::INFINITY];
        let depth = dynaflow_engine::msg::DepthImage { width: 4, height: 2, data };
        let want: [u16; 8] = [0, 0, 0, 0, 2, 1250, 65535, 0];
        assert_eq!(depth_mm(&depth), want);
        let le: Vec<u8> = want.iter().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(depth_mm_le(&depth), le);
    }

    #[test]
    fn the_same_pixels_on_two_ports_are_encoded_once_and_nothing_stays_pending() {
        let cache = EncodeCache::new(2);
        let header = Header { seq: 3, stamp: 0.1, frame_id: Arc::from("camera") };
        let image = |v: u8| Body::Image(Image { width: 4, height: 2, format: PixelFormat::Rgb8, data: vec![v; 24] });
        let (rgb, forwarded, other) = (
            Message::new(header.clone(), image(7)),
            Message::new(header.clone(), image(7)),
            Message::new(header, image(8)),
        );
        let mut encoded = 0;
        let mut enc = || {
            encoded += 1;
            Ok(Encoded { bytes: vec![encoded], format: "png" })
        };
        // Recorder A, then B, each records `rgb` then the forwarded copy, then another image.
        for _ in 0..2 {
            for m in [&rgb, &forwarded] {
                assert_eq!(cache.get_or_encode(m, 0, &mut enc).unwrap().bytes, vec![1]);
            }
        }
        assert_eq!(cache.get_or_encode(&other, 0, &mut enc).unwrap().bytes, vec![2]);
        assert_eq!(cache.get_or_encode(&other, 0, &mut enc).unwrap().bytes, vec![2]);
        assert_eq!(encoded, 2);
        assert_eq!(cache.pending(), 0);
    }
}
