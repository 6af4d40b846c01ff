//! Camera tracking. `pnp_track`: RGB-D odometry from tracked points, the previous frame's
//! depth and PnP with motion-only bundle adjustment (`dynaflow-vision`'s `pnp_ransac`).
//! The local map with local BA (ORB-SLAM's local mapping) comes next.

mod pnp;

pub use pnp::PNP_TRACK;
