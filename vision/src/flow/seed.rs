//! New points to track: FAST corners, strongest first, at least `min_distance` apart and away
//! from the points already tracked (as YG-SLAM re-detects when tracks thin out).

use crate::image::GrayImage;
use crate::orb::fast;

/// Up to `count` corners of `image` (FAST threshold `threshold`, `border` px from the edges)
/// at least `min_distance` from each other and from `existing`, strongest first.
pub fn seed_corners(
    image: &GrayImage,
    count: usize,
    threshold: u8,
    min_distance: f32,
    border: usize,
    existing: &[[f32; 2]],
) -> Vec<[f32; 2]> {
    let mut corners = Vec::new();
    if count == 0 || image.is_empty() {
        return Vec::new();
    }
    fast::detect(
        &image.data,
        image.width,
        image.height,
        threshold,
        border,
        &mut fast::FastScratch::default(),
        &mut corners,
    );
    corners.sort_by_key(|c| (std::cmp::Reverse(c.score), c.y, c.x));
    // Occupancy grid with cells of `min_distance`: a point blocks its 3x3 cells.
    let cell = min_distance.max(1.0);
    let (cols, rows) =
        (((image.width as f32 / cell).ceil() as usize).max(1), ((image.height as f32 / cell).ceil() as usize).max(1));
    let mut taken: Vec<Vec<[f32; 2]>> = vec![Vec::new(); cols * rows];
    let cell_of = |p: [f32; 2]| {
        (((p[0] / cell).max(0.0) as usize).min(cols - 1), ((p[1] / cell).max(0.0) as usize).min(rows - 1))
    };
    let free = |taken: &Vec<Vec<[f32; 2]>>, p: [f32; 2]| {
        let (cx, cy) = cell_of(p);
        for y in cy.saturating_sub(1)..=(cy + 1).min(rows - 1) {
            for x in cx.saturating_sub(1)..=(cx + 1).min(cols - 1) {
                for q in &taken[y * cols + x] {
                    if (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) < min_distance * min_distance {
                        return false;
                    }
                }
            }
        }
        true
    };
    for &p in existing.iter().filter(|p| p[0].is_finite() && p[1].is_finite()) {
        let (cx, cy) = cell_of(p);
        taken[cy * cols + cx].push(p);
    }
    let mut out = Vec::new();
    for c in corners {
        let p = [f32::from(c.x), f32::from(c.y)];
        if free(&taken, p) {
            let (cx, cy) = cell_of(p);
            taken[cy * cols + cx].push(p);
            out.push(p);
            if out.len() >= count {
                break;
            }
        }
    }
    out
}
