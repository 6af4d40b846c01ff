//! `pnp_track` on the synthetic scene, judged by `dynaflow eval` against the generator's
//! ground truth: frame-to-frame RGB-D odometry holds a static scene, and walking people
//! ruin it unless their points are culled first.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use dynaflow_operators::decode::read_trajectory;
use dynaflow_recordings::eval::{Align, evaluate};

fn ate(variant: &str, dir: &std::path::Path, frames: &str) -> f64 {
    let out = dir.join(variant);
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", frames, "--out"])
        .arg(&out)
        .args(["--variant", variant])
        .arg(common::repo().join("graphs/rgbd_odometry.yaml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{variant}: {}", String::from_utf8_lossy(&o.stderr));
    let gt_dir = dir.join("gt");
    if !gt_dir.join("groundtruth.txt").exists() {
        // The camera path depends on the motion only, not on the scene's seed.
        let o = common::bin()
            .args(["synth", "--motion", "xyz", "--people", "0", "--frames", frames, "--out"])
            .arg(&gt_dir)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let gt = read_trajectory(&gt_dir.join("groundtruth.txt")).unwrap();
    let est = read_trajectory(&out.join("track.trajectory.txt")).unwrap();
    let e = evaluate(&gt, &est, 0.01, Align::Se3, 1).unwrap();
    assert_eq!(e.matched, gt.len());
    e.ate.rmse
}

#[test]
fn odometry_holds_a_static_scene_and_culling_protects_it_from_walkers() {
    let dir = common::TempDir::new("tracking");
    let frames = "90";
    let static_scene = ate("static_scene", dir.path(), frames);
    let masked = ate("masked", dir.path(), frames);
    eprintln!("ATE RMSE over {frames} frames: static scene {static_scene:.4} m, walkers masked out {masked:.4} m");
    assert!(static_scene < 0.02, "static scene: {static_scene} m");
    assert!(masked < 0.03, "masked: {masked} m");
}
