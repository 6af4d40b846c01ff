//! Tracking and local mapping, thin wrappers over `dynaflow-slam`:
//!
//! - `pnp_track`: ORB-SLAM-style tracking of RGB-D frames against the local map (projection
//!   search from a constant-velocity model, P3P RANSAC fallback and relocalisation,
//!   motion-only BA), key-frame decisions, trajectory file and ATE against ground truth.
//! - `local_map`: ORB-SLAM's local mapping (covisibility window, local BA, culling), fed by
//!   `pnp_track`'s key frames and feeding its refined map back over a `delay: 1` edge.
//!
//! `convert` maps between the engine's `SparseMap` message and the library's.

mod convert;
mod local_map;
mod pnp;

pub use local_map::LOCAL_MAP;
pub use pnp::PNP_TRACK;
