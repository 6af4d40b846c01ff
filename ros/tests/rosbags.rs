//! The bag readers against the `rosbags` package (the peer): the same sensor messages written by
//! its own serialisers as ROS 1 bags (uncompressed, bz2 and lz4 chunks) and ROS 2 bags (MCAP and
//! SQLite storage) by `tests/peers/write_bags.py`, which also writes every value it put in. Each
//! bag must decode to exactly those values, in order, with header stamps told apart from record
//! times; a `.db3` without stored definitions must decode the same through the built-in ones;
//! a bag cut short at any byte must end in an error naming it, never a panic.
#![allow(clippy::unwrap_used, clippy::panic)]

#[path = "../../tests/common/peers.rs"]
mod peers;
#[path = "../../tests/common/tempdir.rs"]
mod tempdir;

use std::path::Path;
use std::process::Command;

use dynaflow_ros::Bag;
use dynaflow_ros::decode::Message;
use dynaflow_ros::sensor::{self, Picture};
use serde_json::Value as Json;

/// The bags `write_bags.py` writes, in a temp folder; `None` when the peer is skipped.
fn bags(comparison: &str) -> Option<tempdir::TempDir> {
    let python = peers::venv().join("bin/python3");
    let probe = || {
        let ok = Command::new(&python).args(["-c", "import rosbags"]).output().is_ok_and(|o| o.status.success());
        if ok { Ok(()) } else { Err(format!("{} cannot import rosbags", python.display())) }
    };
    if !peers::peer_runs("rosbags", comparison, probe) {
        return None;
    }
    let dir = tempdir::TempDir::new("rosbags");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/peers/write_bags.py");
    let out = Command::new(&python).arg(script).arg(dir.path()).output().unwrap();
    assert!(out.status.success(), "write_bags.py: {}", String::from_utf8_lossy(&out.stderr));
    Some(dir)
}

fn floats(v: &Json) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

/// Checks one decoded message against `write_bags.py`'s row for it.
fn check(m: &Message, row: &Json, what: &str) {
    let topic = row["topic"].as_str().unwrap();
    match topic {
        "/cam/color" | "/cam/bgr" => {
            let Picture::Colour(img) = sensor::image(m, 1000.0).unwrap() else { panic!("{what}: not colour") };
            let want: Vec<u8> = row["rgb"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as u8).collect();
            assert_eq!((img.width, img.height), (5, 3), "{what}");
            assert_eq!(img.data, want, "{what}: pixels");
        }
        "/cam/depth" => {
            let Picture::Depth(d) = sensor::image(m, 1000.0).unwrap() else { panic!("{what}: not depth") };
            let want: Vec<f32> =
                row["depth_mm"].as_array().unwrap().iter().map(|v| (v.as_f64().unwrap() / 1000.0) as f32).collect();
            assert_eq!(d.data, want, "{what}: depth");
        }
        "/cam/info" => {
            let c = sensor::camera_info(m).unwrap();
            let (k, d) = (floats(&row["k"]), floats(&row["d"]));
            assert_eq!([c.fx, c.fy, c.cx, c.cy], [k[0], k[4], k[2], k[5]], "{what}");
            assert_eq!(c.distortion.to_vec(), d, "{what}");
        }
        "/imu" => {
            let s = sensor::imu(m).unwrap();
            assert_eq!(s.gyro.as_slice(), floats(&row["gyro"]).as_slice(), "{what}");
            assert_eq!(s.accel.as_slice(), floats(&row["accel"]).as_slice(), "{what}");
            // The double nearest the decimal stamp (what parsing `sec.nnnnnnnnn` gives).
            let ns = row["stamp_ns"].as_i64().unwrap();
            let decimal: f64 = format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000).parse().unwrap();
            assert_eq!(s.stamp, decimal, "{what}");
        }
        "/tf" | "/pose" | "/odom" => {
            let (child, pose) = if topic == "/tf" {
                let mut all = sensor::transforms(m).unwrap();
                assert_eq!(all.len(), 1, "{what}");
                let (_, child, pose) = all.remove(0);
                (Some(child), pose)
            } else {
                let (_, child, pose) = sensor::stamped_pose(m).unwrap();
                (child, pose)
            };
            assert_eq!(pose.translation.vector.as_slice(), floats(&row["t"]).as_slice(), "{what}");
            let q = floats(&row["q"]);
            let got = pose.rotation.quaternion();
            assert!((got.coords - nalgebra::Vector4::new(q[0], q[1], q[2], q[3])).norm() < 1e-12, "{what}: {got:?}");
            assert_eq!(child.as_deref(), row.get("child").and_then(|c| c.as_str()), "{what}");
        }
        other => panic!("unexpected topic {other}"),
    }
}

/// Reads `path` and compares every message with `rows`, in order: the order written for `.bag`
/// and MCAP (file order), record-time order for SQLite (ties in the order written).
fn read_all(path: &Path, rows: &[Json]) {
    let bag = Bag::open(path).unwrap_or_else(|e| panic!("{e}"));
    let mut rows = rows.to_vec();
    if bag.format() == dynaflow_ros::Format::Ros2(dynaflow_ros::Storage::Sqlite) {
        rows.sort_by_key(|r| r["log_time"].as_u64().unwrap());
    }
    let mut n = 0;
    for (i, raw) in bag.messages().unwrap().enumerate() {
        let raw = raw.unwrap_or_else(|e| panic!("{e}"));
        let row = rows.get(i).unwrap_or_else(|| panic!("{}: more messages than written", path.display()));
        let what = format!("{} message {i} ({})", path.display(), raw.connection.topic);
        assert_eq!(raw.connection.topic, row["topic"].as_str().unwrap(), "{what}");
        assert_eq!(raw.connection.type_name(), row["type"].as_str().unwrap().replace("/msg/", "/"), "{what}");
        assert_eq!(raw.log_time, row["log_time"].as_u64().unwrap(), "{what}: record time");
        let m = raw.decode().unwrap_or_else(|e| panic!("{what}: {e}"));
        let stamp = if raw.connection.topic == "/tf" {
            sensor::transforms(&m).unwrap()[0].0.stamp_ns
        } else {
            sensor::header(&m).unwrap().stamp_ns
        };
        assert_eq!(stamp, row["stamp_ns"].as_i64().unwrap(), "{what}: header stamp");
        check(&m, row, &what);
        n += 1;
    }
    assert_eq!(n, rows.len(), "{}: messages read", path.display());
}

#[test]
fn every_bag_kind_decodes_what_rosbags_wrote() {
    let Some(dir) = bags("bags written by rosbags decode to the values written") else { return };
    let expected: Json =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("expected.json")).unwrap()).unwrap();
    let kinds = expected.as_object().unwrap();
    assert_eq!(kinds.len(), 5);
    for (name, rows) in kinds {
        read_all(&dir.path().join(name), rows.as_array().unwrap());
    }
    // The storage files on their own, without the rosbag2 folder.
    read_all(&dir.path().join("ros2_mcap/ros2_mcap.mcap"), expected["ros2_mcap"].as_array().unwrap());
    read_all(&dir.path().join("ros2_sqlite/ros2_sqlite.db3"), expected["ros2_sqlite"].as_array().unwrap());
}

#[test]
fn a_db3_without_stored_definitions_decodes_through_the_known_ones() {
    let Some(dir) = bags("a .db3 without message_definitions decodes with the built-in sensor types") else { return };
    let expected: Json =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("expected.json")).unwrap()).unwrap();
    let db3 = dir.path().join("ros2_sqlite/ros2_sqlite.db3");
    let old = dir.path().join("humble.db3");
    std::fs::copy(&db3, &old).unwrap();
    // As rosbag2 wrote SQLite bags before Iron: no message_definitions table.
    rusqlite::Connection::open(&old).unwrap().execute("DROP TABLE message_definitions", []).unwrap();
    read_all(&old, expected["ros2_sqlite"].as_array().unwrap());
}

#[test]
fn bags_cut_short_end_in_an_error_naming_the_file() {
    let Some(dir) = bags("truncated bags written by rosbags are errors") else { return };
    for name in ["ros1_none.bag", "ros1_bz2.bag", "ros2_mcap/ros2_mcap.mcap"] {
        let full = std::fs::read(dir.path().join(name)).unwrap();
        let cut_path = dir.path().join("cut");
        // Every 97th byte, and each of the last 16.
        for cut in (16..full.len()).step_by(97).chain(full.len() - 16..full.len()) {
            std::fs::write(&cut_path, &full[..cut]).unwrap();
            let err = match Bag::open(&cut_path) {
                Err(e) => e.to_string(),
                Ok(bag) => match bag.messages() {
                    Err(e) => e.to_string(),
                    Ok(msgs) => match msgs.filter_map(Result::err).next() {
                        Some(e) => e.to_string(),
                        None => panic!("{name} cut at {cut} of {} bytes read without an error", full.len()),
                    },
                },
            };
            assert!(err.contains(&cut_path.display().to_string()), "{name} at {cut}: {err}");
        }
    }
}

#[test]
fn inspect_counts_rates_and_roles() {
    let Some(dir) = bags("inspect lists what rosbags wrote") else { return };
    for name in ["ros1_lz4.bag", "ros2_mcap", "ros2_sqlite"] {
        let inv = dynaflow_ros::inspect::inspect(&Bag::open(&dir.path().join(name)).unwrap()).unwrap();
        let t = |topic: &str| inv.topics.iter().find(|t| t.topic == topic).unwrap_or_else(|| panic!("{name}: {topic}"));
        assert_eq!(inv.topics.len(), 8, "{name}");
        assert_eq!((t("/cam/color").count, t("/imu").count), (3, 18), "{name}");
        // Header stamps 33.333 ms apart: 30 Hz; the IMU's 5 ms steps within each frame.
        assert!((t("/cam/color").rate_hz - 30.0).abs() < 1e-6, "{name}: {:?}", t("/cam/color"));
        assert_eq!(t("/cam/depth").content.as_deref(), Some("depth"), "{name}");
        // Two colour topics: a run must be told which; the rest are clear. Odometry is an
        // estimate, never taken as ground truth unless named: the one pose topic is.
        assert_eq!(inv.candidates["rgb"], ["/cam/bgr", "/cam/color"], "{name}");
        assert_eq!(inv.chosen("rgb"), None);
        assert_eq!(inv.candidates["gt"], ["/pose"], "{name}");
        assert_eq!(
            (inv.chosen("depth"), inv.chosen("imu"), inv.chosen("camera_info")),
            (Some("/cam/depth"), Some("/imu"), Some("/cam/info"))
        );
    }
}
