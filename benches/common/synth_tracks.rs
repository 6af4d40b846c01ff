//! LK tracks between two synthetic frames as `lk_flow` makes them (FAST seeds 5 px apart,
//! 1000 at most, pyramidal LK over 3 levels): shared by the culling benches.

use dynaflow_vision::GrayImage;
use dynaflow_vision::flow::{LkTracker, Pyramid, seed_corners};

/// The found tracks of the `w x h` RGB frame `a` into `b`: previous pixels, current pixels
/// and LK residuals.
pub fn lk_tracks(
    lk: &mut LkTracker,
    a: &[u8],
    b: &[u8],
    w: usize,
    h: usize,
) -> (Vec<[f32; 2]>, Vec<[f32; 2]>, Vec<f32>) {
    let (a, b) = (GrayImage::from_rgb8(w, h, a).unwrap(), GrayImage::from_rgb8(w, h, b).unwrap());
    let (mut pa, mut pb) = (Pyramid::default(), Pyramid::default());
    pa.build(&a, 3);
    pb.build(&b, 3);
    let seeds = seed_corners(&a, 1000, 20, 5.0, 10, &[]);
    let res = lk.track(&pa, &pb, &seeds);
    let mut out = (Vec::new(), Vec::new(), Vec::new());
    for (p, r) in seeds.iter().zip(&res).filter(|(_, r)| r.found) {
        out.0.push(*p);
        out.1.push(r.point);
        out.2.push(r.error);
    }
    out
}
