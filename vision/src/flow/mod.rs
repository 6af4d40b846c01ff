//! Pyramidal Lucas-Kanade optical flow, as OpenCV's `calcOpticalFlowPyrLK` (Bouguet's
//! formulation), and corner seeding for new tracks.
//!
//! - `pyramid`: Gaussian pyramid (`pyrDown`) with Scharr gradients, in `f32`, built once per
//!   frame and reused as the next call's previous frame.
//! - `lk`: the per-point iteration.
//! - `seed`: FAST corners spread with a minimum distance, avoiding points already tracked.

mod lk;
mod pyramid;
mod seed;

pub use lk::{LkConfig, LkTracker, TrackResult};
pub use pyramid::Pyramid;
pub use seed::seed_corners;
