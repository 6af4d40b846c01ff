//! Sensor effects: Kinect-like depth (axial noise σ = 0.0015·z², disparity quantisation,
//! holes at depth edges and random dropouts, range limits) and image noise and blur.

use super::texture::hash;

/// Kinect v1 baseline times focal length times 8 sub-disparity steps (metres·pixels):
/// depth is quantised to `c / round(c / z)`.
pub(super) const DISPARITY_C: f64 = 0.075 * 525.0 * 8.0;
/// Axial noise: σ = this · z² metres (Khoshelham & Elberink 2012 measured 0.0014-0.0015 for the
/// Kinect v1).
pub(super) const SIGMA_Z2: f64 = 0.0015;
/// Share of depth-edge pixels left without depth.
pub(super) const EDGE_DROPOUT: f32 = 0.6;
/// Share of all other pixels left without depth.
pub(super) const DROPOUT: f32 = 0.004;
/// Nearest measurable depth.
pub const MIN_RANGE: f32 = 0.45;
/// Farthest measurable depth.
pub const MAX_RANGE: f32 = 6.0;
/// A depth step above this between neighbours marks an edge where holes appear.
pub(super) const EDGE_STEP_M: f32 = 0.15;

/// A per-pixel 32-bit random word, deterministic in (seed, frame, pixel, salt).
fn word(seed: u32, frame: u32, idx: u32, salt: u32) -> u32 {
    hash(hash(seed ^ hash(frame.wrapping_mul(0x9e37_79b9) ^ salt)) ^ idx)
}

/// Uniform in `[0, 1)` from a random word.
fn uniform(w: u32) -> f32 {
    (w >> 8) as f32 / (1u32 << 24) as f32
}

/// Approximately standard normal from one random word: the sum of its four bytes (an
/// Irwin–Hall(4) variable), centred and scaled to unit variance.
fn normal(w: u32) -> f32 {
    let s = (w & 0xff) + ((w >> 8) & 0xff) + ((w >> 16) & 0xff) + (w >> 24);
    // Mean 4·127.5, variance 4·(256² − 1)/12.
    (s as f32 - 510.0) / 147.8
}

/// Run `f(first_row, rows)` over bands of rows on all cores.
fn par_rows<T: Send>(out: &mut [T], width: usize, f: impl Fn(usize, &mut [T]) + Sync) {
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get).clamp(1, 8);
    let rows = out.len() / width.max(1);
    let per = rows.div_ceil(threads).max(1);
    std::thread::scope(|s| {
        for (band, chunk) in out.chunks_mut(per * width).enumerate() {
            let f = &f;
            s.spawn(move || f(band * per, chunk));
        }
    });
}

/// Kinect-like depth from true depth.
pub fn kinect_depth(truth: &[f32], width: usize, seed: u32, frame: u32) -> Vec<f32> {
    let mut out = vec![0.0f32; truth.len()];
    par_rows(&mut out, width, |row0, chunk| {
        for (j, o) in chunk.iter_mut().enumerate() {
            let i = row0 * width + j;
            let z = truth.get(i).copied().unwrap_or(0.0);
            if !(MIN_RANGE..=MAX_RANGE).contains(&z) {
                continue;
            }
            let neighbour = |k: Option<usize>| k.and_then(|k| truth.get(k)).map_or(0.0, |&n| (n - z).abs());
            let edge = [i.checked_sub(1), Some(i + 1), i.checked_sub(width), Some(i + width)]
                .into_iter()
                .any(|k| neighbour(k) > EDGE_STEP_M);
            let r = uniform(word(seed, frame, i as u32, 1));
            if (edge && r < EDGE_DROPOUT) || r < DROPOUT {
                continue;
            }
            let n = normal(word(seed, frame, i as u32, 2));
            let noisy = f64::from(z) + f64::from(n) * SIGMA_Z2 * f64::from(z) * f64::from(z);
            let disparity = (DISPARITY_C / noisy).round().max(1.0);
            *o = (DISPARITY_C / disparity) as f32;
        }
    });
    out
}

/// Gaussian-like pixel noise (σ in grey levels) and an optional 3×3 binomial blur
/// (separable: a horizontal [1 2 1] pass, then a vertical one with the noise).
pub fn camera_image(rgb: &[u8], width: usize, height: usize, sigma: f32, blur: bool, seed: u32, frame: u32) -> Vec<u8> {
    let stride = width * 3;
    let mut horizontal = vec![0u16; rgb.len()];
    if blur {
        par_rows(&mut horizontal, stride, |row0, chunk| {
            for (r, line) in chunk.chunks_mut(stride).enumerate() {
                let src = rgb.get((row0 + r) * stride..(row0 + r + 1) * stride).unwrap_or(&[]);
                for x in 0..width {
                    let (xm, xp) = (x.saturating_sub(1), (x + 1).min(width - 1));
                    for c in 0..3 {
                        let at = |xx: usize| u16::from(src.get(xx * 3 + c).copied().unwrap_or(0));
                        if let Some(o) = line.get_mut(x * 3 + c) {
                            *o = at(xm) + 2 * at(x) + at(xp);
                        }
                    }
                }
            }
        });
    }
    let mut out = vec![0u8; rgb.len()];
    par_rows(&mut out, stride, |row0, chunk| {
        for (r, line) in chunk.chunks_mut(stride).enumerate() {
            let y = row0 + r;
            let row = |yy: usize| horizontal.get(yy * stride..(yy + 1) * stride).unwrap_or(&[]);
            let (above, here, below) = (row(y.saturating_sub(1)), row(y), row((y + 1).min(height.saturating_sub(1))));
            let plain = rgb.get(y * stride..(y + 1) * stride).unwrap_or(&[]);
            for (i, o) in line.iter_mut().enumerate() {
                let v = if blur {
                    let g = |s: &[u16]| u32::from(s.get(i).copied().unwrap_or(0));
                    ((g(above) + 2 * g(here) + g(below) + 8) / 16) as f32
                } else {
                    f32::from(plain.get(i).copied().unwrap_or(0))
                };
                let noisy = if sigma > 0.0 {
                    v + normal(word(seed ^ 0x1a9e, frame, (y * stride + i) as u32, 3)) * sigma
                } else {
                    v
                };
                *o = noisy.round().clamp(0.0, 255.0) as u8;
            }
        }
    });
    out
}
