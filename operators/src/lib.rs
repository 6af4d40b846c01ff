//! dynaflow's operators, one module per family, each a thin wrapper over a library crate.
//! [`registry`] returns all of them.
//!
//! Families: `synth_op` (the `synth` source over `dynaflow-datasets`' generator), `util` (test sources,
//! pass-through, gating, fault injection: the pieces used to exercise the engine), `decode`
//! (the dataset readers over `dynaflow-datasets`), `frontend` (ORB, descriptor matching, LK flow over `dynaflow-vision`),
//! `culling` (fundamental-matrix RANSAC, the seed papers' culling rules, an oracle for boxes),
//! `tracking` (PnP + BA over `dynaflow-slam`), `inference` (detectors over `dynaflow-infer` and
//! `dynaflow-gpu`), `mapping` (OctoMap over `dynaflow-octomap`).

#![warn(missing_docs)]

pub mod culling;
pub mod decode;
mod frontend;
pub mod inference;
pub mod mapping;
pub mod report;
mod synth_op;
pub mod tracking;
mod util;

use dynaflow_engine::op::Registry;

/// Every operator dynaflow ships.
pub fn registry() -> Registry {
    let mut r = Registry::new();
    util::register(&mut r);
    r.register(synth_op::SYNTH);
    r.register(decode::TUM_RGBD);
    r.register(decode::ROSBAG);
    r.register(decode::IMAGE_FOLDER);
    r.register(decode::RGBD_FOLDER);
    r.register(decode::KITTI_ODOMETRY);
    r.register(decode::EUROC);
    r.register(frontend::ORB_EXTRACT);
    r.register(frontend::MATCH_DESCRIPTORS);
    r.register(frontend::LK_FLOW);
    r.register(frontend::STEREO_MATCH);
    r.register(frontend::UNDISTORT);
    r.register(culling::FUNDAMENTAL_RANSAC);
    r.register(culling::HOMOGRAPHY_PROSAC);
    r.register(culling::CULL_EPIPOLAR);
    r.register(culling::CULL_EPIPOLAR_ADAPTIVE);
    r.register(culling::CULL_MASK);
    r.register(culling::CULL_SEMANTIC_PRIOR);
    r.register(culling::CULL_FLOW);
    r.register(culling::CULL_DEPTH);
    r.retire("cull", culling::CULL_MIGRATION);
    r.register(culling::COMBINE_LABELS);
    r.register(culling::ORACLE_BOXES);
    r.register(tracking::TRACK_RGBD);
    r.register(tracking::TRACK_STEREO);
    r.register(tracking::TRACK_MONO);
    r.retire("pnp_track", tracking::PNP_TRACK_MIGRATION);
    r.register(tracking::LOCAL_MAP);
    r.register(tracking::LOOP_CLOSE);
    r.register(inference::DETECT);
    r.register(inference::BOX_TO_MASK);
    r.register(inference::KEYFRAME_GATE);
    r.register(inference::SEGMENT);
    r.register(mapping::OCTOMAP);
    r
}
