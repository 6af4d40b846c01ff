//! The `frontend` graph end to end: keypoints and tracks recorded for every frame. The
//! front-end's algorithms are tested against OpenCV in `vision/tests/frontend.rs`.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

#[test]
fn frontend_graph_runs_and_records_keypoints_and_tracks() {
    let dir = common::TempDir::new("frontend-graph");
    let out = common::bin()
        .args(["run", "--no-progress", "--frames", "4", "--record", "mcap", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/frontend.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let rec = dynaflow_recordings::diff::read_mcap(&dir.path().join("frontend.mcap")).unwrap();
    let keypoints = &rec.topics["/orb/keypoints"];
    assert_eq!(keypoints.frames.len(), 4);
    for topic in ["/matches/tracks", "/flow/tracks"] {
        let t = &rec.topics[topic];
        assert_eq!(t.frames.len(), 4, "{topic}");
        // Frame 0 has no previous frame; later frames have tracks.
        let n = |k: u64| find_array(&t.frames[&k], "id").map_or(0, Vec::len);
        assert!((1..4).all(|k| n(k) > 50), "{topic}: {:?}", t.frames.values().collect::<Vec<_>>());
    }
}

/// The array under `key`, wherever it sits in the recorded payload.
fn find_array<'a>(v: &'a serde_json::Value, key: &str) -> Option<&'a Vec<serde_json::Value>> {
    match v {
        serde_json::Value::Object(m) => {
            m.get(key).and_then(|x| x.as_array()).or_else(|| m.values().find_map(|x| find_array(x, key)))
        }
        _ => None,
    }
}
