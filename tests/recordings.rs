//! Recordings end to end: rerun `.rrd` and MCAP files of real runs, crash safety under
//! SIGKILL, `dynaflow diff`, and checks by the peer tools (rerun CLI, Python `mcap` reader)
//! when they are installed (CI installs them and sets `DYNAFLOW_REQUIRE_PEERS=1`).
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use dynaflow_engine::sink::{PortReport, SinkReport};
use dynaflow_recordings::diff::read_mcap;

fn run_default(dir: &Path, extra: &[&str]) -> std::process::Output {
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "rrd,mcap,jsonl", "--out"])
        .arg(dir)
        .args(extra)
        .arg(common::repo().join("graphs/engine_smoke.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    out
}

/// A peer tool for `comparison`, or `None` when that comparison is skipped
/// ([`common::peers::peer_runs`]).
fn peer(tool: &str, comparison: &str) -> Option<PathBuf> {
    let candidate = common::peers::venv().join("bin").join(tool);
    // A Python counts only with the `mcap` reader and `protobuf` installed (a user's `python` usually
    // lacks it; the test then skips instead of failing).
    let probe: &[&str] = if tool == "python" { &["-c", "import mcap, google.protobuf"] } else { &["--version"] };
    let works = |exe: &Path| {
        Command::new(exe)
            .args(probe)
            .stdin(std::process::Stdio::null())
            .output()
            .ok()
            .is_some_and(|o| o.status.success())
    };
    let name = if tool == "python" { "mcap" } else { tool };
    let mut found = None;
    let runs = common::peers::peer_runs(name, comparison, || {
        found = [candidate, PathBuf::from(tool)].into_iter().find(|exe| works(exe));
        found.as_ref().map(|_| ()).ok_or_else(|| format!("no `{tool}` that runs"))
    });
    found.filter(|_| runs)
}

fn rerun_rrd(rerun: &Path, args: &[&str], file: &Path) -> std::process::Output {
    Command::new("timeout")
        .arg("300")
        .arg(rerun)
        .arg("rrd")
        .args(args)
        .arg(file)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap()
}

/// Check `rrd` with `rerun rrd verify` and read `mcap` end to end with the Python reader (CRCs
/// validated), when the peers are installed; returns the reader's output.
fn peers_accept(rrd: &Path, mcap: &Path) -> Option<String> {
    if let Some(rerun) = peer("rerun", "recordings::peers_accept: rerun rrd") {
        let out = rerun_rrd(&rerun, &["verify"], rrd);
        let log = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(out.status.success(), "rerun rrd verify {}: {log}", rrd.display());
    }
    let python = peer("python", "recordings::peers_accept: mcap reader")?;
    let out = Command::new(python).arg(common::repo().join("tests/peers/check_mcap.py")).arg(mcap).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "python mcap reader {}: {stdout}{}",
        mcap.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(stdout)
}

#[test]
fn default_run_writes_complete_rrd_and_mcap() {
    let dir = common::TempDir::new("rec");
    run_default(dir.path(), &[]);
    let rec = read_mcap(&dir.path().join("engine_smoke.mcap")).unwrap();
    assert!(!rec.truncated);
    // One channel per recorded port, each with its schema.
    let expected =
        ["/camera/image", "/camera/tick", "/keyframes/output", "/detector/value", "/fuse/sum", "/smooth/sum"];
    assert_eq!(
        rec.topics.keys().map(String::as_str).collect::<Vec<_>>().len(),
        expected.len(),
        "{:?}",
        rec.topics.keys()
    );
    for t in expected {
        let topic = &rec.topics[t];
        assert!(!topic.schema.is_empty(), "{t} has no schema");
    }
    assert_eq!(rec.topics["/camera/image"].schema, "foxglove.CompressedImage");
    assert_eq!(rec.topics["/detector/value"].schema, "dynaflow.Scalars");
    assert_eq!(rec.topics["/camera/image"].frames.len(), 300);
    assert_eq!(rec.topics["/keyframes/output"].frames.len(), 60);
    assert_eq!(rec.metadata["graph"], "engine_smoke");
    assert!(rec.metadata["graph_yaml"].contains("testing.random_scalar"));
    assert_eq!(rec.metadata["seed"], "7");
    // The MCAP and the message log agree message for message (same digests).
    let log = std::fs::read_to_string(dir.path().join("engine_smoke.messages.jsonl")).unwrap();
    let mut n = 0;
    for line in log.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        if v["kind"] == "msg" {
            let topic = format!("/{}/{}", v["node"].as_str().unwrap(), v["port"].as_str().unwrap());
            let payload = &rec.topics[&topic].frames[&v["seq"].as_u64().unwrap()];
            assert_eq!(payload["digest"], v["digest"]);
            n += 1;
        }
    }
    assert_eq!(n, rec.topics.values().map(|t| t.frames.len()).sum::<usize>());
    let rrd = dir.path().join("engine_smoke.rrd");
    assert!(std::fs::metadata(&rrd).unwrap().len() > 10_000);
    if let Some(stdout) = peers_accept(&rrd, &dir.path().join("engine_smoke.mcap")) {
        assert!(stdout.contains(&format!("messages {n}")), "{stdout}");
    }
}

#[test]
fn sigkill_midway_leaves_readable_prefixes() {
    let dir = common::TempDir::new("kill");
    let graph = dir.path().join("kill.yaml");
    std::fs::write(
        &graph,
        "name: kill\nnodes:\n  camera: { op: testing.test_pattern, params: { frames: 300, width: 320, height: 240 } }\n  work: { op: testing.simulate_work, in: { input: camera.tick }, params: { work_us: 20000 } }\n",
    )
    .unwrap();
    let mut child = common::bin()
        .args(["run", "--no-progress", "--record", "rrd,mcap", "--mcap-chunk-kib", "64", "--out"])
        .arg(dir.path())
        .arg(&graph)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mcap_path = dir.path().join("kill.mcap");
    let t = Instant::now();
    // Kill once a few chunks are on disk (however slow the machine), well before frame 300.
    while std::fs::metadata(&mcap_path).map_or(0, |m| m.len()) < 200_000 {
        assert!(t.elapsed() < Duration::from_secs(120), "run never wrote chunks");
        assert!(child.try_wait().unwrap().is_none(), "run ended before it could be killed");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let rec = read_mcap(&mcap_path).unwrap();
    assert!(rec.truncated, "a killed run cannot have finished its MCAP");
    let images = &rec.topics["/camera/image"].frames;
    assert!(!images.is_empty() && images.len() < 300, "{}", images.len());
    // No corrupt and no missing message: every topic holds frames 0..n without holes.
    for (name, topic) in &rec.topics {
        let frames: Vec<u64> = topic.frames.keys().copied().collect();
        assert_eq!(frames, (0..frames.len() as u64).collect::<Vec<_>>(), "{name} has holes");
        assert!(topic.frames.values().all(|p| p["digest"].as_str().is_some_and(|d| d.len() == 16)));
    }
    if let Some(python) = peer("python", "recordings::sigkill_midway_leaves_readable_prefixes: mcap reader") {
        let out = Command::new(python)
            .arg(common::repo().join("tests/peers/check_mcap.py"))
            .arg("--truncated")
            .arg(&mcap_path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "python mcap reader on the prefix: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    if let Some(rerun) = peer("rerun", "recordings::sigkill_midway_leaves_readable_prefixes: rerun rrd") {
        // The prefix of a killed run has no footer; everything before the cut verifies.
        let killed = dir.path().join("kill.rrd");
        let out = rerun_rrd(&rerun, &["verify", "--check-footers", "false"], &killed);
        assert!(
            out.status.success(),
            "rrd prefix does not verify: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        // The documented recovery re-writes it as a complete file that passes the full check.
        let recovered = dir.path().join("recovered.rrd");
        let out = rerun_rrd(&rerun, &["merge", "-o", recovered.to_str().unwrap()], &killed);
        assert!(out.status.success(), "rrd merge: {}", String::from_utf8_lossy(&out.stderr));
        let out = rerun_rrd(&rerun, &["verify"], &recovered);
        assert!(out.status.success(), "recovered rrd does not verify: {}", String::from_utf8_lossy(&out.stderr));
    }
}

#[test]
fn diff_same_seed_is_identical_and_a_changed_parameter_is_located() {
    let (a, b, c) = (common::TempDir::new("da"), common::TempDir::new("db"), common::TempDir::new("dc"));
    run_default(a.path(), &[]);
    run_default(b.path(), &[]);
    run_default(c.path(), &["--set", "detector.scale=2.0"]);
    let (ma, mb, mc) =
        (a.path().join("engine_smoke.mcap"), b.path().join("engine_smoke.mcap"), c.path().join("engine_smoke.mcap"));

    let out = common::bin().arg("diff").arg(&ma).arg(&mb).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stdout));
    assert!(String::from_utf8_lossy(&out.stdout).contains("identical within tolerance"));

    let overlay = c.path().join("overlay.rrd");
    let out = common::bin().arg("diff").arg(&ma).arg(&mc).arg("--json").arg("--out").arg(&overlay).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["same"], false);
    // The detector draws at frame 0 already differ; the camera does not.
    assert_eq!(report["first_divergence"], serde_json::json!([0, "/detector/value"]));
    let topic = |name: &str| report["topics"].as_array().unwrap().iter().find(|t| t["topic"] == name).unwrap().clone();
    assert_eq!(topic("/camera/image")["frames_differing"], 0);
    assert_eq!(topic("/detector/value")["frames_differing"], 60);
    // scale 1 → 2 doubles each draw: the largest delta is the largest draw, below 1.
    let delta = topic("/detector/value")["max"]["value"].as_f64().unwrap();
    assert!(delta > 0.0 && delta < 1.0, "{delta}");
    assert!(std::fs::metadata(&overlay).unwrap().len() > 1000);

    // A loose enough tolerance on the affected topics accepts the change.
    let out = common::bin()
        .arg("diff")
        .arg(&ma)
        .arg(&mc)
        .args(["--tol", "/detector/*=1", "--tol", "/fuse/*=1", "--tol", "/smooth/*=1000"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stdout));
    // A tolerance that is too tight does not.
    let out = common::bin().arg("diff").arg(&ma).arg(&mc).args(["--tol", "*=0.001"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));

    // Bad input: exit 2 naming the file.
    let out = common::bin().arg("diff").arg(&ma).arg(a.path().join("missing.mcap")).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.mcap"));
    let out = common::bin().arg("diff").arg(&ma).arg(&mb).args(["--tol", "oops"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn unwritable_output_is_a_clear_error_not_a_hang() {
    let dir = common::TempDir::new("ro");
    let out_dir = dir.path().join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    // A directory where the recording file should go makes creating it fail.
    std::fs::create_dir_all(out_dir.join("engine_smoke.mcap")).unwrap();
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "mcap", "--out"])
        .arg(&out_dir)
        .arg(common::repo().join("graphs/engine_smoke.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("engine_smoke.mcap"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[cfg(target_os = "linux")]
#[test]
fn full_disk_fails_the_run_with_the_file_named() {
    // /dev/full accepts opens and fails every write with ENOSPC.
    if !Path::new("/dev/full").exists() {
        return;
    }
    // Each recorder in turn, writing to the device itself (the CLI names its files inside
    // `--out` and replaces a symlink planted there rather than following it, so the device is
    // given to the recorder directly): the run fails naming the file and the cause (the MCAP
    // writer's own message hides the cause; the rerun file is written by dynaflow's own sink).
    use dynaflow_engine::sink::Sink;
    use dynaflow_recordings::{McapSink, MessageLog, RrdSink};
    let graph = common::graph(&std::fs::read_to_string(common::repo().join("graphs/engine_smoke.yaml")).unwrap());
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let full = Path::new("/dev/full");
    let sinks: [(&str, Box<dyn Sink>); 3] = [
        ("jsonl", Box::new(MessageLog::new(full))),
        ("rrd", Box::new(RrdSink::new(full))),
        ("mcap", Box::new(McapSink::new(full))),
    ];
    for (format, sink) in sinks {
        let said = match rt.block_on(dynaflow_engine::runtime::run(&graph, Default::default(), vec![sink])) {
            Err(e) => e.to_string(),
            Ok(r) => {
                assert_ne!(
                    r.status,
                    dynaflow_engine::runtime::RunStatus::Completed,
                    "{format}: completed on a full disk"
                );
                r.failures.iter().map(|f| f.error.clone()).collect::<Vec<_>>().join("; ")
            }
        };
        assert!(said.contains("/dev/full") && said.to_lowercase().contains("no space"), "{format}: {said}");
        assert!(full.exists(), "the device was removed");
    }
}

#[test]
fn default_synthetic_scene_recording_verifies() {
    let dir = common::TempDir::new("synthrec");
    let out = common::bin()
        .args(["run", "--no-progress", "--frames", "30", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/default.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let rec = read_mcap(&dir.path().join("default.mcap")).unwrap();
    for (topic, schema) in [
        ("/camera/rgb", "foxglove.CompressedImage"),
        ("/camera/depth", "foxglove.RawImage"),
        ("/camera/gt_mask", "foxglove.RawImage"),
        ("/camera/gt_pose", "foxglove.PoseInFrame"),
        ("/camera/camera_info", "foxglove.CameraCalibration"),
        ("/dynamics/stats", "dynaflow.Scalars"),
    ] {
        assert_eq!(rec.topics[topic].schema, schema, "{topic}");
        assert_eq!(rec.topics[topic].frames.len(), 30, "{topic}");
    }
    // The Python reader decodes the protobuf image messages with the schemas' own descriptors.
    if let Some(stdout) = peers_accept(&dir.path().join("default.rrd"), &dir.path().join("default.mcap")) {
        for line in [
            "pixels /camera/depth foxglove.RawImage 32FC1 640x480",
            "pixels /camera/gt_mask foxglove.RawImage mono8 640x480",
            "pixels /camera/rgb foxglove.CompressedImage jpeg 640x480",
        ] {
            assert!(stdout.contains(line), "{line} not in {stdout}");
        }
    }
    // The rerun file, read back by the rerun CLI: a row per message on each port's entity, one
    // metrics entity per scalar port (its names are series), a pose path in segments.
    if let Some(rerun) = peer("rerun", "recordings::default_synthetic_scene_recording_verifies: rerun rrd") {
        let rows = rows_per_entity(&rerun, &dir.path().join("default.rrd"));
        for entity in ["/camera/depth", "/camera/rgb", "/orb/keypoints"] {
            assert_eq!(rows.get(entity), Some(&30), "{entity}: {rows:?}");
        }
        // 30 rows of values and one static row of series names.
        assert_eq!(rows.get("/metrics/track/stats"), Some(&31), "{rows:?}");
        assert!(!rows.keys().any(|e| e.starts_with("/metrics/track/stats/")), "{rows:?}");
        assert!(rows.get("/world/track/pose_path/0").is_some_and(|n| *n >= 1), "{rows:?}");
    }
    // The summary says what each recorder wrote, per port and per frame.
    let summary = common::summary(&dir.path().join("default.summary.json"));
    let mcap_bytes = std::fs::metadata(dir.path().join("default.mcap")).unwrap().len();
    let recorders = &summary.run.recorders;
    assert_eq!(recorders["mcap"].file_bytes, Some(mcap_bytes));
    let depth = &recorders["mcap"].ports["camera/depth"];
    assert_eq!(depth.messages, 30);
    // 640x480 f32 samples plus the protobuf fields and the payload.
    let per_frame = depth.bytes_per_frame.unwrap();
    assert!((640.0 * 480.0 * 4.0..640.0 * 480.0 * 4.0 + 2048.0).contains(&per_frame), "{per_frame}");
    assert_eq!(recorders["rerun"].ports["camera/rgb"].messages, 30);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("recorded mcap:") && stdout.contains("camera/depth"), "{stdout}");
}

#[test]
fn recordings_made_before_protobuf_images_still_diff_and_replay() {
    // tests/fixtures/legacy_mcap: JSON images, depth as millimetre PNG (see its SOURCE.md).
    let fixture = common::repo().join("tests/fixtures/legacy_mcap");
    let legacy = fixture.join("legacy.mcap");
    let dir = common::TempDir::new("legacy");
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "mcap", "--out"])
        .arg(dir.path())
        .arg(fixture.join("legacy.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let current = dir.path().join("legacy.mcap");
    let (old, new) = (read_mcap(&legacy).unwrap(), read_mcap(&current).unwrap());
    assert_eq!(old.topics["/camera/depth"].schema, "foxglove.CompressedImage");
    assert_eq!(new.topics["/camera/depth"].schema, "foxglove.RawImage");
    assert_eq!(old.topics.keys().collect::<Vec<_>>(), new.topics.keys().collect::<Vec<_>>());
    for (topic, t) in &old.topics {
        assert_eq!(t.frames.len(), 3, "{topic}");
        assert_eq!(new.topics[topic].frames.len(), 3, "{topic}");
        assert!(t.frames.values().all(|p| p["digest"].as_str().is_some_and(|d| d.len() == 16)), "{topic}");
    }
    // `dynaflow diff` compares the two layouts topic by topic (exit 0 or 1, never a read error);
    // the old file's digests are scheme 1, so it says it compared numeric payloads only.
    let out = common::bin().arg("diff").arg(&legacy).arg(&current).arg("--json").output().unwrap();
    assert!(matches!(out.status.code(), Some(0 | 1)), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["topics"].as_array().unwrap().len(), old.topics.len());
    assert!(report["digests"].as_str().is_some_and(|n| n.contains("dynaflow-digest-1")), "{report}");
    assert!(!old.metadata.contains_key("digest"));
    assert_eq!(new.metadata["digest"], dynaflow_engine::msg::DIGEST_SCHEME);

    // `mcap_replay` reads the old file: depth to the millimetre, JPEG colour, exact keypoints.
    let yaml = format!(
        "name: old\nnodes:\n  src: {{ op: mcap_replay, params: {{ path: '{}', topics: 'depth=/camera/depth,rgb=/camera/rgb,mask=/camera/gt_mask,keypoints=/orb/keypoints' }} }}\n",
        legacy.display()
    );
    let sink = run_in_memory(&yaml);
    let depth = sink.port("src", "depth");
    assert_eq!(depth.len(), 3);
    for m in &depth {
        let dynaflow_engine::msg::Body::Depth(d) = &m.body else { panic!() };
        assert_eq!((d.width, d.height), (160, 120));
        let measured = d.data.iter().filter(|v| **v > 0.0).count();
        assert!(measured > d.data.len() / 2, "{measured} of {} pixels have depth", d.data.len());
        assert!(d.data.iter().all(|v| ((v * 1000.0) - (v * 1000.0).round()).abs() < 1e-3), "not whole millimetres");
    }
    assert!(
        sink.port("src", "rgb")
            .iter()
            .all(|m| matches!(&m.body, dynaflow_engine::msg::Body::Image(i) if i.width == 160))
    );
    assert_eq!(sink.port("src", "mask").len(), 3);
    let keypoints = sink.port("src", "keypoints");
    assert_eq!(keypoints.len(), 3);
    for m in keypoints {
        let dynaflow_engine::msg::Body::Keypoints(k) = &m.body else { panic!() };
        let recorded = &old.topics["/orb/keypoints"].frames[&m.header.seq]["data"]["xy"];
        let xy: Vec<[f32; 2]> = k.points.iter().map(|p| [p.x, p.y]).collect();
        assert_eq!(serde_json::to_value(&xy).unwrap(), *recorded);
    }
}

#[test]
fn mcap_replay_restores_recorded_messages() {
    let dir = common::TempDir::new("replay");
    let out = common::bin()
        .args(["run", "--no-progress", "--frames", "12", "--record", "mcap", "--image-format", "raw", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/default.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let mcap = dir.path().join("default.mcap");
    let recorded = read_mcap(&mcap).unwrap();
    let yaml = format!(
        "name: replay\nnodes:\n  src: {{ op: mcap_replay, params: {{ path: '{}', topics: 'rgb=/camera/rgb,depth=/camera/depth,pose=/camera/gt_pose,camera_info=/camera/camera_info,mask=/camera/gt_mask,scalars=/dynamics/stats' }} }}\n  dynamics: {{ op: mask_stats, in: {{ mask: src.mask }} }}\n",
        mcap.display()
    );
    let graph = common::graph(&yaml);
    let sink = dynaflow_engine::sink::MemorySink::default();
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let report =
        rt.block_on(dynaflow_engine::runtime::run(&graph, Default::default(), vec![Box::new(sink.clone())])).unwrap();
    assert_eq!(report.status, dynaflow_engine::runtime::RunStatus::Completed, "{:?}", report.failures);
    // Lossless types come back bit-exact: same content digests as recorded (depth included:
    // `32FC1` samples, whatever the source's quantisation).
    for (port, topic) in [
        ("rgb", "/camera/rgb"),
        ("depth", "/camera/depth"),
        ("pose", "/camera/gt_pose"),
        ("camera_info", "/camera/camera_info"),
        ("scalars", "/dynamics/stats"),
    ] {
        let replayed = sink.port("src", port);
        assert_eq!(replayed.len(), 12, "{port}");
        for m in &replayed {
            let digest = &recorded.topics[topic].frames[&m.header.seq]["digest"];
            assert_eq!(digest.as_str().unwrap(), format!("{:016x}", m.digest()), "{topic} frame {}", m.header.seq);
        }
    }
    // The late part of the graph re-run on the replayed mask computes the same dynamic fraction.
    for m in sink.port("dynamics", "stats") {
        let dynaflow_engine::msg::Body::Scalars(s) = &m.body else { panic!() };
        let original = &recorded.topics["/dynamics/stats"].frames[&m.header.seq]["data"]["dynamic_fraction"];
        assert_eq!(s.get("dynamic_fraction").unwrap(), original.as_f64().unwrap());
    }
    // Replayed ground truth is still ground truth: the recording marks its ground-truth
    // topics (and what derives from them: `dynamics.stats`), and a replay that decides with
    // them must declare `oracle: true`.
    let channels = dynaflow_recordings::replay::ground_truth_topics(&mcap).unwrap();
    for t in ["/camera/gt_mask", "/camera/gt_pose", "/dynamics/stats"] {
        assert!(channels.iter().any(|c| c == t), "{t} not marked: {channels:?}");
    }
    assert!(!channels.iter().any(|c| c == "/camera/rgb" || c == "/track/pose"), "{channels:?}");
    let deciding = format!("{yaml}  orb: {{ op: orb_extract, in: {{ image: src.rgb, mask: src.mask }} }}\n");
    let loaded = dynaflow_engine::load_str("t.yaml", &deciding, None, &dynaflow::registry(), &Default::default());
    let d = loaded.diagnostics.iter().find(|d| d.code == "undeclared-oracle").expect("an undeclared oracle");
    assert!(d.message.contains("orb/mask <- src.mask"), "{}", d.message);
    common::graph(&deciding.replace("name: replay\n", "name: replay\noracle: true\n"));
    // A topic that is not in the file is a clear error listing the topics.
    let bad = yaml.replace("/camera/gt_pose", "/camera/gt_pos");
    let graph = common::graph(&bad);
    let err =
        rt.block_on(dynaflow_engine::runtime::run(&graph, Default::default(), Vec::new())).unwrap_err().to_string();
    assert!(err.contains("no topic `/camera/gt_pos`") && err.contains("/camera/gt_pose"), "{err}");
}

/// A headless rerun receiver (`rerun --port P --save FILE`).
struct Receiver {
    child: std::process::Child,
    url: String,
    file: PathBuf,
}

impl Receiver {
    fn start(rerun: &Path, dir: &Path) -> Self {
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let file = dir.join("received.rrd");
        let child = Command::new(rerun)
            .args(["--port", &port.to_string(), "--save"])
            .arg(&file)
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let started = Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(started.elapsed() < Duration::from_secs(60), "the rerun receiver did not start");
            std::thread::sleep(Duration::from_millis(100));
        }
        Self { child, url: format!("rerun+http://127.0.0.1:{port}/proxy"), file }
    }

    /// Signal the receiver: the `rerun` script and the viewer binary it started (its
    /// descendants, found in `/proc`), children first.
    fn signal(&mut self, sig: &str) {
        fn descendants(pid: u32, out: &mut Vec<u32>) {
            let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).into_iter().flatten().flatten();
            for task in tasks {
                let children = std::fs::read_to_string(task.path().join("children")).unwrap_or_default();
                for child in children.split_whitespace().filter_map(|c| c.parse().ok()) {
                    descendants(child, out);
                    out.push(child);
                }
            }
        }
        if self.child.try_wait().ok().flatten().is_some() {
            return;
        }
        let mut pids = Vec::new();
        descendants(self.child.id(), &mut pids);
        pids.push(self.child.id());
        for pid in pids.into_iter().filter(|p| *p > 1) {
            let _ = Command::new("kill").arg(format!("-{sig}")).arg(pid.to_string()).status();
        }
        let _ = self.child.wait();
    }

    /// Wait until the received file stops growing, then stop the receiver.
    fn finish(&mut self) {
        let mut last = (0, Instant::now());
        while last.1.elapsed() < Duration::from_secs(2) {
            let len = std::fs::metadata(&self.file).map_or(0, |m| m.len());
            if len != last.0 {
                last = (len, Instant::now());
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        self.signal("TERM");
    }
}

impl Drop for Receiver {
    fn drop(&mut self) {
        self.signal("KILL");
    }
}

/// Rows per entity of the recording in an `.rrd` (`rerun rrd print`), blueprint entities left
/// out (their ids are random per blueprint).
fn rows_per_entity(rerun: &Path, file: &Path) -> std::collections::BTreeMap<String, u64> {
    let out = rerun_rrd(rerun, &["print"], file);
    assert!(out.status.success(), "rerun rrd print {}: {}", file.display(), String::from_utf8_lossy(&out.stderr));
    let mut rows = std::collections::BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        // `Chunk(id) with N rows (SIZE) - /entity - data columns: [...]`
        let Some(rest) = line.strip_prefix("Chunk(") else { continue };
        let mut parts = rest.split(" - ");
        let head = parts.next().unwrap_or_default();
        let entity = parts.next().unwrap_or_default().to_owned();
        let n: u64 = head.split_whitespace().nth(2).and_then(|n| n.parse().ok()).unwrap();
        if ["/view/", "/container/", "/viewport"].iter().any(|p| entity.starts_with(p)) {
            continue;
        }
        *rows.entry(entity).or_insert(0) += n;
    }
    rows
}

fn live_summary(dir: &Path) -> BTreeMap<String, SinkReport> {
    common::summary(&dir.join("default.summary.json")).run.recorders
}

fn totals(ports: &BTreeMap<String, PortReport>) -> (u64, u64) {
    (ports.values().map(|p| p.messages).sum(), ports.values().map(|p| p.dropped).sum())
}

#[test]
fn live_stream_reaches_a_headless_receiver_with_what_the_file_has() {
    let Some(rerun) =
        peer("rerun", "recordings::live_stream_reaches_a_headless_receiver_with_what_the_file_has: rerun rrd")
    else {
        return;
    };
    let dir = common::TempDir::new("live");
    let mut receiver = Receiver::start(&rerun, dir.path());
    let out = common::bin()
        .args(["run", "--no-progress", "--frames", "20", "--record", "rrd", "--connect", &receiver.url, "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/default.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    receiver.finish();
    let recorders = live_summary(dir.path());
    let (sent, dropped) = totals(&recorders["live"].ports);
    assert_eq!(dropped, 0, "a local receiver keeps up with 20 frames");
    assert_eq!(sent, totals(&recorders["rerun"].ports).0, "the stream carried every recorded message");
    // The received stream has no footer (the receiver was stopped); it must still verify.
    let v = rerun_rrd(&rerun, &["verify", "--check-footers", "false"], &receiver.file);
    assert!(v.status.success(), "{}{}", String::from_utf8_lossy(&v.stdout), String::from_utf8_lossy(&v.stderr));
    let file = dir.path().join("default.rrd");
    assert!(rerun_rrd(&rerun, &["verify"], &file).status.success());
    // Same entity paths, same number of messages (rows) per entity as the file.
    let (live, recorded) = (rows_per_entity(&rerun, &receiver.file), rows_per_entity(&rerun, &file));
    assert_eq!(live, recorded);
    assert_eq!(recorded.get("/camera/rgb"), Some(&20), "{recorded:?}");
    assert!(recorded.keys().any(|k| k.starts_with("/world/track/pose")), "{recorded:?}");
}

#[test]
fn live_stream_survives_a_killed_receiver_and_counts_what_it_dropped() {
    let Some(rerun) =
        peer("rerun", "recordings::live_stream_survives_a_killed_receiver_and_counts_what_it_dropped: rerun rrd")
    else {
        return;
    };
    let dir = common::TempDir::new("livekill");
    let mut receiver = Receiver::start(&rerun, dir.path());
    let run = common::bin()
        .args(["run", "--no-progress", "--frames", "150", "--connect", &receiver.url, "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/default.yaml"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Kill the receiver once it has some of the stream, mid-run.
    let started = Instant::now();
    while std::fs::metadata(&receiver.file).map_or(0, |m| m.len()) < 2_000_000 {
        assert!(started.elapsed() < Duration::from_secs(120), "nothing reached the receiver");
        std::thread::sleep(Duration::from_millis(50));
    }
    receiver.signal("KILL");
    let out = run.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("went away"), "{stderr}");
    // The files are complete and valid.
    let rec = read_mcap(&dir.path().join("default.mcap")).unwrap();
    assert!(!rec.truncated);
    assert_eq!(rec.topics["/camera/rgb"].frames.len(), 150);
    peers_accept(&dir.path().join("default.rrd"), &dir.path().join("default.mcap"));
    // What the stream could not deliver is counted, per port.
    let recorders = live_summary(dir.path());
    let (sent, dropped) = totals(&recorders["live"].ports);
    assert!(sent > 0 && dropped > 0, "sent {sent}, dropped {dropped}");
    assert_eq!(sent + dropped, totals(&recorders["mcap"].ports).0, "every recorded message is sent or counted");
    assert!(recorders["live"].ports["camera/rgb"].dropped > 0);
}

#[test]
fn no_viewer_is_a_clear_message_and_the_run_completes() {
    let dir = common::TempDir::new("noview");
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let url = format!("rerun+http://127.0.0.1:{port}/proxy");
    let out = common::bin()
        .args(["run", "--no-progress", "--frames", "5", "--connect", &url, "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/engine_smoke.yaml"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains(&format!("no rerun viewer at {url}")) && stderr.contains("--spawn"), "{stderr}");
    assert!(dir.path().join("engine_smoke.rrd").exists() && dir.path().join("engine_smoke.mcap").exists());
    // `--spawn` without a viewer installed says how to install one, and runs on.
    let empty = common::TempDir::new("nopath");
    let out = common::bin()
        .env("PATH", empty.path())
        .args(["run", "--no-progress", "--frames", "5", "--record", "none", "--spawn", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/engine_smoke.yaml"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("pip install rerun-sdk==0.36.3"), "{stderr}");
}

/// Every `Points2D` position logged on `entity` in an `.rrd` file, by `frame`.
fn rrd_points(path: &Path, entity: &str) -> std::collections::BTreeMap<i64, Vec<[f32; 2]>> {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let positions = rerun::Points2D::descriptor_positions().component;
    let mut out = std::collections::BTreeMap::new();
    for msg in DecoderApp::decode_lazy(file) {
        let LogMsg::ArrowMsg(_, arrow) = msg.unwrap() else { continue };
        let chunk = Chunk::from_arrow_msg(&arrow).unwrap();
        if chunk.entity_path().to_string() != entity {
            continue;
        }
        let frames = chunk.iter_component_indices("frame".into(), positions).map(|(t, _)| t.as_i64());
        for (frame, points) in frames.zip(chunk.iter_component::<rerun::components::Position2D>(positions)) {
            out.insert(frame, points.iter().map(|p| [p.x(), p.y()]).collect());
        }
    }
    out
}

#[test]
fn every_label_in_the_rrd_is_drawn_at_its_own_track() {
    // The default graph records five point sets per frame (keypoints, tracks and
    // three label sets); a label was drawn at whichever set the recorder saw last. Now each
    // label carries its pixel: read the `.rrd` back and check every label's position against
    // the track it labels (the MCAP of the same run gives the tracks and the labels' indices).
    let dir = common::TempDir::new("rrd-labels");
    let out = common::bin()
        .args(["run", "--no-progress", "--frames", "5", "--record", "rrd,mcap", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/default.yaml"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rec = read_mcap(&dir.path().join("default.mcap")).unwrap();
    let tracks = &rec.topics["/flow/tracks"];
    let mut checked = 0;
    for node in ["semantic", "geometric", "combined"] {
        let drawn = rrd_points(&dir.path().join("default.rrd"), &format!("/{node}/labels"));
        let labels = &rec.topics[&format!("/{node}/labels")];
        assert!(!labels.frames.is_empty(), "{node}: no labels recorded");
        for (seq, frame) in &labels.frames {
            let cur = tracks.frames[seq]["data"]["cur"].as_array().unwrap();
            let want: Vec<[f32; 2]> = frame["data"]["index"]
                .as_array()
                .unwrap()
                .iter()
                .map(|i| {
                    let p = &cur[i.as_u64().unwrap() as usize];
                    [p[0].as_f64().unwrap() as f32, p[1].as_f64().unwrap() as f32]
                })
                .collect();
            let got = drawn.get(&(*seq as i64)).unwrap_or_else(|| panic!("{node}: frame {seq} not in the rrd"));
            assert_eq!(got, &want, "{node}: frame {seq}: labels not at their tracks");
            checked += want.len();
        }
    }
    assert!(checked > 100, "only {checked} labels checked");
}

#[test]
fn each_pose_stream_is_drawn_through_its_own_camera() {
    // The recorder gave every pose stream the intrinsics it saw last, whichever
    // camera they came from; each pose now takes its own node's camera (or what feeds the
    // node's camera input). Two generators of different sizes, read back from the `.rrd`.
    let dir = common::TempDir::new("rrd-cameras");
    let graph = dir.path().join("two.yaml");
    std::fs::write(
        &graph,
        "name: two\noracle: true\nnodes:\n  big: { op: synth, params: { frames: 2, width: 640, height: 480 } }\n  small: { op: synth, params: { frames: 2, width: 160, height: 120 } }\n",
    )
    .unwrap();
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "rrd", "--out"])
        .arg(dir.path())
        .arg(&graph)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    let resolution = rerun::Pinhole::descriptor_resolution().component;
    let mut seen = std::collections::BTreeMap::new();
    let file = std::io::BufReader::new(std::fs::File::open(dir.path().join("two.rrd")).unwrap());
    for msg in DecoderApp::decode_lazy(file) {
        let LogMsg::ArrowMsg(_, arrow) = msg.unwrap() else { continue };
        let chunk = Chunk::from_arrow_msg(&arrow).unwrap();
        for r in chunk.iter_component::<rerun::components::Resolution>(resolution) {
            if let Some(r) = r.first() {
                seen.insert(chunk.entity_path().to_string(), [r.0.x(), r.0.y()]);
            }
        }
    }
    assert_eq!(seen.get("/world/big/gt_pose"), Some(&[640.0, 480.0]), "{seen:?}");
    assert_eq!(seen.get("/world/small/gt_pose"), Some(&[160.0, 120.0]), "{seen:?}");
}

#[test]
fn a_stereo_rig_is_recorded_with_its_own_schema_and_replays_bit_exact() {
    let dir = common::TempDir::new("stereo_rig");
    let mcap = common::record_mcap(
        dir.path(),
        "rig",
        "name: rig\nnodes:\n  camera: { op: synth, params: { frames: 3, width: 64, height: 48, people: 0, stereo_baseline: 0.12 } }\n",
    );
    let recorded = read_mcap(&mcap).unwrap();
    let rig = &recorded.topics["/camera/stereo"];
    assert_eq!(rig.schema, "dynaflow.StereoRig", "{}", rig.schema);
    assert_eq!(rig.frames.len(), 3);
    let yaml = format!(
        "name: replay\nnodes:\n  src: {{ op: mcap_replay, params: {{ path: '{}', topics: 'stereo=/camera/stereo' }} }}\n",
        mcap.display()
    );
    let sink = run_in_memory(&yaml);
    let replayed = sink.port("src", "stereo");
    assert_eq!(replayed.len(), 3);
    for m in &replayed {
        let dynaflow_engine::msg::Body::StereoRig(r) = &m.body else { panic!("{m:?}") };
        assert_eq!(r.baseline, 0.12);
        let digest = &rig.frames[&m.header.seq]["digest"];
        assert_eq!(digest.as_str().unwrap(), format!("{:016x}", m.digest()), "frame {}", m.header.seq);
    }
}

/// Run a graph in this process into a memory sink; it must complete.
fn run_in_memory(yaml: &str) -> dynaflow_engine::sink::MemorySink {
    let sink = dynaflow_engine::sink::MemorySink::default();
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let report = rt
        .block_on(dynaflow_engine::runtime::run(&common::graph(yaml), Default::default(), vec![Box::new(sink.clone())]))
        .unwrap();
    assert_eq!(report.status, dynaflow_engine::runtime::RunStatus::Completed, "{:?}", report.failures);
    sink
}
