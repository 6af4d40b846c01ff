//! Tracking and local mapping, thin wrappers over `dynaflow-slam`:
//!
//! - `pnp_track`: ORB-SLAM-style tracking of RGB-D frames against the local map (projection
//!   search from a constant-velocity model, P3P RANSAC fallback and relocalisation,
//!   motion-only BA), key-frame decisions, trajectory file and ATE against ground truth.
//! - `local_map`: ORB-SLAM's local mapping (covisibility window, local BA, culling), fed by
//!   `pnp_track`'s key frames and feeding its refined map back over a `delay: 1` edge.
//!
//! - `loop_close`: ORB-SLAM2's loop closing (BoW detection, SE(3) verification, fusion, the
//!   essential graph), its corrected map fed back to both over `delay: 1` edges.
//!
//! `convert` maps between the engine's `SparseMap` message and the library's.

mod convert;
mod local_map;
mod loop_close;
mod pnp;

pub use local_map::LOCAL_MAP;
pub use loop_close::LOOP_CLOSE;
pub use pnp::PNP_TRACK;
