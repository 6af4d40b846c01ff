//! Visual-inertial tracking (issue 51's done-when 2 and 3) on EuRoC folders written by
//! `dynaflow synth --format euroc --motion handheld` (a hand-held camera that rests for 1 s,
//! then moves along and about every axis; a 200 Hz IMU with EuRoC's ADIS16448 noise and bias
//! walks), read back through `--input`. Seeds 5 and 7: never run while the tracker was built.
//! The bounds are the issue's: on a static scene the stereo-inertial ATE within 1 cm and no
//! worse than stereo alone (this holds on seeds 1-3 and 5 but not on seed 0, docs/benchmarks.md),
//! the IMU initialised within 2 s of the motion's start (stereo and mono), the mono-inertial
//! ATE within 3 cm with no scale fitted and its scale error within 2 %; with walking
//! people YSAG's culling on the stereo-inertial tracker cuts the no-culling row's ATE by 80 %,
//! and through a 30-frame blackout the inertial tracker keeps one map (no relocalisation)
//! and stays within 2 cm, where the visual tracker loses the frames and relocalises.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};

use dynaflow::summary::Summary;
use dynaflow_datasets::synth::HANDHELD_REST;
use dynaflow_datasets::tum::read_trajectory;
use dynaflow_slam::eval::{Align, evaluate};

/// Write a EuRoC folder; return its `mav0`.
fn euroc(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let root = dir.join(name);
    let o = common::bin()
        .args(["synth", "--format", "euroc", "--motion", "handheld", "--frames", "300", "--out"])
        .arg(&root)
        .args(extra)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    root.join("mav0")
}

/// Run `graph --variant variant` on `input`; its summary.
fn run(graph: &str, variant: &str, input: &Path, out: &Path) -> Summary {
    let out = out.join(format!("{graph}-{variant}"));
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--variant", variant, "--input"])
        .arg(input)
        .arg("--out")
        .arg(&out)
        .arg(common::repo().join(format!("graphs/{graph}.yaml")))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{graph} {variant}: {}", String::from_utf8_lossy(&o.stderr));
    common::summary(&out.join(format!("{graph}-{variant}.summary.json")))
}

#[test]
fn stereo_and_mono_inertial_meet_the_bounds_on_a_static_scene() {
    let dir = common::TempDir::new("inertial-static");
    let input = euroc(dir.path(), "static", &["--people", "0", "--seed", "5"]);
    let stereo = run("orb_baseline", "stereo", &input, dir.path());
    let inertial = run("orb_baseline", "stereo_inertial", &input, dir.path());
    let (s, i) = (stereo.ate.clone().unwrap(), inertial.ate.clone().unwrap());
    let report = inertial.tracker("track").unwrap();
    let imu = report.inertial.clone().unwrap();
    let after = imu.init_after_s.unwrap();
    eprintln!(
        "static scene: stereo ATE {:.4} m, stereo-inertial {:.4} m; IMU initialised ({:?}) at {after:.2} s",
        s.rmse, i.rmse, imu.init_method
    );
    assert_eq!(i.pairs, 300, "every frame has a pose");
    assert!(i.rmse <= 0.01, "stereo-inertial ATE {} m over 1 cm", i.rmse);
    assert!(i.rmse <= s.rmse, "stereo-inertial ATE {} m worse than stereo alone {} m", i.rmse, s.rmse);
    assert!(imu.windows > 0, "no visual-inertial window was optimised: {imu:?}");
    assert!(after <= HANDHELD_REST + 2.0, "initialised {after} s after the first frame: over 2 s of motion");

    // Monocular-inertial on the same folder: the IMU makes the map metric, so the final
    // trajectory (rebuilt from the key frames, as ORB-SLAM3 saves it) is scored SE(3)-aligned
    // with no scale fitted, and the scale a Sim(3) alignment would fit is the scale error.
    let mono = run("orb_baseline", "mono_inertial", &input, dir.path());
    let report = mono.tracker("track").unwrap();
    let imu = report.inertial.clone().unwrap();
    let ate = report.ate_final.clone().unwrap();
    assert_eq!(ate.align, "se3");
    let out = dir.path().join("orb_baseline-mono_inertial");
    let read = |f: &str| read_trajectory(&out.join(format!("orb_baseline-mono_inertial.track.{f}.txt"))).unwrap();
    let sim3 = evaluate(&read("groundtruth"), &read("final_trajectory"), 0.01, Align::Sim3, 1).unwrap();
    let scale_error = (sim3.scale - 1.0).abs();
    eprintln!(
        "static scene, mono-inertial: final ATE {:.4} m (SE(3)), scale error {:.2} %, IMU initialised at {:.2} s ({} key frames)",
        ate.rmse,
        100.0 * scale_error,
        imu.init_after_s.unwrap(),
        imu.init_keyframes.unwrap()
    );
    assert!(ate.rmse <= 0.03, "mono-inertial ATE {} m over 3 cm", ate.rmse);
    // The scale follows the visual-inertial windows (refined at each, in the summary).
    assert!(scale_error <= 0.02, "mono-inertial scale error {:.2} % over 2 %", 100.0 * scale_error);
    assert!(!imu.scale_refinements.is_empty(), "the scale was never refined: {imu:?}");
    // The device rested first: gravity from the rest, carried to the map's first key frame,
    // and the initialisation after 5 key frames, within 2 s of the motion's start.
    assert_eq!(imu.init_method.as_deref(), Some("map_gravity_at_rest"));
    let after = imu.init_after_s.unwrap();
    assert!(
        after <= HANDHELD_REST + 2.0,
        "mono-inertial initialised {after} s after the first frame: over 2 s of motion"
    );
}

#[test]
fn culling_and_the_imu_carry_stereo_inertial_through_people_and_a_blackout() {
    let dir = common::TempDir::new("inertial-walking");
    let input = euroc(dir.path(), "walking", &["--people", "2", "--seed", "7", "--blackout", "150"]);
    let baseline = run("orb_baseline", "stereo_inertial", &input, dir.path());
    let ysag = run("ysag", "stereo_inertial", &input, dir.path());
    let visual = run("ysag", "stereo", &input, dir.path());
    let (b, y) = (baseline.ate.clone().unwrap(), ysag.ate.clone().unwrap());
    let (yr, vr) = (ysag.tracker("track").unwrap(), visual.tracker("track").unwrap());
    eprintln!(
        "walking people, blackout at frame 150: no culling ATE {:.4} m, ysag stereo-inertial {:.4} m ({:?}), ysag stereo {:?}",
        b.rmse, y.rmse, yr.frames, vr.frames
    );
    assert!(y.rmse <= 0.2 * b.rmse, "ysag {} m vs no culling {} m: less than 80 % better", y.rmse, b.rmse);
    // The blackout: 30 frames the IMU alone carries, one map, no relocalisation, every frame
    // posed and the whole run within 2 cm.
    assert_eq!(yr.frames.inertial, 30, "{:?}", yr.frames);
    assert_eq!((yr.maps, yr.frames.relocalised, yr.map_relocalisations), (1, 0, 0), "{:?}", yr.frames);
    assert_eq!(y.pairs, 300);
    assert!(y.rmse <= 0.02, "ysag stereo-inertial ATE {} m over 2 cm", y.rmse);
    // The visual tracker loses the covered frames and has to relocalise.
    assert!(vr.frames.lost >= 30, "{:?}", vr.frames);
    assert!(vr.frames.relocalised + vr.map_relocalisations as u64 >= 1, "{:?}", vr.frames);
}
