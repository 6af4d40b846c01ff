//! ROS bags as run sources (`--input BAG`, the `rosbag` operator), against the `rosbags` Python
//! package (the peer): one synthetic sequence written by `dynaflow synth` as a TUM folder is
//! written again as ROS bags by `tests/peers/tum_to_bags.py` with rosbags' own serialisers.
//!
//! - The raw bags (ROS 1, ROS 2 MCAP, ROS 2 SQLite) give the TUM folder's run, port by port
//!   (per-port digests equal); with JPEG colour `mg_slam`'s ATE stays within 1 mm of it.
//! - A robot's bag (other topic names, JPEG colour, millimetre depth, ground truth only in the
//!   tf tree, record times late and out of order) runs `mg_slam` with `--topics` and nothing
//!   else; its ground truth, resolved through `/tf` and `/tf_static`, is the folder's to 1e-9;
//!   every message it leaves out is counted by reason.
//! - Each defective bag fails before the run with exit status 2 and an error naming the bag,
//!   the topic and the stamp.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dynaflow::summary::{BagReport, SourceReport, Summary};

/// The peers' Python with `rosbags` and OpenCV, when the `rosbags` comparison runs.
fn rosbags_python(comparison: &str) -> Option<PathBuf> {
    let python = common::peers::venv().join("bin/python3");
    let probe = || {
        let ok = Command::new(&python).args(["-c", "import rosbags, cv2"]).output().is_ok_and(|o| o.status.success());
        if ok { Ok(()) } else { Err(format!("{} cannot import rosbags and cv2", python.display())) }
    };
    common::peers::peer_runs("rosbags", comparison, probe).then_some(python)
}

/// The TUM folder (40 frames, two people, seed 21: a seed nothing was chosen on) and the bags
/// `tum_to_bags.py` wrote from it; `None` when the peer is skipped.
fn sequence(dir: &Path, comparison: &str) -> Option<(PathBuf, PathBuf)> {
    let python = rosbags_python(comparison)?;
    let tum = dir.join("tum");
    let o = common::bin()
        .args(["synth", "--frames", "40", "--people", "2", "--seed", "21", "--out"])
        .arg(&tum)
        .output()
        .unwrap();
    assert!(o.status.success(), "synth: {}", String::from_utf8_lossy(&o.stderr));
    // The generator's masks are not in the bags; without them both runs read the same inputs.
    for sub in ["mask", "instance"] {
        let _ = std::fs::remove_dir_all(tum.join(sub));
    }
    let bags = dir.join("bags");
    let o = Command::new(&python)
        .arg(common::repo().join("tests/peers/tum_to_bags.py"))
        .arg(&tum)
        .arg(&bags)
        .output()
        .unwrap();
    assert!(o.status.success(), "tum_to_bags.py: {}", String::from_utf8_lossy(&o.stderr));
    Some((tum, bags))
}

fn run(graph: &str, input: &Path, extra: &[&str], out: &Path) -> Output {
    common::bin()
        .args(["run", "--no-progress", "--record", "none", "--input"])
        .arg(input)
        .args(extra)
        .arg("--out")
        .arg(out)
        .arg(common::repo().join("graphs").join(graph))
        .output()
        .unwrap()
}

fn summary(graph: &str, input: &Path, extra: &[&str], out: &Path) -> Summary {
    let o = run(graph, input, extra, out);
    assert_eq!(o.status.code(), Some(0), "{}: {}", input.display(), String::from_utf8_lossy(&o.stderr));
    common::summary(&out.join(format!("{}.summary.json", graph.trim_end_matches(".yaml"))))
}

fn bag_report(s: &Summary) -> BagReport {
    s.report_as::<SourceReport>("camera").and_then(|r| r.bag).expect("the source's report has no `bag`")
}

#[test]
fn a_bag_runs_as_the_tum_folder_it_was_written_from() {
    let dir = common::TempDir::new("bags-equal");
    let Some((tum, bags)) = sequence(dir.path(), "bags: a bag runs as its TUM folder") else { return };
    let reference = summary("orb_baseline.yaml", &tum, &["--digest"], &dir.path().join("tum-run"));
    let want = reference.digests.clone().unwrap();
    assert!(want["track/pose"].count >= 35, "{want:?}");
    // The bags hold the PNGs' depth values (TUM's 5000 per metre, not REP 118's millimetres).
    for name in ["raw.bag", "raw_mcap", "raw_sqlite"] {
        let s = summary(
            "orb_baseline.yaml",
            &bags.join(name),
            &["--digest", "--set", "camera.depth_factor=5000"],
            &dir.path().join(name),
        );
        assert_eq!(s.digests.as_ref().unwrap(), &want, "{name}: the ports differ from the TUM folder's run");
        let r = bag_report(&s);
        assert_eq!(r.frames, 40, "{name}: {r:?}");
        assert!(r.dropped.is_empty(), "{name}: {r:?}");
        assert_eq!(r.topics["rgb"], "/camera/rgb/image_color", "{name}");
        assert_eq!(r.topics["gt"], "/groundtruth", "{name}");
    }
    // JPEG colour (quality 95): `mg_slam` (which copes with the walking people; ORB-SLAM2's
    // baseline does not on this sequence, and its large error moves with any pixel) within
    // 1 mm of ATE.
    let jpeg_args = ["--set", "camera.depth_factor=5000"];
    let png = summary("mg_slam.yaml", &tum, &[], &dir.path().join("tum-mg"));
    let jpeg = summary("mg_slam.yaml", &bags.join("jpeg_mcap"), &jpeg_args, &dir.path().join("jpeg-mg"));
    let (a, b) = (png.ate.unwrap().rmse, jpeg.ate.unwrap().rmse);
    assert!((a - b).abs() <= 1e-3, "ATE {b} m from JPEG colour, {a} m from the PNGs");
    assert!(a < 0.05, "mg_slam lost the TUM folder's sequence (ATE {a} m): the comparison says nothing");
}

#[test]
fn a_robot_bag_runs_mg_slam_with_topics_and_nothing_else() {
    let dir = common::TempDir::new("bags-robot");
    let Some((tum, bags)) = sequence(dir.path(), "bags: a robot's bag runs mg_slam") else { return };
    let robot = bags.join("robot.bag");
    // Two colour cameras and no pose topic: the run needs the colour topic and the tf pair.
    let o = run("mg_slam.yaml", &robot, &[], &dir.path().join("ambiguous"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("robot.bag") && err.contains("--topics rgb=TOPIC"), "{err}");
    let topics = "rgb=/camera/color/image_raw/compressed,gt=tf:odom:camera_color_optical_frame";
    let s = summary("mg_slam.yaml", &robot, &["--topics", topics], &dir.path().join("run"));
    let r = bag_report(&s);
    // Every tenth colour frame is missing: 36 frames, and 4 depth images without a partner.
    assert_eq!(r.frames, 36, "{r:?}");
    assert_eq!(
        r.dropped.iter().map(|(k, v)| (k.as_str(), *v)).collect::<Vec<_>>(),
        [("/camera/aligned_depth_to_color/image_raw: no colour within 0.02 s", 4)],
        "{r:?}"
    );
    assert_eq!(r.topics["camera_info"], "/camera/color/camera_info");
    assert_eq!(r.frames_without_ground_truth, 0);
    // 200 Hz over the 1.3 s of frames, every third frame from the rear camera, one odometry
    // message per frame (as tum_to_bags.py writes them; docs/robot-bags.md shows these).
    let not_read: Vec<(&str, u64)> = r.topics_not_read.iter().map(|(k, v)| (k.as_str(), *v)).collect();
    assert_eq!(not_read, [("/camera/imu", 260), ("/rear_camera/image_raw", 14), ("/wheel/odom", 40)], "{r:?}");
    assert!(s.ate.is_some_and(|a| a.rmse.is_finite()), "no ATE");
    // The ground truth through odom -> base_link (/tf) -> optical frame (/tf_static) is the
    // folder's camera pose at each frame's stamp.
    use dynaflow_datasets::Sequence as _;
    let mut folder = dynaflow_datasets::tum::TumSequence::open(&tum, None, 0.02, 5000.0, 0).unwrap();
    let options = dynaflow_ros::sequence::BagOptions {
        topics: dynaflow_ros::sequence::Topics::parse(topics).unwrap(),
        max_difference: 0.02,
        depth_factor: 1000.0,
        frames: 0,
        intrinsics: None,
        imu: dynaflow_ros::sequence::ImuOptions::default(),
    };
    let mut bag =
        dynaflow_ros::sequence::BagSequence::open(dynaflow_ros::Bag::open(&robot).unwrap(), &options).unwrap();
    let truth: Vec<(f64, nalgebra::Isometry3<f64>)> = (0..folder.len())
        .map(|i| {
            let f = folder.read(i).unwrap().unwrap();
            (f.stamp, f.gt_pose.unwrap())
        })
        .collect();
    for i in 0..bag.len() {
        let f = bag.frame(i).unwrap().unwrap();
        let (_, want) = truth.iter().find(|(t, _)| *t == f.stamp).unwrap();
        let got = f.gt_pose.unwrap();
        let d = want.inverse() * got;
        assert!(d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-9, "frame {i}: {got} vs {want}");
    }
}

#[test]
fn a_defective_bag_fails_naming_the_bag_the_topic_and_the_stamp() {
    let dir = common::TempDir::new("bags-bad");
    let Some((_, bags)) = sequence(dir.path(), "bags: defects name bag, topic and stamp") else { return };
    // `inspect` lists the raw bag: every topic with its count, and the roles a run would take.
    let o = common::bin().args(["inspect", "--json"]).arg(bags.join("raw.bag")).output().unwrap();
    assert_eq!(o.status.code(), Some(0));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let count = |t: &str| v["topics"].as_array().unwrap().iter().find(|x| x["topic"] == t).map(|x| x["count"].clone());
    assert_eq!(count("/camera/rgb/image_color"), Some(40.into()), "{v}");
    assert_eq!(count("/camera/depth/image"), Some(40.into()), "{v}");
    assert_eq!(v["candidates"]["rgb"], serde_json::json!(["/camera/rgb/image_color"]), "{v}");
    // A bag cut in half.
    let bytes = std::fs::read(bags.join("raw.bag")).unwrap();
    std::fs::write(bags.join("bad_truncated.bag"), &bytes[..bytes.len() / 2]).unwrap();
    let cases: &[(&str, &[&str], &[&str])] = &[
        ("bad_two_colour.bag", &[], &["/camera/rgb/image_color", "/camera/ir/image", "--topics rgb=TOPIC"]),
        (
            "raw.bag",
            &["--topics", "rgb=/camera/color"],
            &["/camera/color", "not in the bag", "/camera/rgb/image_color"],
        ),
        ("bad_encoding.bag", &[], &["/camera/rgb/image_color", "yuv422", " s: "]),
        ("bad_truncated.bag", &[], &["bad_truncated.bag", "(byte ", "after topic /", " s)"]),
        ("bad_no_info.bag", &[], &["CameraInfo", "/camera/rgb/image_color", "--intrinsics"]),
        ("bad_never_pair.bag", &[], &["/camera/rgb/image_color", "/camera/depth/image", " s, is nearest depth "]),
    ];
    for (name, extra, needles) in cases {
        let o = run("orb_baseline.yaml", &bags.join(name), extra, &dir.path().join(name));
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(name), "{name}: the error does not name the bag: {err}");
        for n in *needles {
            assert!(err.contains(n), "{name}: no `{n}` in: {err}");
        }
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
}

/// Rows per entity of an `.rrd` whose chunks carry `column`, from `rerun rrd print`'s chunk
/// lines (`Chunk(..) with N rows (..) - /entity - data columns: [..]`).
fn rrd_rows(print: &str, column: &str) -> std::collections::BTreeMap<String, u64> {
    let mut rows = std::collections::BTreeMap::new();
    for line in print.lines().filter(|l| l.starts_with("Chunk(") && l.contains(column)) {
        let n: u64 = line.split(" with ").nth(1).and_then(|r| r.split(' ').next()).unwrap().parse().unwrap();
        let entity = line.split(" - ").nth(1).unwrap().to_string();
        *rows.entry(entity).or_default() += n;
    }
    rows
}

#[test]
fn a_ros2_recording_reads_back_in_rosbags_and_rerun() {
    let Some(python) = rosbags_python("bags: a ROS 2 recording reads back in rosbags") else { return };
    let rerun = common::peers::venv().join("bin/rerun");
    let dir = common::TempDir::new("bags-ros2");
    let out = dir.path();
    let o = common::bin()
        .args(["run", "--no-progress", "--frames", "20", "--digest", "--record", "ros2", "--out"])
        .arg(out)
        .arg(common::repo().join("graphs/default.yaml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let s = common::summary(&out.join("default.summary.json"));
    let digests = s.digests.unwrap();
    let bag = out.join("default.ros2");
    let o = Command::new(&python).arg(common::repo().join("tests/peers/read_ros2_bag.py")).arg(&bag).output().unwrap();
    assert!(o.status.success(), "rosbags: {}", String::from_utf8_lossy(&o.stderr));
    let topics: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let topic = |t: &str| topics.get(t).unwrap_or_else(|| panic!("no topic {t} in {topics}"));
    // Every port with messages is a topic holding exactly the run's messages of it.
    for (port, d) in digests.iter().filter(|(_, d)| d.count > 0) {
        let t = topics.get(format!("/{port}")).or_else(|| topics.get(format!("/{port}/compressed")));
        let t = t.unwrap_or_else(|| panic!("port {port} is not in the bag: {topics}"));
        assert_eq!(t["count"], d.count, "{port}: {t}");
    }
    // The ROS types a user's tools expect, in a consistent frame tree.
    assert_eq!(topic("/camera/rgb/compressed")["type"], "sensor_msgs/msg/CompressedImage");
    assert_eq!(topic("/camera/rgb/compressed")["format"], "jpeg");
    assert_eq!(topic("/camera/depth")["encoding"], "32FC1");
    assert_eq!(topic("/camera/depth")["size"], serde_json::json!([640, 480]));
    assert_eq!(topic("/camera/camera_info")["k"][0], 535.4);
    let first = s.ate.as_ref().and_then(|a| a.node.clone()).unwrap();
    assert_eq!(topic(&format!("/{first}/pose"))["frame_id"], "map");
    assert_eq!(topic("/camera/gt_pose")["frame_id"], "world");
    assert_eq!(topic("/tf")["count"], digests[&format!("{first}/pose")].count);
    assert_eq!(topic("/tf")["edges"], serde_json::json!(["map->camera"]));
    assert_eq!(topic(&format!("/{first}/pose/path"))["poses"], digests[&format!("{first}/pose")].count);
    assert_eq!(topic("/mapping/points")["fields"], serde_json::json!(["x", "y", "z"]));
    // The last pose is the trajectory file's last line (written with 6-7 decimals).
    let text = std::fs::read_to_string(out.join(format!("default.{first}.trajectory.txt"))).unwrap();
    let last: Vec<f64> = text.lines().last().unwrap().split_whitespace().skip(1).map(|v| v.parse().unwrap()).collect();
    let got = topic(&format!("/{first}/pose"))["last_pose"].as_array().unwrap().clone();
    for (a, b) in last.iter().zip(&got) {
        assert!((a - b.as_f64().unwrap()).abs() < 1e-5, "{last:?} vs {got:?}");
    }
    // rerun's MCAP importer shows the images, depth, map points and the camera's transforms.
    if !common::peers::peer_runs("rerun", "bags: rerun opens a ROS 2 recording", || {
        let ok = Command::new(&rerun).arg("--version").output().is_ok_and(|o| o.status.success());
        if ok { Ok(()) } else { Err(format!("{} does not run", rerun.display())) }
    }) {
        return;
    }
    let mcap = bag.join("default.ros2_0.mcap");
    let rrd = out.join("ros2.rrd");
    let o = Command::new("timeout")
        .arg("300")
        .arg(&rerun)
        .args(["mcap", "convert"])
        .arg(&mcap)
        .arg("-o")
        .arg(&rrd)
        .output()
        .unwrap();
    assert!(o.status.success(), "rerun mcap convert: {}", String::from_utf8_lossy(&o.stderr));
    let o = Command::new("timeout").arg("300").arg(&rerun).args(["rrd", "print"]).arg(&rrd).output().unwrap();
    assert!(o.status.success(), "rerun rrd print: {}", String::from_utf8_lossy(&o.stderr));
    let print = String::from_utf8_lossy(&o.stdout);
    let count = |p: &str| digests[p].count;
    assert_eq!(
        rrd_rows(&print, "EncodedImage:blob").get("/camera/rgb/compressed"),
        Some(&count("camera/rgb")),
        "{print}"
    );
    assert_eq!(rrd_rows(&print, "DepthImage:buffer").get("/camera/depth"), Some(&count("camera/depth")), "{print}");
    assert_eq!(
        rrd_rows(&print, "Transform3D:translation").get("/tf"),
        Some(&count(&format!("{first}/pose"))),
        "{print}"
    );
    assert_eq!(
        rrd_rows(&print, "Points3D:positions").get("/mapping/points"),
        Some(&count("mapping/points")),
        "{print}"
    );
}

#[test]
fn a_bags_imu_runs_rgbd_inertial_as_the_euroc_folder_it_was_written_from() {
    let Some(python) = rosbags_python("bags: a bag's IMU runs visual-inertial") else { return };
    let dir = common::TempDir::new("bags-imu");
    let root = dir.path().join("euroc");
    let o = common::bin()
        .args(["synth", "--format", "euroc", "--motion", "handheld", "--frames", "150", "--people", "0", "--seed", "5"])
        .arg("--out")
        .arg(&root)
        .output()
        .unwrap();
    assert!(o.status.success(), "synth: {}", String::from_utf8_lossy(&o.stderr));
    let mav0 = root.join("mav0");
    let bag = dir.path().join("rig_bag");
    let o = Command::new(&python)
        .arg(common::repo().join("tests/peers/euroc_to_bag.py"))
        .arg(&mav0)
        .arg(&bag)
        .output()
        .unwrap();
    assert!(o.status.success(), "euroc_to_bag.py: {}", String::from_utf8_lossy(&o.stderr));
    let variant = ["--variant", "rgbd_inertial"];
    let out = dir.path().join("folder");
    let o = run("orb_baseline.yaml", &mav0, &variant, &out);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let folder = common::summary(&out.join("orb_baseline-rgbd_inertial.summary.json"));
    // The noise is the folder's imu0/sensor.yaml (EuRoC's ADIS16448 figures, which synth uses);
    // the mounting comes from /tf_static, the ground truth through /tf.
    let noise = "camera.imu_noise=1.6968e-4,2e-3,1.9393e-5,3e-3";
    let args =
        [&variant[..], &["--topics", "gt=tf:world:cam0", "--set", "camera.depth_factor=5000", "--set", noise]].concat();
    let out = dir.path().join("bag");
    let o = run("orb_baseline.yaml", &bag, &args, &out);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let from_bag = common::summary(&out.join("orb_baseline-rgbd_inertial.summary.json"));
    let (a, b) = (folder.tracker("track").unwrap(), from_bag.tracker("track").unwrap());
    let (ia, ib) = (a.inertial.clone().unwrap(), b.inertial.clone().unwrap());
    assert_eq!(ia.init_method, ib.init_method);
    assert!((ia.init_after_s.unwrap() - ib.init_after_s.unwrap()).abs() < 1e-3, "{ia:?} vs {ib:?}");
    for (x, y) in ia
        .gyro_bias
        .unwrap()
        .iter()
        .chain(&ia.accel_bias.unwrap())
        .zip(ib.gyro_bias.unwrap().iter().chain(&ib.accel_bias.unwrap()))
    {
        assert!((x - y).abs() < 1e-6, "biases: {ia:?} vs {ib:?}");
    }
    let (ea, eb) = (a.ate.unwrap(), b.ate.unwrap());
    assert_eq!(ea.pairs, eb.pairs);
    assert!((ea.rmse - eb.rmse).abs() < 1e-4, "ATE {} m from the bag, {} m from the folder", eb.rmse, ea.rmse);
    // The samples after the last frame are counted, not lost silently.
    let r = bag_report(&from_bag);
    assert_eq!(r.topics["imu"], "/imu0");
    let stamps = |f: &str| -> Vec<i64> {
        std::fs::read_to_string(mav0.join(f))
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('#') && !l.is_empty())
            .map(|l| l.split(',').next().unwrap().parse().unwrap())
            .collect()
    };
    let last = *stamps("cam0/data.csv").last().unwrap();
    let after = stamps("imu0/data.csv").iter().filter(|&&s| s > last).count() as u64;
    assert_eq!(r.dropped.get("/imu0: after the last frame").copied().unwrap_or(0), after, "{r:?}");
    // Naming the IMU without its noise is an error saying what to give.
    let o = run("orb_baseline.yaml", &bag, &["--topics", "imu=/imu0,gt=none"], &dir.path().join("no-noise"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("rig_bag") && err.contains("/imu0") && err.contains("imu_noise"), "{err}");
}
