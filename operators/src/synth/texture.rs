//! Textures: procedural ones rich in corners (hashed tiles of varying size and shade over a
//! base colour, so FAST/ORB find stable features on walls, floor and furniture), and photo
//! crops for the people (a public-domain portrait, `assets/textures/SOURCE.md`), so a COCO
//! detector sees persons.

use std::sync::OnceLock;

/// The embedded photo (NASA portrait, public domain; 256x256 RGB).
const ASTRONAUT: &[u8] = include_bytes!("../../../assets/textures/astronaut.png");

/// A decoded photo, RGB in 0..=1.
struct Photo {
    width: usize,
    height: usize,
    rgb: Vec<[f32; 3]>,
}

fn photo() -> &'static Photo {
    static PHOTO: OnceLock<Photo> = OnceLock::new();
    PHOTO.get_or_init(|| match image::load_from_memory(ASTRONAUT) {
        Ok(img) => {
            let img = img.into_rgb8();
            let (width, height) = (img.width() as usize, img.height() as usize);
            let rgb = img.pixels().map(|p| p.0.map(|c| f32::from(c) / 255.0)).collect();
            Photo { width, height, rgb }
        }
        // The bytes are compiled in and checked by a test; a grey patch if they were not.
        Err(_) => Photo { width: 1, height: 1, rgb: vec![[0.5; 3]] },
    })
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
        let x = ((x0 + (x1 - x0) * s.clamp(0.0, 1.0)) * p.width as f32 - 0.5).clamp(0.0, (p.width - 1) as f32);
        let y = ((y0 + (y1 - y0) * t.clamp(0.0, 1.0)) * p.height as f32 - 0.5).clamp(0.0, (p.height - 1) as f32);
        let (xi, yi) = (x.floor() as usize, y.floor() as usize);
        let (xj, yj) = ((xi + 1).min(p.width - 1), (yi + 1).min(p.height - 1));
        let (fx, fy) = (x - xi as f32, y - yi as f32);
        let at = |x: usize, y: usize| p.rgb[y * p.width + x];
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let top = at(xi, yi)[c] * (1.0 - fx) + at(xj, yi)[c] * fx;
            let bottom = at(xi, yj)[c] * (1.0 - fx) + at(xj, yj)[c] * fx;
            *o = top * (1.0 - fy) + bottom * fy;
        }
        out
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

fn hash3(a: i32, b: i32, c: u32) -> u32 {
    hash((a as u32).wrapping_mul(0x9e37_79b1) ^ hash((b as u32).wrapping_mul(0x85eb_ca77) ^ hash(c)))
}

/// A texture: a base colour and a tile size (metres); `seed` picks the pattern.
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
}

impl Texture {
    /// The colour on face `axis` (0, 1: vertical faces; 2: top or bottom) of a box at `(a, b)`
    /// metres from the face's corner, on a face `size_a x size_b` metres (`b` up).
    pub fn sample_face(&self, axis: usize, a: f32, b: f32, size_a: f32, size_b: f32) -> [f32; 3] {
        match self.photo {
            Some(crop) if axis != 2 && size_a > 0.0 && size_b > 0.0 => crop.sample(a / size_a, 1.0 - b / size_b),
            _ => self.sample(a, b),
        }
    }

    /// The colour at surface coordinates `(u, v)` in metres.
    pub fn sample(&self, u: f32, v: f32) -> [f32; 3] {
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
