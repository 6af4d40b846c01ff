//! Procedural textures rich in corners: hashed tiles of varying size and shade over a base
//! colour, so FAST/ORB find stable features on walls, floor, furniture and clothing.

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
}

impl Texture {
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
