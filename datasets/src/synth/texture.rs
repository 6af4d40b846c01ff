//! Textures: photographed surfaces (CC0 brick, gravel and grass photos from scikit-image's
//! sample data, tinted and tiled) for walls, floor and furniture, so corners come from real
//! image statistics rather than synthetic checkerboards; photo crops for the people (a
//! public-domain portrait), so a COCO detector sees persons; and procedural hashed tiles for
//! clothes (`assets/textures/SOURCE.md` for every image).

use std::sync::OnceLock;

/// The embedded photo (NASA portrait, public domain; 256x256 RGB).
const ASTRONAUT: &[u8] = include_bytes!("../../../assets/textures/astronaut.png");

/// The embedded surface photos (CC0; 256x256 grey).
const BRICK: &[u8] = include_bytes!("../../../assets/textures/brick.png");
const GRAVEL: &[u8] = include_bytes!("../../../assets/textures/gravel.png");
const GRASS: &[u8] = include_bytes!("../../../assets/textures/grass.png");

/// A decoded photo, RGB in 0..=1.
struct Photo {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
}

impl Photo {
    fn decode(bytes: &[u8]) -> Photo {
        match image::load_from_memory(bytes) {
            Ok(img) => {
                let img = img.into_rgb8();
                let (width, height) = (img.width() as usize, img.height() as usize);
                let rgb = img.pixels().map(|p| p.0.map(|c| f32::from(c) / 255.0)).collect();
                Photo { width, height, rgb }
            }
            // The bytes are compiled in and checked by a test; a grey patch if they were not.
            Err(_) => Photo { width: 1, height: 1, rgb: vec![[0.5; 3]] },
        }
    }

    /// Bilinear sample at pixel coordinates `(x, y)` (pixel centres at `i + 0.5`), which the
    /// caller keeps inside the image.
    fn bilinear(&self, x: f32, y: f32) -> [f32; 3] {
        let x = (x - 0.5).clamp(0.0, (self.width - 1) as f32);
        let y = (y - 0.5).clamp(0.0, (self.height - 1) as f32);
        let (xi, yi) = (x.floor() as usize, y.floor() as usize);
        let (xj, yj) = ((xi + 1).min(self.width - 1), (yi + 1).min(self.height - 1));
        let (fx, fy) = (x - xi as f32, y - yi as f32);
        let at = |x: usize, y: usize| self.rgb[y * self.width + x];
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let top = at(xi, yi)[c] * (1.0 - fx) + at(xj, yi)[c] * fx;
            let bottom = at(xi, yj)[c] * (1.0 - fx) + at(xj, yj)[c] * fx;
            *o = top * (1.0 - fy) + bottom * fy;
        }
        out
    }
}

fn photo() -> &'static Photo {
    static PHOTO: OnceLock<Photo> = OnceLock::new();
    PHOTO.get_or_init(|| Photo::decode(ASTRONAUT))
}

/// A photographed surface, tiled over a face.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    /// Brick courses (CC0Textures Bricks25 via scikit-image).
    Brick,
    /// Gravel (CC0Textures Gravel04 via scikit-image).
    Gravel,
    /// Grass, here a stand-in for rough fabric and carpet (CC0, via scikit-image).
    Grass,
}

/// A decoded square grey photo (0..=1) and its mip levels (each half the previous, 2x2 box
/// filtered), so a surface seen from afar is sampled at its footprint instead of aliasing.
struct Grey {
    levels: Vec<(usize, Vec<f32>)>,
}

impl Grey {
    fn new(size: usize, px: Vec<f32>) -> Grey {
        let mut levels = vec![(size, px)];
        while let Some((n, prev)) = levels.last()
            && *n >= 32
        {
            let h = n / 2;
            let at = |x: usize, y: usize| prev[y * n + x];
            let next = (0..h * h)
                .map(|i| {
                    let (x, y) = (2 * (i % h), 2 * (i / h));
                    0.25 * (at(x, y) + at(x + 1, y) + at(x, y + 1) + at(x + 1, y + 1))
                })
                .collect();
            levels.push((h, next));
        }
        Grey { levels }
    }

    /// Bilinear sample of level `l` at `(u, v)` in photo units, mirrored at every edge so the
    /// tiling has no seams.
    fn bilinear(&self, l: usize, u: f32, v: f32) -> f32 {
        let (size, px) = &self.levels[l.min(self.levels.len() - 1)];
        let n = *size as f32;
        // Mirrored repeat: period 2 in photo units, folded back into [0, 1].
        let mirror = |t: f32| {
            let m = t - 2.0 * (t * 0.5).floor();
            (if m > 1.0 { 2.0 - m } else { m } * n - 0.5).clamp(0.0, n - 1.0)
        };
        let (x, y) = (mirror(u), mirror(v));
        let (xi, yi) = (x as usize, y as usize);
        let (xj, yj) = ((xi + 1).min(size - 1), (yi + 1).min(size - 1));
        let (fx, fy) = (x - xi as f32, y - yi as f32);
        let at = |x: usize, y: usize| px[y * size + x];
        let top = at(xi, yi) + (at(xj, yi) - at(xi, yi)) * fx;
        let bottom = at(xi, yj) + (at(xj, yj) - at(xi, yj)) * fx;
        top + (bottom - top) * fy
    }
}

impl Surface {
    fn photo(self) -> &'static Grey {
        static PHOTOS: [OnceLock<Grey>; 3] = [OnceLock::new(), OnceLock::new(), OnceLock::new()];
        let (i, bytes) = match self {
            Surface::Brick => (0, BRICK),
            Surface::Gravel => (1, GRAVEL),
            Surface::Grass => (2, GRASS),
        };
        PHOTOS[i].get_or_init(|| {
            let p = Photo::decode(bytes);
            // Square by construction (256x256); a decoding failure gives the 1x1 grey patch.
            let size = p.width.min(p.height);
            let px = (0..size * size).map(|i| p.rgb[(i / size) * p.width + i % size][0]).collect();
            Grey::new(size, px)
        })
    }

    /// Grey level (0..=1) at `(u, v)` in units of the photo's edge, for a pixel whose
    /// footprint covers `footprint` photo units: trilinear between the two mip levels around
    /// it. The brick photo's courses run vertically: it is read transposed, so courses lie
    /// horizontal on walls (`v` up).
    fn grey(self, u: f32, v: f32, footprint: f32) -> f32 {
        let p = self.photo();
        let (u, v) = if self == Surface::Brick { (v, u) } else { (u, v) };
        let texels = footprint * p.levels[0].0 as f32;
        let lod = texels.max(1.0).log2().min((p.levels.len() - 1) as f32);
        let l = lod.floor();
        let a = p.bilinear(l as usize, u, v);
        if lod - l < 1e-3 {
            return a;
        }
        a + (p.bilinear(l as usize + 1, u, v) - a) * (lod - l)
    }
}

/// A rectangle of the embedded photo, in 0..=1 image coordinates (x0, y0, x1, y1; y down).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhotoCrop(pub [f32; 4]);

impl PhotoCrop {
    /// The person's head in the portrait.
    pub const HEAD: PhotoCrop = PhotoCrop([0.36, 0.05, 0.66, 0.40]);
    /// Shoulders and chest.
    pub const TORSO: PhotoCrop = PhotoCrop([0.22, 0.38, 0.82, 1.0]);

    /// Bilinear sample at `(s, t)` in 0..=1 across the crop (`t` down).
    fn sample(&self, s: f32, t: f32) -> [f32; 3] {
        let p = photo();
        let [x0, y0, x1, y1] = self.0;
        let x = (x0 + (x1 - x0) * s.clamp(0.0, 1.0)) * p.width as f32;
        let y = (y0 + (y1 - y0) * t.clamp(0.0, 1.0)) * p.height as f32;
        p.bilinear(x, y)
    }
}

/// A 32-bit integer hash (lowbias32), the source of all texture randomness.
pub fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

fn unit(h: u32) -> f32 {
    (h & 0xff) as f32 / 255.0
}

fn hash3(a: i32, b: i32, c: u32) -> u32 {
    hash((a as u32).wrapping_mul(0x9e37_79b1) ^ hash((b as u32).wrapping_mul(0x85eb_ca77) ^ hash(c)))
}

/// A texture: a base colour and a tile size (metres); `seed` picks the pattern. With a
/// `surface`, the photo (tinted by `base`, shaded by `contrast`) covers `tile` metres per
/// edge instead of the procedural tiles.
#[derive(Clone, Copy, Debug)]
pub struct Texture {
    /// Base RGB.
    pub base: [f32; 3],
    /// Tile edge length in metres.
    pub tile: f32,
    /// Pattern seed.
    pub seed: u32,
    /// Strength of the tile shading in `[0, 1]`.
    pub contrast: f32,
    /// A photo crop on the vertical faces of a box (top and bottom stay procedural).
    pub photo: Option<PhotoCrop>,
    /// A photographed surface in place of the procedural tiles.
    pub surface: Option<Surface>,
    /// A facade's windows on the vertical faces: `[bay width, floor height]` in metres, one
    /// window a bay from the first floor up, each pane its own shade (so a street of them does
    /// not repeat); `None`: a plain surface.
    pub windows: Option<[f32; 2]>,
}

impl Texture {
    /// The colour on face `axis` (0, 1: vertical faces; 2: top or bottom) of a box at `(a, b)`
    /// metres from the face's corner, on a face `size_a x size_b` metres (`b` up).
    /// `footprint`: metres of surface one pixel covers.
    pub fn sample_face(&self, axis: usize, a: f32, b: f32, size_a: f32, size_b: f32, footprint: f32) -> [f32; 3] {
        if let (Some([bay, floor]), true) = (self.windows, axis != 2)
            && let Some(shade) = self.pane(a, b, bay, floor)
        {
            return shade;
        }
        match self.photo {
            Some(crop) if axis != 2 && size_a > 0.0 && size_b > 0.0 => crop.sample(a / size_a, 1.0 - b / size_b),
            _ => self.sample(a, b, footprint),
        }
    }

    /// The window pane at `(a, b)` on a facade, if one is there: centred in its bay, 45 % of
    /// the bay wide and half the floor high, from the first floor up; dark glass, each pane a
    /// shade of its own.
    fn pane(&self, a: f32, b: f32, bay: f32, floor: f32) -> Option<[f32; 3]> {
        let (i, j) = ((a / bay).floor(), (b / floor).floor());
        let (fa, fb) = (a / bay - i, b / floor - j);
        if j < 1.0 || (fa - 0.5).abs() > 0.225 || !(0.3..0.8).contains(&fb) {
            return None;
        }
        let h = hash3(i as i32, j as i32, self.seed ^ 0x91a5);
        let lit = 0.08 + 0.5 * ((h & 0xff) as f32 / 255.0).powi(2);
        Some([lit * 0.9, lit * 0.95, lit * 1.1 + 0.03])
    }

    /// Whether the colour on face `axis` has hard steps (procedural tiles), which the
    /// renderer integrates with sub-samples; photos are bilinear and smooth.
    pub fn hard_edges(&self, axis: usize) -> bool {
        (self.windows.is_some() && axis != 2) || self.surface.is_none() && !(self.photo.is_some() && axis != 2)
    }

    /// The colour at surface coordinates `(u, v)` in metres, for a pixel covering
    /// `footprint` metres of the surface.
    pub fn sample(&self, u: f32, v: f32, footprint: f32) -> [f32; 3] {
        if let Some(surface) = self.surface {
            // A per-texture offset so two faces with one photo do not show the same patch.
            let off = (unit(self.seed), unit(self.seed >> 8));
            let g = surface.grey(u / self.tile + off.0, v / self.tile + off.1, footprint / self.tile);
            let shade = 1.0 + (g * 2.0 - 1.0) * self.contrast;
            return self.base.map(|b| (b * shade).clamp(0.0, 1.0));
        }
        // Two tile layers: coarse tiles, and finer "posters" inside half of them.
        let (cu, cv) = ((u / self.tile).floor() as i32, (v / self.tile).floor() as i32);
        let h = hash3(cu, cv, self.seed);
        let mut shade = ((h & 0xff) as f32 / 255.0 - 0.5) * self.contrast;
        if h & 0x100 != 0 {
            let f = self.tile * 0.37;
            let (fu, fv) = ((u / f).floor() as i32, (v / f).floor() as i32);
            let h2 = hash3(fu, fv, self.seed ^ 0xabcd);
            shade += ((h2 & 0xff) as f32 / 255.0 - 0.5) * self.contrast * 0.8;
        }
        let tint = [
            ((h >> 9) & 0x3f) as f32 / 63.0 - 0.5,
            ((h >> 15) & 0x3f) as f32 / 63.0 - 0.5,
            ((h >> 21) & 0x3f) as f32 / 63.0 - 0.5,
        ];
        let mut out = [0.0; 3];
        for i in 0..3 {
            out[i] = (self.base[i] * (1.0 + shade) + tint[i] * 0.12 * self.contrast).clamp(0.0, 1.0);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_photos_decode_and_tile_without_seams() {
        assert_eq!((photo().width, photo().height), (256, 256), "astronaut.png");
        for s in [Surface::Brick, Surface::Gravel, Surface::Grass] {
            let p = s.photo();
            let sizes: Vec<usize> = p.levels.iter().map(|l| l.0).collect();
            assert_eq!(sizes, [256, 128, 64, 32, 16], "{s:?}");
            // Mip levels keep the mean grey (box filter).
            let mean = |l: usize| p.levels[l].1.iter().sum::<f32>() / p.levels[l].1.len() as f32;
            assert!((mean(0) - mean(4)).abs() < 1e-3, "{s:?}");
            // Mirrored tiling: continuous across a tile border, and the photo has contrast.
            for v in [0.1_f32, 0.5, 0.9] {
                let (a, b) = (s.grey(1.0 - 1e-4, v, 0.0), s.grey(1.0 + 1e-4, v, 0.0));
                assert!((a - b).abs() < 0.01, "{s:?} at v {v}: {a} vs {b}");
            }
            let g: Vec<f32> = (0..100).map(|i| s.grey(i as f32 * 0.0137, 0.3, 0.0)).collect();
            let (lo, hi) = g.iter().fold((1.0_f32, 0.0_f32), |(lo, hi), &x| (lo.min(x), hi.max(x)));
            assert!(hi - lo > 0.2, "{s:?}: {lo}..{hi}");
            // A footprint of many texels reads the blurred levels: less contrast, same mean.
            let far: Vec<f32> = (0..100).map(|i| s.grey(i as f32 * 0.0137, 0.3, 0.5)).collect();
            let (flo, fhi) = far.iter().fold((1.0_f32, 0.0_f32), |(lo, hi), &x| (lo.min(x), hi.max(x)));
            assert!(fhi - flo < hi - lo, "{s:?}");
        }
    }
}
