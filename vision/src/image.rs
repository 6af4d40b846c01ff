//! Grey 8-bit image buffers and the resampling the pyramids need.

/// A grey 8-bit image, row-major, `width * height` bytes (no row padding).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GrayImage {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Pixels.
    pub data: Vec<u8>,
}

impl GrayImage {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        Self { width, height, data: vec![0; width * height] }
    }

    /// Wrap pixels; `None` if the length does not match.
    pub fn from_vec(width: usize, height: usize, data: Vec<u8>) -> Option<Self> {
        (width.checked_mul(height)? == data.len()).then_some(Self { width, height, data })
    }

    /// Convert packed RGB8 with OpenCV's fixed-point BT.601 weights
    /// (`Y = 0.299 R + 0.587 G + 0.114 B`, rounded), so features match OpenCV's on the same
    /// image. `None` if the length does not match.
    pub fn from_rgb8(width: usize, height: usize, rgb: &[u8]) -> Option<Self> {
        if width.checked_mul(height)?.checked_mul(3)? != rgb.len() {
            return None;
        }
        let data = rgb
            .chunks_exact(3)
            .map(|p| {
                let y = u32::from(p[0]) * 4899 + u32::from(p[1]) * 9617 + u32::from(p[2]) * 1868;
                ((y + (1 << 13)) >> 14) as u8
            })
            .collect();
        Some(Self { width, height, data })
    }

    /// Resize the buffer (contents unspecified), reusing its allocation.
    pub(crate) fn reshape(&mut self, width: usize, height: usize) {
        self.width = width;
        self.height = height;
        self.data.resize(width * height, 0);
    }

    /// Row `y`.
    #[inline]
    pub fn row(&self, y: usize) -> &[u8] {
        &self.data[y * self.width..(y + 1) * self.width]
    }

    /// Pixel, clamped to the border.
    #[inline]
    pub fn at_clamped(&self, x: isize, y: isize) -> u8 {
        let x = x.clamp(0, self.width as isize - 1) as usize;
        let y = y.clamp(0, self.height as isize - 1) as usize;
        self.data[y * self.width + x]
    }

    /// Whether the image has no pixels.
    pub fn is_empty(&self) -> bool {
        self.width == 0 || self.height == 0
    }
}

/// Bilinear resize to `width` x `height` with pixel-centre alignment (OpenCV's
/// `INTER_LINEAR`), in 11-bit fixed point, into `dst` (reused).
pub fn resize_bilinear(src: &GrayImage, width: usize, height: usize, dst: &mut GrayImage) {
    dst.reshape(width, height);
    if src.is_empty() || width == 0 || height == 0 {
        return;
    }
    const BITS: u32 = 11;
    const ONE: i32 = 1 << BITS;
    let sx = src.width as f64 / width as f64;
    let sy = src.height as f64 / height as f64;
    // Per column: left index and weight of the right neighbour.
    let cols: Vec<(usize, i32)> = (0..width)
        .map(|x| {
            let f = ((x as f64 + 0.5) * sx - 0.5).max(0.0);
            let i = (f.floor() as usize).min(src.width - 1);
            let w = if i + 1 < src.width { ((f - i as f64) * f64::from(ONE)).round() as i32 } else { 0 };
            (i, w)
        })
        .collect();
    let mut row_a = vec![0i32; width];
    let mut row_b = vec![0i32; width];
    // Source rows held in row_a / row_b: consecutive output rows mostly share one, so each
    // source row is interpolated horizontally about once.
    let (mut have_a, mut have_b) = (usize::MAX, usize::MAX);
    let last = src.width - 1;
    let horizontal = |row: &[u8], out: &mut [i32]| {
        for (o, &(i, w)) in out.iter_mut().zip(&cols) {
            let a = i32::from(row[i]);
            let b = i32::from(row[(i + 1).min(last)]);
            *o = a * (ONE - w) + b * w;
        }
    };
    for y in 0..height {
        let f = ((y as f64 + 0.5) * sy - 0.5).max(0.0);
        let i = (f.floor() as usize).min(src.height - 1);
        let w = if i + 1 < src.height { ((f - i as f64) * f64::from(ONE)).round() as i32 } else { 0 };
        let j = (i + 1).min(src.height - 1);
        if have_a != i {
            if have_b == i {
                std::mem::swap(&mut row_a, &mut row_b);
                have_b = usize::MAX;
            } else {
                horizontal(src.row(i), &mut row_a);
            }
            have_a = i;
        }
        if have_b != j {
            horizontal(src.row(j), &mut row_b);
            have_b = j;
        }
        let out = &mut dst.data[y * width..(y + 1) * width];
        // In i32 (vectorises): a, b <= 255 * 2^11 and the weights sum to 2^11, so the sum is at
        // most 255 * 2^22 + 2^21 < 2^31.
        for ((o, &a), &b) in out.iter_mut().zip(&row_a).zip(&row_b) {
            let v = (a * (ONE - w) + b * w + (1 << (2 * BITS - 1))) >> (2 * BITS);
            *o = v.clamp(0, 255) as u8;
        }
    }
}

/// Index `i` reflected into `0..n` (BORDER_REFLECT_101: `dcb|abcd|cba`).
pub(crate) fn reflect101(i: isize, n: usize) -> usize {
    let n = n as isize;
    if n <= 1 {
        return 0;
    }
    let mut i = i;
    while i < 0 || i >= n {
        i = if i < 0 { -i } else { 2 * (n - 1) - i };
    }
    i as usize
}

/// Scratch for [`gaussian_blur`].
#[derive(Clone, Debug, Default)]
pub struct BlurScratch {
    padded: Vec<u8>,
    rows: Vec<u16>,
    acc: Vec<u32>,
}

/// The `2 * radius + 1` taps of [`gaussian_blur`]'s kernel in 8-bit fixed point: the sampled
/// Gaussian normalised and rounded, the centre tap absorbing the rounding so they sum to 256.
fn gaussian_taps(radius: usize, sigma: f64) -> Vec<u16> {
    let raw: Vec<f64> = (0..=2 * radius)
        .map(|i| {
            let d = i as f64 - radius as f64;
            (-d * d / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let sum: f64 = raw.iter().sum();
    let mut k: Vec<u16> = raw.iter().map(|v| (v / sum * 256.0).round() as u16).collect();
    let total: u16 = k.iter().sum();
    k[radius] = (k[radius] + 256).saturating_sub(total);
    k
}

/// Separable Gaussian blur with BORDER_REFLECT_101, kernel `2 * radius + 1`, into `dst`
/// (reused). ORB smooths each level with a 7x7, sigma 2 kernel before BRIEF. 8-bit
/// fixed-point taps (each pass sums to 256); the loops run over whole rows so they vectorise.
pub fn gaussian_blur(src: &GrayImage, radius: usize, sigma: f64, scratch: &mut BlurScratch, dst: &mut GrayImage) {
    dst.reshape(src.width, src.height);
    if src.is_empty() {
        return;
    }
    let k = gaussian_taps(radius, sigma);
    let (w, h) = (src.width, src.height);
    let taps = 2 * radius + 1;
    // Horizontal pass into u16 rows (at most 255 * 256).
    scratch.rows.clear();
    scratch.rows.resize(w * h, 0);
    scratch.padded.resize(w + 2 * radius, 0);
    for y in 0..h {
        let row = src.row(y);
        let pad = &mut scratch.padded;
        pad[radius..radius + w].copy_from_slice(row);
        for i in 0..radius {
            pad[i] = row[reflect101(i as isize - radius as isize, w)];
            pad[radius + w + i] = row[reflect101((w + i) as isize, w)];
        }
        let out = &mut scratch.rows[y * w..(y + 1) * w];
        out.fill(0);
        for (j, &kj) in k.iter().enumerate().take(taps) {
            for (o, &p) in out.iter_mut().zip(&pad[j..j + w]) {
                *o += kj * u16::from(p);
            }
        }
    }
    // Vertical pass, row by row.
    scratch.acc.resize(w, 0);
    for y in 0..h {
        let acc = &mut scratch.acc[..w];
        acc.fill(1 << 15);
        for (j, &kj) in k.iter().enumerate() {
            let r = reflect101(y as isize + j as isize - radius as isize, h);
            for (a, &v) in acc.iter_mut().zip(&scratch.rows[r * w..(r + 1) * w]) {
                *a += u32::from(kj) * u32::from(v);
            }
        }
        for (o, &a) in dst.data[y * w..(y + 1) * w].iter_mut().zip(acc.iter()) {
            *o = (a >> 16).min(255) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_conversion_matches_opencv_weights() {
        let g = GrayImage::from_rgb8(3, 1, &[255, 0, 0, 0, 255, 0, 0, 0, 255]).unwrap();
        assert_eq!(g.data, vec![76, 150, 29]);
        assert!(GrayImage::from_rgb8(2, 2, &[0; 5]).is_none());
    }

    #[test]
    fn blur_equals_the_separable_sums_pixel_by_pixel() {
        // The definition, one pixel at a time: the kernel's 8-bit taps (summing to 256),
        // horizontal sums, then vertical sums with rounding, both with BORDER_REFLECT_101;
        // several widths and radii.
        let mut state = 0x853c_49e6_748f_ea9bu64;
        for (w, h, radius) in [(31usize, 9usize, 3usize), (64, 12, 3), (97, 20, 2), (70, 17, 5), (5, 4, 3)] {
            let data: Vec<u8> = (0..w * h)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    (state >> 24) as u8
                })
                .collect();
            let src = GrayImage::from_vec(w, h, data).unwrap();
            let mut fast = GrayImage::default();
            gaussian_blur(&src, radius, 2.0, &mut BlurScratch::default(), &mut fast);
            let k: Vec<u32> = gaussian_taps(radius, 2.0).into_iter().map(u32::from).collect();
            assert_eq!(k.iter().sum::<u32>(), 256, "taps of radius {radius}");
            let r = radius as isize;
            let horizontal = |x: usize, y: usize| -> u32 {
                (0..=2 * radius)
                    .map(|j| k[j] * u32::from(src.data[y * w + reflect101(x as isize + j as isize - r, w)]))
                    .sum()
            };
            for y in 0..h {
                for x in 0..w {
                    let v: u32 = (0..=2 * radius)
                        .map(|j| k[j] * horizontal(x, reflect101(y as isize + j as isize - r, h)))
                        .sum::<u32>()
                        + (1 << 15);
                    assert_eq!(fast.data[y * w + x], (v >> 16).min(255) as u8, "{w}x{h} r {radius} at ({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn resize_and_blur_keep_constant_images_constant() {
        let src = GrayImage::from_vec(37, 23, vec![91; 37 * 23]).unwrap();
        let mut dst = GrayImage::default();
        resize_bilinear(&src, 30, 19, &mut dst);
        assert!(dst.data.iter().all(|&v| v == 91));
        let mut blurred = GrayImage::default();
        gaussian_blur(&src, 3, 2.0, &mut BlurScratch::default(), &mut blurred);
        assert!(blurred.data.iter().all(|&v| v == 91));
    }
}
