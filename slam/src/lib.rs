//! dynaflow's SLAM back-end as a plain library, with no engine or async dependency (the
//! `pnp_track` and `local_map` operators are thin wrappers around it).
//!
//! - `map`: the sparse map's plain data: key frames, map points, observations, and the
//!   [`map::SparseMap`] batch that tracking and local mapping exchange.
//! - `tracker`: ORB-SLAM-style tracking of an RGB-D frame against the local map: guided
//!   projection search from a constant-velocity prediction, descriptor matching with P3P
//!   RANSAC as the fallback and for relocalisation, motion-only BA, key-frame decisions,
//!   tracking loss and new maps.
//! - `local_map`: ORB-SLAM's local mapping: covisibility, the local window, local BA, culling
//!   of bad observations and points.
//! - `ba`: sparse bundle adjustment (Levenberg-Marquardt, Schur complement on the points,
//!   Huber kernel).
//! - `bow`: a bag-of-binary-words vocabulary for ORB descriptors (DBoW2's design): training,
//!   words and tf-idf vectors, the L1 score, a versioned file format.
//! - `keyframe_db`: ORB-SLAM2's key-frame database (inverted index, loop and relocalisation
//!   candidates) and its loop-consistency check.
//! - `keyframe_map`: the whole key-frame map as place recognition sees it (keypoints, words,
//!   covisibility), kept by loop closing and by tracking for relocalisation.
//! - `loop_closing`: ORB-SLAM2's loop closing for rigid maps: detection with the key-frame
//!   database, SE(3) RANSAC and guided matching, fusion, the essential graph.
//! - `map_file`: a saved map (key frames, keypoints, points, vocabulary id), for map reuse.
//! - `pose_graph`: SE(3) pose-graph optimisation (the essential graph).
//! - `imu`: IMU pre-integration on the manifold (Forster et al. 2017): deltas, covariance,
//!   bias Jacobians, re-integration.
//! - `eval`: trajectory evaluation (association, Umeyama alignment, ATE and RPE) as evo does it.

#![warn(missing_docs)]

pub mod ba;
pub mod bow;
pub mod eval;
pub mod imu;
pub mod keyframe_db;
pub mod keyframe_map;
pub mod local_map;
pub mod loop_closing;
pub mod map;
pub mod map_file;
pub mod memory;
pub mod pose_graph;
pub mod sim3;
pub mod tracker;

pub use local_map::{LocalMapConfig, LocalMapper};
pub use map::{Feature, MapFeature, MapKeyFrame, MapKeypoint, MapObservation, MapPoint, SparseMap};
pub use tracker::{
    InertialEstimate, InertialInitInfo, InitMethod, Sensor, TrackState, Tracker, TrackerConfig, TrackingResult,
};
