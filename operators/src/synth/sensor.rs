//! Sensor effects: Kinect-like depth (axial noise σ = 0.0015·z², disparity quantisation,
//! holes at depth edges and random dropouts, range limits) and image noise and blur.

use super::texture::hash;

/// Kinect v1 baseline times focal length times 8 sub-disparity steps (metres·pixels):
/// depth is quantised to `c / round(c / z)`.
const DISPARITY_C: f64 = 0.075 * 525.0 * 8.0;
/// Nearest measurable depth.
pub const MIN_RANGE: f32 = 0.45;
/// Farthest measurable depth.
pub const MAX_RANGE: f32 = 6.0;
/// A depth step above this between neighbours marks an edge where holes appear.
const EDGE_STEP_M: f32 = 0.15;

/// Deterministic per-pixel randomness: uniform in `[0, 1)`.
fn uniform(seed: u32, frame: u32, idx: u32, salt: u32) -> f32 {
    (hash(hash(seed ^ hash(frame ^ salt)) ^ idx) >> 8) as f32 / (1u32 << 24) as f32
}

/// Approximately standard normal (sum of four uniforms, scaled to unit variance).
fn normal(seed: u32, frame: u32, idx: u32) -> f32 {
    let s: f32 = (0..4).map(|k| uniform(seed, frame, idx, 0x100 + k)).sum();
    (s - 2.0) * (3.0f32).sqrt()
}

/// Kinect-like depth from true depth.
pub fn kinect_depth(truth: &[f32], width: usize, seed: u32, frame: u32) -> Vec<f32> {
    let mut out = vec![0.0f32; truth.len()];
    for (i, (&z, o)) in truth.iter().zip(out.iter_mut()).enumerate() {
        if !(MIN_RANGE..=MAX_RANGE).contains(&z) {
            continue;
        }
        let neighbour = |j: Option<usize>| j.and_then(|j| truth.get(j)).map_or(0.0, |&n| (n - z).abs());
        let edge = [i.checked_sub(1), Some(i + 1), i.checked_sub(width), Some(i + width)]
            .into_iter()
            .any(|j| neighbour(j) > EDGE_STEP_M);
        let r = uniform(seed, frame, i as u32, 1);
        if (edge && r < 0.6) || r < 0.004 {
            continue;
        }
        let noisy = f64::from(z) + f64::from(normal(seed, frame, i as u32)) * 0.0015 * f64::from(z) * f64::from(z);
        let disparity = (DISPARITY_C / noisy).round().max(1.0);
        *o = (DISPARITY_C / disparity) as f32;
    }
    out
}

/// Gaussian-like pixel noise (σ in grey levels) and an optional 3×3 binomial blur.
pub fn camera_image(rgb: &[u8], width: usize, height: usize, sigma: f32, blur: bool, seed: u32, frame: u32) -> Vec<u8> {
    let src: Vec<u8> = if blur {
        let mut b = vec![0u8; rgb.len()];
        for y in 0..height {
            for x in 0..width {
                for c in 0..3 {
                    let mut acc = 0u32;
                    for (dy, wy) in [(-1i64, 1u32), (0, 2), (1, 1)] {
                        for (dx, wx) in [(-1i64, 1u32), (0, 2), (1, 1)] {
                            let yy = (y as i64 + dy).clamp(0, height as i64 - 1) as usize;
                            let xx = (x as i64 + dx).clamp(0, width as i64 - 1) as usize;
                            acc += u32::from(rgb.get((yy * width + xx) * 3 + c).copied().unwrap_or(0)) * wy * wx;
                        }
                    }
                    if let Some(p) = b.get_mut((y * width + x) * 3 + c) {
                        *p = ((acc + 8) / 16) as u8;
                    }
                }
            }
        }
        b
    } else {
        rgb.to_vec()
    };
    if sigma <= 0.0 {
        return src;
    }
    src.iter()
        .enumerate()
        .map(|(i, &v)| (f32::from(v) + normal(seed ^ 0x1a9e, frame, i as u32) * sigma).round().clamp(0.0, 255.0) as u8)
        .collect()
}
