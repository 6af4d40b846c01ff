//! Data sources end to end: `dynaflow synth` → TUM folder → `tum_rgbd` round trip, real
//! Kinect fixtures, and malformed TUM folders.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::Path;

use dynaflow_engine::msg::{Body, Message};
use dynaflow_engine::runtime::{self, RunError, RunOptions, RunReport, RunStatus};
use dynaflow_engine::sink::{MemorySink, Sink};

fn run(yaml: &str) -> Result<(RunReport, MemorySink), RunError> {
    let g = common::graph(yaml);
    let sink = MemorySink::default();
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let sinks: Vec<Box<dyn Sink>> = vec![Box::new(sink.clone())];
    rt.block_on(runtime::run(&g, RunOptions::default(), sinks)).map(|r| (r, sink))
}

fn tum_graph(dir: &Path, extra: &str) -> String {
    format!("name: tum\nnodes:\n  cam: {{ op: tum_rgbd, params: {{ path: '{}' {extra} }} }}\n", dir.display())
}

fn depth_of(m: &Message) -> &[f32] {
    match &m.body {
        Body::Depth(d) => &d.data,
        _ => panic!("not depth"),
    }
}

#[test]
fn synth_folder_reads_back_with_tum_rgbd() {
    let dir = common::TempDir::new("synth");
    let seq = dir.path().join("seq");
    let out = common::bin()
        .args([
            "synth", "--motion", "xyz", "--frames", "60", "--width", "320", "--height", "240", "--seed", "3", "--out",
        ])
        .arg(&seq)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for f in ["rgb.txt", "depth.txt", "groundtruth.txt", "calibration.txt", "synth.json"] {
        assert!(seq.join(f).is_file(), "{f} missing");
    }
    // The same frames streamed by `synth` and read back by `tum_rgbd`, side by side.
    let yaml = format!(
        "name: rt\nnodes:\n  live: {{ op: synth, params: {{ motion: xyz, frames: 60, width: 320, height: 240, seed: 3 }} }}\n  disk: {{ op: tum_rgbd, params: {{ path: '{}' }} }}\n",
        seq.display()
    );
    let (report, sink) = run(&yaml).unwrap();
    assert_eq!(report.status, RunStatus::Completed);
    let (live_rgb, disk_rgb) = (sink.port("live", "rgb"), sink.port("disk", "rgb"));
    let (live_d, disk_d) = (sink.port("live", "depth"), sink.port("disk", "depth"));
    let (live_p, disk_p) = (sink.port("live", "gt_pose"), sink.port("disk", "gt_pose"));
    assert_eq!((live_rgb.len(), disk_rgb.len(), disk_d.len(), disk_p.len()), (60, 60, 60, 60));
    for k in 0..60 {
        assert_eq!(live_rgb[k].body, disk_rgb[k].body, "frame {k}: colour differs");
        assert!((live_rgb[k].header.stamp - disk_rgb[k].header.stamp).abs() < 1e-6);
        // Depth is stored as 1/5000 m steps.
        let worst =
            depth_of(&live_d[k]).iter().zip(depth_of(&disk_d[k])).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 0.5 / 5000.0 + 1e-6, "frame {k}: depth differs by {worst}");
        let (Body::Pose(a), Body::Pose(b)) = (&live_p[k].body, &disk_p[k].body) else { panic!() };
        let dt = (a.world_from_cam.translation.vector - b.world_from_cam.translation.vector).norm();
        let dr = a.world_from_cam.rotation.angle_to(&b.world_from_cam.rotation);
        assert!(dt < 1e-5 && dr < 1e-6, "frame {k}: pose differs by {dt} m, {dr} rad");
    }
    let (Body::CameraInfo(a), Body::CameraInfo(b)) =
        (&sink.port("live", "camera_info")[0].body, &sink.port("disk", "camera_info")[0].body)
    else {
        panic!()
    };
    assert!((a.fx - b.fx).abs() < 1e-9 && (a.cy - b.cy).abs() < 1e-9);
}

#[test]
fn real_kinect_frames_load_with_tum_depth_scale() {
    let dir = common::repo().join("tests/fixtures/slambook2_rgbd_pair");
    let (report, sink) = run(&tum_graph(&dir, ", intrinsics: fr2")).unwrap();
    assert_eq!(report.status, RunStatus::Completed);
    let depth = sink.port("cam", "depth");
    assert_eq!(depth.len(), 2);
    for d in &depth {
        let mut valid: Vec<f32> = depth_of(d).iter().copied().filter(|z| *z > 0.0).collect();
        valid.sort_by(f32::total_cmp);
        let median = valid[valid.len() / 2];
        // An office scene seen by a Kinect: a median around 1.5 m (it would read 7.5 m with a
        // factor of 1000, 0.3 m with 25000).
        assert!((1.0..2.5).contains(&median), "median depth {median} m");
        assert!(valid.len() > 640 * 480 / 2);
    }
    let Body::CameraInfo(k) = &sink.port("cam", "camera_info")[0].body else { panic!() };
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (520.9, 521.0, 325.1, 249.7));
    let Body::Image(img) = &sink.port("cam", "rgb")[0].body else { panic!() };
    assert_eq!((img.width, img.height), (640, 480));
    assert!(sink.port("cam", "gt_pose").is_empty(), "no groundtruth.txt, no gt_pose");
}

/// A writable copy of the real fixture to break in different ways.
fn broken_copy(tag: &str) -> common::TempDir {
    let dir = common::TempDir::new(tag);
    let src = common::repo().join("tests/fixtures/slambook2_rgbd_pair");
    for sub in ["rgb", "depth"] {
        std::fs::create_dir_all(dir.path().join(sub)).unwrap();
        for f in ["1.png", "2.png"] {
            std::fs::copy(src.join(sub).join(f), dir.path().join(sub).join(f)).unwrap();
        }
    }
    for f in ["rgb.txt", "depth.txt"] {
        std::fs::copy(src.join(f), dir.path().join(f)).unwrap();
    }
    dir
}

fn build_error(dir: &Path, extra: &str) -> String {
    match run(&tum_graph(dir, extra)) {
        Err(e) => e.to_string(),
        Ok((r, _)) => panic!("expected a build error, run ended {:?} {:?}", r.status, r.failures),
    }
}

fn run_failure(dir: &Path, extra: &str) -> String {
    let (report, _) = run(&tum_graph(dir, extra)).unwrap();
    assert_eq!(report.status, RunStatus::Failed);
    report.failures[0].error.clone()
}

#[test]
fn malformed_tum_folders_give_errors_naming_file_and_line() {
    let fr2 = ", intrinsics: fr2";
    // Missing index file.
    let d = broken_copy("missing");
    std::fs::remove_file(d.path().join("depth.txt")).unwrap();
    let e = build_error(d.path(), fr2);
    assert!(e.contains("depth.txt: missing"), "{e}");

    // Non-monotonic timestamps.
    let d = broken_copy("order");
    std::fs::write(d.path().join("rgb.txt"), "# c\n2.0 rgb/2.png\n1.0 rgb/1.png\n").unwrap();
    let e = build_error(d.path(), fr2);
    assert!(e.contains("rgb.txt:3:") && e.contains("earlier than"), "{e}");

    // Duplicate timestamps.
    let d = broken_copy("dup");
    std::fs::write(d.path().join("depth.txt"), "1.0 depth/1.png\n1.0 depth/2.png\n").unwrap();
    let e = build_error(d.path(), fr2);
    assert!(e.contains("depth.txt:2:") && e.contains("duplicate timestamp"), "{e}");

    // Malformed line.
    let d = broken_copy("fields");
    std::fs::write(d.path().join("rgb.txt"), "1.0 rgb/1.png\n2.0\n").unwrap();
    let e = build_error(d.path(), fr2);
    assert!(e.contains("rgb.txt:2:") && e.contains("expected `timestamp filename`"), "{e}");

    // Ground truth within 10 ms of no frame (evo would match nothing): an error.
    let d = broken_copy("gt");
    std::fs::write(d.path().join("groundtruth.txt"), "# gt\n1.02 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 0 1\n").unwrap();
    let e = build_error(d.path(), fr2);
    assert!(e.contains("groundtruth.txt") && e.contains("no pose within 0.01 s of any frame"), "{e}");
    assert!(e.contains("1.020000..1.500000") && e.contains("frames 1.000000..2.000000"), "{e}");
    // Within 10 ms of the first frame only: that frame has ground truth, the second none (a
    // motion-capture gap, which evo leaves out of the ATE too).
    std::fs::write(d.path().join("groundtruth.txt"), "# gt\n1.004 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 0 1\n").unwrap();
    let (report, sink) = run(&tum_graph(d.path(), fr2)).unwrap();
    assert_eq!(report.status, RunStatus::Completed);
    let seqs: Vec<u64> = sink.port("cam", "gt_pose").iter().map(|m| m.header.seq).collect();
    assert_eq!(seqs, [0]);

    // Bad quaternion in the ground truth.
    let d = broken_copy("quat");
    std::fs::write(d.path().join("groundtruth.txt"), "1.0 0 0 0 0 0 0 1\n2.5 0 0 0 0 0 0 3\n").unwrap();
    let e = build_error(d.path(), fr2);
    assert!(e.contains("groundtruth.txt:2:") && e.contains("quaternion"), "{e}");

    // No intrinsics to be found.
    let d = broken_copy("intr");
    let e = build_error(d.path(), "");
    assert!(e.contains("calibration.txt") && e.contains("intrinsics"), "{e}");

    // Wrong bit depth: an 8-bit colour image where 16-bit depth belongs.
    let d = broken_copy("bits");
    std::fs::copy(d.path().join("rgb/2.png"), d.path().join("depth/2.png")).unwrap();
    let e = run_failure(d.path(), fr2);
    assert!(e.contains("depth/2.png") && e.contains("16-bit"), "{e}");

    // Unreadable PNG.
    let d = broken_copy("corrupt");
    std::fs::write(d.path().join("rgb/2.png"), b"\x89PNG\r\n\x1a\nnot really").unwrap();
    let e = run_failure(d.path(), fr2);
    assert!(e.contains("rgb/2.png") && e.contains("decode"), "{e}");

    // …and with `on_error: skip` the bad frame is skipped and counted.
    let (report, sink) = run(&tum_graph(d.path(), ", intrinsics: fr2, on_error: skip")).unwrap();
    assert_eq!(report.status, RunStatus::Completed);
    assert_eq!(sink.port("cam", "rgb").len(), 1);
    let cam = report.nodes.iter().find(|n| n.node == "cam").unwrap();
    assert_eq!((cam.frames, cam.skipped), (1, 1));
}

#[test]
fn cli_reports_a_bad_folder_as_bad_input() {
    let d = broken_copy("cli");
    std::fs::remove_file(d.path().join("rgb.txt")).unwrap();
    let graph = d.path().join("g.yaml");
    std::fs::write(&graph, tum_graph(d.path(), ", intrinsics: fr2")).unwrap();
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--out"])
        .arg(d.path().join("out"))
        .arg(&graph)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("rgb.txt: missing"));
}

#[test]
fn input_flag_points_the_default_graph_at_a_folder() {
    let dir = common::TempDir::new("input");
    let seq = dir.path().join("seq");
    let out = common::bin()
        .args(["synth", "--frames", "8", "--width", "160", "--height", "120", "--out"])
        .arg(&seq)
        .output()
        .unwrap();
    assert!(out.status.success());
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "mcap", "--out"])
        .arg(dir.path().join("out"))
        .arg("--input")
        .arg(&seq)
        .arg(common::repo().join("graphs/default.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let rec = dynaflow_recordings::diff::read_mcap(&dir.path().join("out/default.mcap")).unwrap();
    assert_eq!(rec.topics["/camera/rgb"].frames.len(), 8);
    assert_eq!(rec.topics["/dynamics/stats"].frames.len(), 8, "masks written by synth are read back");
    // A folder that is none of the known layouts is bad input, with the expected layouts named.
    let out = common::bin()
        .args(["run", "--no-progress", "--input"])
        .arg(dir.path().join("out"))
        .arg(common::repo().join("graphs/default.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a TUM RGB-D folder"));
    // A fisheye (Kannala-Brandt) camera is read and recorded as one, and the tracker refuses
    // it by name rather than tracking it as a pinhole.
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "mcap", "--out"])
        .arg(dir.path().join("fisheye"))
        .args(["--intrinsics", "kb:100,100,79.5,59.5,0.0035,0.0007,-0.0021,0.0002", "--input"])
        .arg(&seq)
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("node `track` failed") && err.contains("Kannala-Brandt"), "{err}");
    let rec = dynaflow_recordings::diff::read_mcap(&dir.path().join("fisheye/orb_baseline.mcap")).unwrap();
    let info = &rec.topics["/camera/camera_info"].frames[&0];
    assert_eq!(info["data"]["model"], "kannala_brandt", "{info}");
}

#[test]
fn an_image_folder_runs_monocular_and_a_graph_needing_depth_fails_validation() {
    // An image folder has no depth and no ground truth: `--input` unwires the
    // monocular tracker's depth and leaves out the nodes scoring against masks; a culling
    // rule that judges with depth fails validation at its place in the file; the RGB-D
    // tracker says on the first frame what it needs.
    let dir = common::TempDir::new("input-images");
    let seq = dir.path().join("seq");
    let out = common::bin().args(["synth", "--frames", "40", "--people", "0", "--out"]).arg(&seq).output().unwrap();
    assert!(out.status.success());
    let images = seq.join("rgb");
    let run = |graph: &str, extra: &[&str]| {
        common::bin()
            .args(["run", "--no-progress", "--record", "none", "--intrinsics", "fr3", "--out"])
            .arg(dir.path().join(graph))
            .args(extra)
            .arg("--input")
            .arg(&images)
            .arg(common::repo().join(format!("graphs/{graph}.yaml")))
            .output()
            .unwrap()
    };
    let o = run("orb_baseline", &["--variant", "mono"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = common::summary(&dir.path().join("orb_baseline/orb_baseline-mono.summary.json"));
    let track = summary.tracker("track").unwrap();
    assert!(track.frames.tracked > 20, "{track:?}");
    assert!(summary.ate.is_none(), "an image folder has no ground truth");

    let o = run("yoec_dslam", &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("yoec_dslam.yaml:") && stderr.contains("(op `image_folder`) has no output `depth`"),
        "{stderr}"
    );

    // The RGB-D tracker requires depth: refused at validation, at its place in the file.
    let o = run("orb_baseline", &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("orb_baseline.yaml:") && stderr.contains("(op `image_folder`) has no output `depth`"),
        "{stderr}"
    );
}

#[test]
fn kitti_sequence_reads_stereo_calibration_and_poses() {
    let dir = common::TempDir::new("kitti");
    let synth = dir.path().join("synth");
    let out = common::bin()
        .args(["synth", "--frames", "3", "--width", "64", "--height", "48", "--out"])
        .arg(&synth)
        .output()
        .unwrap();
    assert!(out.status.success());
    // dataset/sequences/07 with dataset/poses/07.txt, as KITTI ships it.
    let seq = dir.path().join("dataset/sequences/07");
    let rgb: Vec<std::path::PathBuf> = {
        let mut v: Vec<_> = std::fs::read_dir(synth.join("rgb")).unwrap().map(|e| e.unwrap().path()).collect();
        v.sort();
        v
    };
    for cam in ["image_0", "image_1"] {
        std::fs::create_dir_all(seq.join(cam)).unwrap();
        for (i, f) in rgb.iter().enumerate() {
            std::fs::copy(f, seq.join(cam).join(format!("{i:06}.png"))).unwrap();
        }
    }
    let fx = 718.856;
    std::fs::write(
        seq.join("calib.txt"),
        format!(
            "P0: {fx} 0 607.1928 0 0 {fx} 185.2157 0 0 0 1 0\nP1: {fx} 0 607.1928 {} 0 {fx} 185.2157 0 0 0 1 0\nP2: {fx} 0 607.1928 45.38225 0 {fx} 185.2157 -0.1130887 0 0 1 0.003779761\nP3: {fx} 0 607.1928 -337.2877 0 {fx} 185.2157 2.369057 0 0 1 0.004915215\nTr: 1 0 0 0 0 1 0 0 0 0 1 0\n",
            -386.1448
        ),
    )
    .unwrap();
    std::fs::write(seq.join("times.txt"), "0.000000e+00\n1.036300e-01\n2.072600e-01\n").unwrap();
    std::fs::create_dir_all(dir.path().join("dataset/poses")).unwrap();
    std::fs::write(
        dir.path().join("dataset/poses/07.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.1 0 1 0 0 0 0 1 0.5\n0 0 1 0.2 0 1 0 0 -1 0 0 1.0\n",
    )
    .unwrap();
    let (report, sink) =
        run(&format!("name: k\nnodes:\n  cam: {{ op: kitti_odometry, params: {{ path: '{}' }} }}\n", seq.display()))
            .unwrap();
    assert_eq!(report.status, RunStatus::Completed, "{:?}", report.failures);
    assert_eq!((sink.port("cam", "rgb").len(), sink.port("cam", "right").len()), (3, 3));
    let Body::StereoRig(rig) = &sink.port("cam", "stereo")[0].body else { panic!() };
    assert!((rig.baseline - 386.1448 / fx).abs() < 1e-9);
    let Body::CameraInfo(k) = &sink.port("cam", "camera_info")[0].body else { panic!() };
    assert_eq!((k.fx, k.cx, k.cy, k.width), (fx, 607.1928, 185.2157, 64));
    let poses = sink.port("cam", "gt_pose");
    assert_eq!(poses.len(), 3);
    let Body::Pose(p) = &poses[2].body else { panic!() };
    assert!((p.world_from_cam.translation.vector - nalgebra::Vector3::new(0.2, 0.0, 1.0)).norm() < 1e-9);
    assert!((p.world_from_cam.rotation.angle() - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
    assert!((sink.port("cam", "rgb")[1].header.stamp - 0.10363).abs() < 1e-9);

    // Too few poses for the frames: an error naming the pose file.
    std::fs::write(dir.path().join("dataset/poses/07.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n").unwrap();
    let e =
        run(&format!("name: k\nnodes:\n  cam: {{ op: kitti_odometry, params: {{ path: '{}' }} }}\n", seq.display()))
            .unwrap_err()
            .to_string();
    assert!(e.contains("07.txt") && e.contains("1 poses for 3 frames"), "{e}");

    // Each broken file named with its line.
    let graph = format!("name: k\nnodes:\n  cam: {{ op: kitti_odometry, params: {{ path: '{}' }} }}\n", seq.display());
    let build_error = |what: &str| run(&graph).map(|_| ()).expect_err(what).to_string();
    // A pose whose 3x3 part is no rotation (a scaled matrix).
    std::fs::write(
        dir.path().join("dataset/poses/07.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 0\n",
    )
    .unwrap();
    let e = build_error("scaled pose");
    assert!(e.contains("07.txt:2:") && e.contains("not a rotation"), "{e}");
    std::fs::remove_file(dir.path().join("dataset/poses/07.txt")).unwrap();
    // times.txt: `nan`, `inf`, empty.
    for (text, line) in [("0\nnan\n0.2\n", 2), ("0\n0.1\ninf\n", 3)] {
        std::fs::write(seq.join("times.txt"), text).unwrap();
        let e = build_error(text);
        assert!(e.contains(&format!("times.txt:{line}:")) && e.contains("is not a time"), "{text}: {e}");
    }
    std::fs::write(seq.join("times.txt"), "\n").unwrap();
    let e = build_error("empty times");
    assert!(e.contains("times.txt: no frame"), "{e}");
    std::fs::write(seq.join("times.txt"), "0.000000e+00\n1.036300e-01\n2.072600e-01\n").unwrap();
    // A zero or negative focal length.
    let calib = std::fs::read_to_string(seq.join("calib.txt")).unwrap();
    for bad in ["0 0 607.1928", "-718.856 0 607.1928"] {
        std::fs::write(seq.join("calib.txt"), calib.replacen(&format!("{fx} 0 607.1928"), bad, 1)).unwrap();
        let e = build_error(bad);
        assert!(e.contains("calib.txt:1:") && e.contains("P0: fx") && e.contains("must be positive"), "{bad}: {e}");
    }
    std::fs::write(seq.join("calib.txt"), &calib).unwrap();
    // Left and right images of different sizes.
    png(&seq.join("image_1/000001.png"), 32, 24, false);
    let (report, _) = run(&graph).unwrap();
    assert_eq!(report.status, RunStatus::Failed);
    assert!(report.failures[0].error.contains("image_1/000001.png: 32x24 but"), "{:?}", report.failures);
}

// Sizes that change, masks that are missing or of another size --------------

/// Write a grey 8-bit (`depth == false`) or 16-bit depth PNG of `w`x`h` to `path`.
fn png(path: &Path, w: u32, h: u32, depth: bool) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    if depth {
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(w, h, image::Luma([5000])).save(path).unwrap();
    } else {
        image::GrayImage::from_pixel(w, h, image::Luma([0])).save(path).unwrap();
    }
}

#[test]
fn a_frame_of_another_size_or_a_missing_or_mismatched_mask_is_an_error() {
    let fr2 = ", intrinsics: fr2";
    // The second frame (colour and depth alike) smaller than the first.
    let d = broken_copy("size-change");
    png(&d.path().join("rgb/2.png"), 320, 240, false);
    png(&d.path().join("depth/2.png"), 320, 240, true);
    let e = run_failure(d.path(), fr2);
    assert!(e.contains("rgb/2.png: 320x240 but the sequence's first frame (rgb/1.png) is 640x480"), "{e}");
    // A `mask/` folder without the second frame's mask.
    let d = broken_copy("mask-missing");
    png(&d.path().join("mask/1.png"), 640, 480, false);
    let e = run_failure(d.path(), fr2);
    assert!(e.contains("mask/2.png: missing"), "{e}");
    // A mask of another size than its image.
    png(&d.path().join("mask/2.png"), 320, 240, false);
    let e = run_failure(d.path(), fr2);
    assert!(e.contains("mask/2.png: 320x240 but rgb/2.png is 640x480"), "{e}");
    // An image folder whose second image is smaller than the first.
    let d = common::TempDir::new("folder-size-change");
    png(&d.path().join("a.png"), 64, 48, false);
    png(&d.path().join("b.png"), 32, 24, false);
    let yaml = format!(
        "name: f\nnodes:\n  cam: {{ op: image_folder, params: {{ path: '{}', intrinsics: '50,50,32,24' }} }}\n",
        d.path().display()
    );
    let (report, _) = run(&yaml).unwrap();
    assert_eq!(report.status, RunStatus::Failed);
    assert!(
        report.failures[0].error.contains("b.png: 32x24 but the first image (a.png) is 64x48"),
        "{:?}",
        report.failures
    );
}

#[test]
fn a_euroc_folder_written_by_synth_runs_as_its_tum_twin_and_records_every_imu_sample() {
    // The same generator (seed 5, hand-held motion, two people) written as a TUM folder and as
    // a EuRoC MAV folder: `--input` picks `tum_rgbd` for one and `euroc` for the other, and
    // the RGB-D graph tracks both alike (the same images, depth and intrinsics; EuRoC's ground
    // truth comes through the body and `T_BS`). The EuRoC run's MCAP holds the IMU port: every
    // sample of imu0/data.csv up to the last frame, once.
    let dir = common::TempDir::new("euroc");
    let frames = "90";
    let write = |format: &str, out: &Path| {
        let o = common::bin()
            .args(["synth", "--motion", "handheld", "--people", "2", "--frames", frames, "--seed", "5", "--format"])
            .arg(format)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{format}: {}", String::from_utf8_lossy(&o.stderr));
    };
    let (tum, euroc) = (dir.path().join("tum"), dir.path().join("euroc"));
    write("tum", &tum);
    write("euroc", &euroc);
    let run = |input: &Path, name: &str, record: &str| {
        let out = dir.path().join(name);
        let o = common::bin()
            .args(["run", "--no-progress", "--record", record, "--input"])
            .arg(input)
            .arg("--out")
            .arg(&out)
            .arg(common::repo().join("graphs/orb_baseline.yaml"))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        let summary = common::summary(&out.join("orb_baseline.summary.json"));
        let ate = summary.ate.clone().unwrap();
        assert_eq!(ate.pairs, 90, "{name}: every frame has ground truth");
        (ate.rmse, out)
    };
    let (ate_tum, _) = run(&tum, "on-tum", "none");
    let (ate_euroc, out) = run(&euroc, "on-euroc", "mcap");
    eprintln!("orb_baseline on the TUM layout: ATE {ate_tum:.6} m; on the EuRoC layout: {ate_euroc:.6} m");
    // TUM's ground truth is written to 1 µm; the estimates are the same.
    assert!((ate_tum - ate_euroc).abs() <= 1e-5, "TUM {ate_tum} m, EuRoC {ate_euroc} m");

    let rec = dynaflow_recordings::diff::read_mcap(&out.join("orb_baseline.mcap")).unwrap();
    let (name, topic) = rec.topics.iter().find(|(k, _)| k.ends_with("/imu")).expect("an IMU topic");
    assert_eq!(topic.schema, "dynaflow.ImuBatch", "{name}");
    let recorded: Vec<f64> = topic
        .frames
        .values()
        .flat_map(|f| f["data"]["stamp"].as_array().unwrap().iter().map(|s| s.as_f64().unwrap()).collect::<Vec<_>>())
        .collect();
    let csv = std::fs::read_to_string(euroc.join("mav0/imu0/data.csv")).unwrap();
    let last_frame = 1_700_000_000.0 + 89.0 / 30.0;
    let written: Vec<f64> = csv
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(',').next().unwrap().parse::<i64>().unwrap() as f64 * 1e-9)
        .filter(|&t| t <= last_frame + 1e-6)
        .collect();
    assert_eq!(recorded, written, "each sample once, in order");
}

#[test]
fn synth_streams_its_imu_per_frame_and_a_blackout_keeps_the_motion() {
    // `imu: true`: each frame carries the rig's samples since the previous frame, exactly the
    // generator's noisy IMU (the scene seed's noise), each sample once. `blackout: 20`: frames
    // 20-49 are black without depth while the camera keeps moving (no rewind, unlike a kidnap).
    use dynaflow_datasets::synth::{Generator, Motion, STAMP_BASE, SynthConfig, rig_calibration, scaled_fr3};
    let (report, sink) = run(
        "name: s\nnodes:\n  cam: { op: synth, params: { motion: handheld, frames: 60, width: 64, height: 48, seed: 4, imu: true, blackout: 20 } }\n",
    )
    .unwrap();
    assert_eq!(report.status, RunStatus::Completed, "{:?}", report.failures);
    let g = Generator::new(SynthConfig {
        motion: Motion::Handheld,
        seed: 4,
        intrinsics: scaled_fr3(64, 48),
        ..SynthConfig::default()
    });
    let truth = g.imu(&rig_calibration(), g.time(59), true);
    let batches = sink.port("cam", "imu");
    assert_eq!(batches.len(), 60);
    let mut streamed = Vec::new();
    for (k, m) in batches.iter().enumerate() {
        let Body::Imu(b) = &m.body else { panic!("{m:?}") };
        assert_eq!(b.calibration, rig_calibration());
        assert!(b.samples.iter().all(|s| s.stamp <= m.header.stamp), "frame {k}: a sample after the frame");
        streamed.extend(b.samples.iter().copied());
    }
    assert_eq!(streamed, truth, "every sample once, in order");
    assert_eq!(streamed.last().map(|s| s.stamp), Some(STAMP_BASE + 1.965));
    let black = |k: usize| {
        let Body::Image(i) = &sink.port("cam", "rgb")[k].body else { panic!() };
        i.data.iter().all(|&v| v == 0) && depth_of(&sink.port("cam", "depth")[k]).iter().all(|&d| d == 0.0)
    };
    assert!(!black(19) && (20..50).all(black) && !black(50));
    let Body::Pose(p) = &sink.port("cam", "gt_pose")[50].body else { panic!() };
    assert!(
        (p.world_from_cam.to_homogeneous() - Motion::Handheld.pose(50.0 / 30.0).to_homogeneous()).abs().max() < 1e-12
    );
    // An IMU cannot follow a kidnap's rewind: refused, naming the parameter.
    let e = run("name: s\nnodes:\n  cam: { op: synth, params: { frames: 3, imu: true, kidnap: 1 } }\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("`imu`") && e.contains("kidnap"), "{e}");
}

#[test]
fn a_fisheye_camera_tracks_through_undistort_at_least_as_well_as_the_pinhole() {
    // `graphs/fisheye.yaml`: the synthetic Kannala-Brandt camera (TUM-VI's lens) resampled to a
    // pinhole by `undistort`, then ORB-SLAM2's monocular and stereo modes; the same graph with
    // `camera.fisheye=false` is the fr3 pinhole on the same motion. A static room (the lens,
    // not the people, is what is compared), two seeds that chose nothing. Issue bound: the
    // fisheye's ATE within 1.5x the pinhole's.
    let dir = common::TempDir::new("fisheye");
    let ate = |variant: &str, seed: u64, fisheye: bool| -> (f64, usize) {
        let out = dir.path().join(format!("{variant}-{seed}-{fisheye}"));
        let o = common::bin()
            .args(["run", "--no-progress", "--record", "none", "--frames", "90", "--variant", variant])
            .args(["--seed", &seed.to_string(), "--set", "camera.people=0"])
            .args(["--set", &format!("camera.fisheye={fisheye}"), "--out"])
            .arg(&out)
            .arg(common::repo().join("graphs/fisheye.yaml"))
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        let s = common::summary(&out.join(format!("fisheye-{variant}.summary.json")));
        let a = s.ate.unwrap_or_else(|| panic!("{variant} seed {seed}: no ATE"));
        (a.rmse, a.pairs as usize)
    };
    for seed in [5, 6] {
        for variant in ["mono", "stereo"] {
            let (fish, fish_poses) = ate(variant, seed, true);
            let (pin, _) = ate(variant, seed, false);
            assert!(fish_poses >= 80, "{variant} seed {seed}: the fisheye tracked {fish_poses} of 90 frames");
            assert!(
                fish <= 1.5 * pin,
                "{variant} seed {seed}: fisheye ATE {fish:.4} m against the pinhole's {pin:.4} m"
            );
        }
    }
}
