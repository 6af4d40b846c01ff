//! `graphs/orb_baseline.yaml` (ORB -> `track_rgbd` -> `local_map`) on the synthetic scene,
//! judged against the generator's ground truth twice: by the ATE the run puts in its summary
//! and, independently, by `evaluate` on the trajectory file against the poses of the
//! generator's own motion and clock (what `dynaflow synth` writes to `groundtruth.txt`; the
//! camera path depends on the motion only, not on the scene seed), computed here without
//! rendering a frame.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;
#[path = "../vision/tests/common/frontend.rs"]
mod frontend;

use std::path::Path;

use dynaflow::summary::Summary;
use dynaflow_datasets::tum::read_trajectory;
use dynaflow_slam::eval::{Align, evaluate};

/// Run a variant; return the summary's ATE RMSE and the trajectory file's.
fn run(variant: Option<&str>, motion: &str, dir: &Path, frames: &str) -> (Summary, f64) {
    run_with(variant, &[], motion, dir, frames)
}

/// [`run`] with `--set` overrides (`sets`), in a folder of its own.
fn run_with(variant: Option<&str>, sets: &[&str], motion: &str, dir: &Path, frames: &str) -> (Summary, f64) {
    let name = variant.unwrap_or("walking");
    let out = dir.join(format!("{name}{}", sets.join(",")));
    let mut cmd = common::bin();
    cmd.args(["run", "--no-progress", "--record", "none", "--frames", frames, "--out"]).arg(&out);
    for s in sets {
        cmd.args(["--set", s]);
    }
    if let Some(v) = variant {
        cmd.args(["--variant", v]);
    }
    let o = cmd.arg(common::repo().join("graphs/orb_baseline.yaml")).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{name}: {}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("ATE of `track`"), "{stdout}");
    let stem = variant.map_or("orb_baseline".to_string(), |v| format!("orb_baseline-{v}"));
    let summary = common::summary(&out.join(format!("{stem}.summary.json")));

    let gt = ground_truth(motion, frames.parse().unwrap());
    let est = read_trajectory(&out.join(format!("{stem}.track.trajectory.txt"))).unwrap();
    let e = evaluate(&gt, &est, 0.01, Align::Se3, 1).unwrap();
    assert_eq!(e.matched, gt.len(), "every frame has a pose");
    (summary, e.ate.rmse)
}

/// The generator's ground truth for `frames` frames of `motion` (`stamp, world_from_cam`), as
/// `dynaflow synth` writes it, straight from its clock and motion model.
fn ground_truth(motion: &str, frames: u64) -> Vec<(f64, nalgebra::Isometry3<f64>)> {
    use dynaflow_datasets::synth::{Generator, Motion, STAMP_BASE, SynthConfig};
    let motion = Motion::from_name(motion).unwrap();
    let generator = Generator::new(SynthConfig { motion, ..SynthConfig::default() });
    (0..frames).map(|k| (STAMP_BASE + generator.time(k), generator.pose(k))).collect()
}

/// The bounds on a static scene, 300 frames: the RGB-D graph's ATE within `bound` (1 cm
/// for `xyz`, 2 cm for `halfsphere` and `rpy`), as the summary reports it; with `stereo`, ORB-SLAM2's
/// stereo mode on a rectified pair (12 cm) on the same frames within the same bound and within
/// 1.5x of RGB-D. One test per motion, so they run side by side.
fn static_scene_bounds(variant: &str, motion: &str, bound: f64, stereo: bool) {
    let dir = common::TempDir::new(&format!("tracking-static-{motion}"));
    let (summary, rgbd) = run(Some(variant), motion, dir.path(), "300");
    let ate = summary.ate.clone().unwrap();
    let reported = ate.rmse;
    eprintln!("{variant}: ATE RMSE {rgbd:.4} m (summary {reported:.4} m)");
    assert!(rgbd <= bound, "{variant}: ATE RMSE {rgbd} m > {bound} m");
    // The summary's ATE is the same evaluation of the same poses.
    assert!((reported - rgbd).abs() < 1e-6, "{reported} vs {rgbd}");
    assert_eq!(ate.align, "se3");
    assert_eq!(ate.node.as_deref(), Some("track"));
    let track = summary.tracker("track").unwrap();
    assert_eq!(track.frames.lost, 0, "{variant}");
    assert_eq!(track.maps, 1, "{variant}");
    let mapping = summary.run.nodes.iter().find(|n| n.node == "mapping").unwrap();
    assert!(mapping.frames >= 3, "key frames reached local mapping");
    if !stereo {
        return;
    }
    let sets = ["camera.people=0", &format!("camera.motion={motion}")];
    let (summary, stereo) = run_with(Some("stereo"), &sets, motion, dir.path(), "300");
    eprintln!("{motion}, static: stereo ATE RMSE {stereo:.4} m, RGB-D {rgbd:.4} m");
    assert!(stereo <= bound, "{motion}: stereo {stereo} m > {bound} m");
    assert!(stereo <= 1.5 * rgbd, "{motion}: stereo {stereo} m > 1.5 x RGB-D {rgbd} m");
    let track = summary.tracker("track").unwrap();
    assert_eq!(track.frames.lost, 0, "{motion}");
    let matcher = summary.run.nodes.iter().find(|n| n.node == "stereo").unwrap();
    assert_eq!(matcher.frames, 300, "every frame was matched");
}

#[test]
fn rgbd_and_stereo_meet_the_ate_bounds_on_the_static_xyz_scene() {
    static_scene_bounds("static_scene", "xyz", 0.01, true);
}

#[test]
fn rgbd_and_stereo_meet_the_ate_bounds_on_the_static_halfsphere_scene() {
    static_scene_bounds("halfsphere", "halfsphere", 0.02, true);
}

#[test]
fn rgbd_meets_the_ate_bound_on_the_static_rpy_scene() {
    static_scene_bounds("rpy", "rpy", 0.02, false);
}

#[test]
fn a_stereo_graph_without_a_right_image_fails_naming_the_fix() {
    let dir = common::TempDir::new("tracking-stereo-zero");
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", "5", "--variant", "stereo"])
        .args(["--set", "camera.stereo_baseline=0", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("frame 0 has no right image") && stderr.contains("stereo_baseline"), "{stderr}");
}

#[test]
fn walking_people_pull_the_baseline_off_and_masks_keep_them_out() {
    let dir = common::TempDir::new("tracking-walking");
    let frames = "150";
    let (_, walking) = run(None, "xyz", dir.path(), frames);
    let (_, masked) = run(Some("masked"), "xyz", dir.path(), frames);
    eprintln!("ATE RMSE over {frames} frames: walkers tracked {walking:.4} m, walkers masked out {masked:.4} m");
    assert!(masked <= 0.01, "masked: {masked} m");
    assert!(walking > 2.0 * masked, "the walkers should hurt the unculled baseline: {walking} vs {masked}");
}

/// ICL-NUIM intrinsics used by slambook2 for these frames (note the negative fy).
const ICL: dynaflow_vision::camera::Pinhole =
    dynaflow_vision::camera::Pinhole { fx: 481.2, fy: -480.0, cx: 319.5, cy: 239.5 };

#[test]
fn relative_poses_on_the_slambook2_frames_match_the_given_ones() {
    use dynaflow_slam::{Feature, TrackState, Tracker, TrackerConfig};
    use dynaflow_vision::orb::{OrbConfig, OrbExtractor};
    use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

    let dir = common::repo().join("tests/fixtures/slambook2_dense_rgbd");
    let gt: Vec<Isometry3<f64>> = std::fs::read_to_string(dir.join("pose.txt"))
        .unwrap()
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            Isometry3::from_parts(
                Translation3::new(v[0], v[1], v[2]),
                UnitQuaternion::from_quaternion(Quaternion::new(v[6], v[3], v[4], v[5])),
            )
        })
        .collect();
    let mut orb = OrbExtractor::new(OrbConfig { features: 1000, ..OrbConfig::default() });
    let frames: Vec<Vec<Feature>> = (1..=5)
        .map(|k| {
            let gray = frontend::load_gray(&dir.join(format!("color/{k}.png")));
            let depth = image::open(dir.join(format!("depth/{k}.png"))).unwrap().into_luma16();
            let f = orb.extract(&gray, None);
            f.keypoints
                .iter()
                .zip(&f.descriptors)
                .map(|(p, d)| {
                    let raw = depth.get_pixel((p.x.round() as u32).min(639), (p.y.round() as u32).min(479))[0];
                    Feature {
                        uv: [f64::from(p.x), f64::from(p.y)],
                        octave: p.octave,
                        angle: p.angle,
                        depth: (raw > 0).then(|| f64::from(raw) / 5000.0),
                        descriptor: *d,
                        dynamic: false,
                    }
                })
                .collect()
        })
        .collect();
    let (mut found, mut lost) = (Vec::new(), Vec::new());
    for i in 0..5 {
        for j in 0..5 {
            if i == j {
                continue;
            }
            let f = &frames;
            let mut tracker = Tracker::new(TrackerConfig::rgbd(ICL.fx), ICL, 640, 480, 3);
            assert_eq!(tracker.track(0.0, &f[i]).state, TrackState::NewMap);
            let r = tracker.track(1.0, &f[j]);
            let want = gt[i].inverse() * gt[j];
            let d = want.inverse() * r.world_from_cam.unwrap();
            let (t, a) = (d.translation.vector.norm(), d.rotation.angle().to_degrees());
            eprintln!(
                "{} -> {}: {:?} inliers {} off by {:.1} mm {:.3} deg",
                i + 1,
                j + 1,
                r.state,
                r.inliers,
                t * 1e3,
                a
            );
            if r.state == TrackState::Lost {
                lost.push((i + 1, j + 1));
            } else {
                // Whatever the tracker claims to have found is right.
                assert!(t <= 0.02 && a <= 1.0, "{} -> {}: {t} m, {a} deg", i + 1, j + 1);
                found.push((i + 1, j + 1));
            }
        }
    }
    // These frames were picked for dense mapping, 12 to 91 degrees apart: most pairs share
    // little view. Frames 1 and 3 see the same picture and sofa; that pair must be found.
    assert!(found.contains(&(1, 3)) && found.contains(&(3, 1)), "found {found:?}, lost {lost:?}");
}

/// Run `graphs/orb_baseline.yaml` with `extra` arguments into `out`; its summary.
fn baseline_summary(extra: &[&str], out: &Path) -> Summary {
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none"])
        .args(extra)
        .arg("--out")
        .arg(out)
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let variant = extra.iter().position(|a| *a == "--variant").and_then(|i| extra.get(i + 1));
    common::summary(&out.join(match variant {
        Some(v) => format!("orb_baseline-{v}.summary.json"),
        None => "orb_baseline.summary.json".into(),
    }))
}

#[test]
fn baseline_is_deterministic_in_lockstep_and_runs_in_realtime() {
    let dir = common::TempDir::new("tracking-determinism");
    let digests = |sub: &str| baseline_summary(&["--digest", "--frames", "40"], &dir.path().join(sub)).digests.unwrap();
    let (a, b) = (digests("a"), digests("b"));
    for port in ["track/pose", "track/keyframe", "track/stats", "mapping/points", "mapping/stats"] {
        assert!(a[port].count > 0, "{port}: {a:?}");
    }
    assert_eq!(a, b, "two lockstep runs differ");
    // The stereo, monocular and stereo-inertial modes too, on the static scene (the monocular
    // map starts at frame 8 and local mapping triangulates and fuses from there; the
    // stereo-inertial tracker initialises its IMU at rest by frame 9 and tracks with it).
    for variant in ["stereo", "mono", "stereo_inertial"] {
        let digests = |sub: &str| {
            let out = dir.path().join(format!("{variant}-{sub}"));
            let extra = ["--digest", "--frames", "60", "--set", "camera.people=0", "--variant", variant];
            baseline_summary(&extra, &out).digests.unwrap()
        };
        let (a, b) = (digests("a"), digests("b"));
        assert!(a["mapping/points"].count > 0, "{variant}: {a:?}");
        if variant == "stereo_inertial" {
            assert_eq!(a["camera/imu"].count, 60, "{a:?}");
        }
        assert_eq!(a, b, "{variant}: two lockstep runs differ");
    }

    // Paced at sensor rate, tracking reads the newest map it has (`join: latest`) and never
    // waits for local mapping; the run completes and still reports its ATE.
    let s = baseline_summary(&["--realtime", "--frames", "30"], &dir.path().join("rt"));
    assert!(s.ate.as_ref().is_some_and(|a| a.rmse.is_finite()), "{s:?}");
}

/// Run `graphs/default.yaml` (`variant`, at most `frames`) into `out`, nothing recorded: what it
/// printed and its summary.
fn default_run(variant: Option<&str>, frames: Option<u64>, out: &Path) -> (String, Summary) {
    let mut cmd = common::bin();
    cmd.args(["run", "--no-progress", "--record", "none", "--out"]).arg(out);
    if let Some(v) = variant {
        cmd.args(["--variant", v]);
    }
    if let Some(f) = frames {
        cmd.args(["--frames", &f.to_string()]);
    }
    let o = cmd.arg(common::repo().join("graphs/default.yaml")).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let stem = variant.map_or_else(|| "default".to_owned(), |v| format!("default-{v}"));
    (String::from_utf8_lossy(&o.stdout).into_owned(), common::summary(&out.join(format!("{stem}.summary.json"))))
}

#[test]
fn default_graph_prints_mg_slam_next_to_the_baseline_as_the_readme_quotes() {
    // The README's first command: MG-SLAM (S+G) and the unculled baseline side by side in
    // one run, on the same frames and keypoints; each ATE printed, MG-SLAM's against the
    // baseline's, and both kept in the summary.
    let dir = common::TempDir::new("tracking-default");
    let (stdout, s) = default_run(None, None, &dir.path().join("default"));
    // The README quotes the two ATE lines; they must be what the default graph prints
    // (lockstep runs are deterministic), so they are refreshed when the result changes.
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let quoted: Vec<&str> = readme.lines().filter(|l| l.starts_with("ATE of `")).collect();
    assert_eq!(quoted.len(), 2, "{quoted:?}");
    for line in quoted {
        assert!(stdout.lines().any(|l| l == line), "README says\n{line}\nthe run printed\n{stdout}");
    }
    assert!(stdout.contains("ATE of `baseline` (300 poses"), "{stdout}");
    let line = stdout.lines().find(|l| l.starts_with("ATE of `track`")).unwrap_or_default();
    assert!(line.contains("% vs `baseline`)"), "{stdout}");
    let (baseline, mg) = (&s.trackers["baseline"], &s.trackers["track"]);
    assert_eq!(s.ate.as_ref().and_then(|a| a.node.as_deref()), Some("baseline"), "the first tracker is the reference");
    assert_eq!(baseline.pairs, 300);
    assert_eq!(mg.pairs, 300);
    let (b, m) = (baseline.rmse, mg.rmse);
    assert!(stdout.lines().all(|l| !l.contains("(oracle)")), "the default graph decides without ground truth");
    // The bound on culling, computed here: the same graph and frames with the generator's
    // masks in place of the detector's (`masked`, an oracle), whose tracker sees no walker.
    let (printed, s) = default_run(Some("masked"), None, &dir.path().join("masked"));
    assert!(printed.contains("ATE of `track` (oracle)"), "the oracle run says so: {printed}");
    let oracle = s.trackers["track"].rmse;
    eprintln!("300 frames: baseline {b:.4} m, MG-SLAM {m:.4} m, with ground-truth masks {oracle:.4} m");
    // MG-SLAM within twice what perfect masks give, and the walkers' damage to the baseline
    // at least ten times what is left to MG-SLAM.
    assert!(m <= 2.0 * oracle, "MG-SLAM {m} m against {oracle} m with ground-truth masks");
    assert!(m * 10.0 <= b, "MG-SLAM {m} m vs baseline {b} m");
}

#[test]
fn a_tracker_that_never_initialises_says_so_and_fails_its_bench_row() {
    // Every depth beyond `max_depth` (0.1 m; the scene is 0.45 m or
    // farther), so no frame can start a map.
    let dir = common::TempDir::new("tracking-never");
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", "5", "--set", "track.max_depth=0.1", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        stdout.contains("`track` has no trajectory: the tracker never initialised in 5 frames: at most 0 keypoints"),
        "{stdout}"
    );
    let trajectory = std::fs::read_to_string(dir.path().join("orb_baseline.track.trajectory.txt")).unwrap();
    assert_eq!(trajectory.lines().filter(|l| !l.starts_with('#')).count(), 0, "{trajectory}");
    let bench = dir.path().join("bench");
    let o = common::bin()
        .args([
            "bench",
            "--variants",
            "base",
            "--frames",
            "5",
            "--no-progress",
            "--set",
            "track.max_depth=0.1",
            "--out",
        ])
        .arg(&bench)
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stdout));
    let csv = std::fs::read_to_string(bench.join("bench.csv")).unwrap();
    let row = csv.lines().nth(1).unwrap();
    assert!(row.contains(",failed,") && row.contains("never initialised"), "{row}");
}

/// `orb_baseline --variant mono` on the static scene: the summary and the trajectory file.
fn run_mono(motion: &str, frames: &str, dir: &Path) -> (String, Summary, Vec<(f64, nalgebra::Isometry3<f64>)>) {
    let out = dir.join(format!("mono-{motion}"));
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", frames, "--variant", "mono"])
        .args(["--set", "camera.people=0", "--set", &format!("camera.motion={motion}"), "--out"])
        .arg(&out)
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = common::summary(&out.join("orb_baseline-mono.summary.json"));
    let est = read_trajectory(&out.join("orb_baseline-mono.track.trajectory.txt")).unwrap_or_default();
    (String::from_utf8_lossy(&o.stdout).into_owned(), summary, est)
}

#[test]
fn monocular_initialises_within_30_frames_and_reports_a_sim3_ate() {
    // ORB-SLAM2's monocular mode: a map from two views (H or F, chosen by score),
    // points triangulated by local mapping, scale arbitrary, so the ATE is Sim(3)-aligned.
    // Bounds: initialisation within the first 30 frames (the issue's); ATE within 2 cm
    // (measured 0.86 cm on xyz and 0.64 cm on the orbit, docs/benchmarks.md).
    let dir = common::TempDir::new("tracking-mono");
    for motion in ["xyz", "halfsphere"] {
        let (stdout, summary, est) = run_mono(motion, "300", dir.path());
        let track = summary.tracker("track").unwrap();
        let first = track.first_pose_frame.unwrap();
        assert!(first <= 30, "{motion}: initialised at frame {first}");
        assert_eq!(track.frames.lost, 0, "{motion}");
        assert_eq!(track.maps, 1, "{motion}");
        // Every frame from the initialisation on has a pose, none before.
        assert_eq!(est.len() as u64, 300 - first, "{motion}");
        let ate = summary.ate.clone().unwrap();
        assert_eq!(ate.align, "sim3", "{stdout}");
        // The summary's ATE is evo's Sim(3) evaluation of the trajectory file.
        let gt = ground_truth(motion, 300);
        let e = evaluate(&gt, &est, 0.01, Align::Sim3, 1).unwrap();
        eprintln!("{motion}, static, mono: initialised at frame {first}, ATE RMSE (sim3) {:.4} m", e.ate.rmse);
        assert!((e.ate.rmse - ate.rmse).abs() < 1e-6, "{} vs {}", e.ate.rmse, ate.rmse);
        assert!(e.ate.rmse <= 0.02, "{motion}: mono ATE {} m > 2 cm", e.ate.rmse);
        // Local mapping triangulated the points tracking went on with: the map outgrew the
        // initial two-view map.
        let mapping = summary.report_as::<dynaflow::summary::LocalMappingReport>("mapping").unwrap();
        assert!(mapping.keyframes >= 3, "{mapping:?}");
    }
}

#[test]
fn a_monocular_rotation_without_translation_never_claims_a_pose() {
    // Degenerate input: the rpy motion turns the camera about its centre, so no
    // pair of views has parallax; ORB-SLAM2 does not initialise, and neither does this.
    let dir = common::TempDir::new("tracking-mono-rpy");
    let (stdout, summary, est) = run_mono("rpy", "60", dir.path());
    assert!(est.is_empty(), "{est:?}");
    assert!(summary.ate.is_none());
    assert!(
        stdout.contains("the monocular tracker never initialised in 60 frames") && stdout.contains("parallax"),
        "{stdout}"
    );
}

#[test]
fn a_kitti_sequence_written_by_synth_runs_the_stereo_graphs() {
    // `dynaflow synth --format kitti` writes a stereo sequence in the KITTI odometry layout
    // (seed 11, walking people); `--input` reads it with `kitti_odometry` into the `stereo`
    // variants of orb_baseline, ysag (YSAG-VINS's own setting) and mg_slam. Both culling
    // graphs keep their >= 80 % ATE improvement over orb_baseline on stereo; its mask scoring needs the generator's
    // masks, which KITTI has not, so that node is left out with a warning.
    let dir = common::TempDir::new("tracking-kitti");
    let root = dir.path().join("kitti");
    let o = common::bin()
        .args(["synth", "--format", "kitti", "--people", "2", "--frames", "300", "--seed", "11", "--out"])
        .arg(&root)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let seq = root.join("sequences/00");
    for f in ["calib.txt", "times.txt", "image_2/000299.png", "image_3/000000.png"] {
        assert!(seq.join(f).is_file(), "{f}");
    }
    let ate = |graph: &str| {
        let out = dir.path().join(graph);
        let o = common::bin()
            .args(["run", "--no-progress", "--record", "none", "--variant", "stereo", "--input"])
            .arg(&seq)
            .arg("--out")
            .arg(&out)
            .arg(common::repo().join(format!("graphs/{graph}.yaml")))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(0), "{graph}: {stderr}");
        let summary = common::summary(&out.join(format!("{graph}-stereo.summary.json")));
        let ate = summary.ate.clone().unwrap();
        assert_eq!(ate.pairs, 300, "{graph}: every frame against poses/00.txt");
        (ate.rmse, stderr)
    };
    let (baseline, _) = ate("orb_baseline");
    let (ysag, stderr) = ate("ysag");
    let (mg, _) = ate("mg_slam");
    eprintln!("KITTI layout, stereo: orb_baseline ATE {baseline:.4} m, ysag {ysag:.4} m, mg_slam {mg:.4} m");
    assert!(ysag <= 0.2 * baseline, "ysag {ysag} m vs baseline {baseline} m: less than 80 % better");
    assert!(mg <= 0.2 * baseline, "mg_slam {mg} m vs baseline {baseline} m: less than 80 % better");
    assert!(stderr.contains("node `cull_pr` is left out of the run: it needs `camera.gt_mask`"), "{stderr}");
}
