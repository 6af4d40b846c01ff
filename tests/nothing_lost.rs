//! Nothing lost, nobody let in: outputs that never destroy inputs or follow a planted symlink,
//! signals that reach every child, readers that refuse what they cannot read (the defects of
//! an adversarial pass, one test each; docs/validation.md states the rules).
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, Instant};

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn dynaflow(args: &[&str], paths: &[&Path]) -> Output {
    let mut c = common::bin();
    c.args(args);
    for p in paths {
        c.arg(p);
    }
    c.output().unwrap()
}

/// A short MCAP recording of the engine smoke graph (no SLAM: quick) in `dir`.
fn recording(dir: &Path) -> PathBuf {
    let o = dynaflow(
        &["run", "--no-progress", "--frames", "12", "--record", "mcap", "--out"],
        &[dir, &common::repo().join("graphs/engine_smoke.yaml")],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    dir.join("engine_smoke.mcap")
}

fn png(path: &Path, w: u32, h: u32) {
    let img = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 7) as u8, (y * 5) as u8, ((x + y) * 3) as u8]));
    img.save(path).unwrap();
}

#[test]
fn no_command_writes_over_one_of_its_inputs() {
    let dir = common::TempDir::new("inputs");
    let a = recording(dir.path());
    let b = dir.path().join("b.mcap");
    std::fs::copy(&a, &b).unwrap();
    let before = std::fs::read(&a).unwrap();
    // compare and diff write `.rrd`: never over an input, never to a `.mcap` name.
    for args in [vec!["compare"], vec!["diff"]] {
        let o = dynaflow(&[args.as_slice(), &[]].concat(), &[&a, &b, Path::new("--out"), &a]);
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        assert!(text(&o).contains("is the input") || text(&o).contains(".rrd"), "{}", text(&o));
        let o = dynaflow(&args, &[&a, &b, Path::new("--out"), &dir.path().join("new.mcap")]);
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        assert!(text(&o).contains("ending in `.rrd`"), "{}", text(&o));
        assert!(!dir.path().join("new.mcap").exists());
    }
    assert_eq!(std::fs::read(&a).unwrap(), before, "an input recording was changed");
    // merge: `--out` one of its inputs (by another spelling too).
    let (ra, rb) = (dir.path().join("run.a.rrd"), dir.path().join("run.b.rrd"));
    std::fs::write(&ra, b"precious a").unwrap();
    std::fs::write(&rb, b"precious b").unwrap();
    let dotted = dir.path().join(".").join("run.a.rrd");
    let o = dynaflow(&["merge"], &[&ra, &rb, Path::new("--out"), &dotted]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("is the input"), "{}", text(&o));
    assert_eq!(std::fs::read(&ra).unwrap(), b"precious a");
    // segment into the folder of its input; vocab train onto its training image.
    let photo = dir.path().join("frame.png");
    png(&photo, 64, 48);
    let photo_bytes = std::fs::read(&photo).unwrap();
    let o = dynaflow(&["segment", "--out"], &[dir.path(), &photo]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("is the input"), "{}", text(&o));
    let o = dynaflow(&["vocab", "train", "--out"], &[&photo, &photo]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert_eq!(std::fs::read(&photo).unwrap(), photo_bytes, "the input image was overwritten");
}

#[test]
fn two_images_of_one_name_are_refused_before_either_is_segmented() {
    let dir = common::TempDir::new("stems");
    for sub in ["a", "b"] {
        std::fs::create_dir_all(dir.path().join(sub)).unwrap();
        png(&dir.path().join(sub).join("x.png"), 32, 24);
    }
    let out = dir.path().join("masks");
    let o = dynaflow(&["segment", "--out"], &[&out, &dir.path().join("a/x.png"), &dir.path().join("b/x.png")]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("a/x.png") && text(&o).contains("b/x.png") && text(&o).contains("both write"),
        "{}",
        text(&o)
    );
    assert!(!out.join("x.png").exists());
}

#[cfg(unix)]
#[test]
fn outputs_never_follow_a_symlink_out_of_the_output_folder() {
    let dir = common::TempDir::new("symlink");
    let (out, outside) = (dir.path().join("out"), dir.path().join("outside.txt"));
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(&outside, "precious").unwrap();
    for name in ["engine_smoke.summary.json", "engine_smoke.messages.jsonl"] {
        std::os::unix::fs::symlink(&outside, out.join(name)).unwrap();
    }
    let o = dynaflow(
        &["run", "--no-progress", "--frames", "5", "--record", "jsonl", "--out"],
        &[&out, &common::repo().join("graphs/engine_smoke.yaml")],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(&outside).unwrap(), "precious");
    for name in ["engine_smoke.summary.json", "engine_smoke.messages.jsonl"] {
        let meta = std::fs::symlink_metadata(out.join(name)).unwrap();
        assert!(meta.is_file() && meta.len() > 0, "{name} is not a new file");
    }
    // segment's masks too.
    let photo = dir.path().join("p.png");
    png(&photo, 64, 48);
    std::os::unix::fs::symlink(&outside, out.join("p.png")).unwrap();
    let o = dynaflow(&["segment", "--out"], &[&out, &photo]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(&outside).unwrap(), "precious");
    assert!(!std::fs::symlink_metadata(out.join("p.png")).unwrap().file_type().is_symlink());
}

#[test]
fn every_recorder_reports_its_messages_and_file() {
    let dir = common::TempDir::new("report");
    let o = dynaflow(
        &["run", "--no-progress", "--frames", "13", "--digest", "--record", "jsonl", "--out"],
        &[dir.path(), &common::repo().join("graphs/engine_smoke.yaml")],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let summary = common::summary(&dir.path().join("engine_smoke.summary.json"));
    let log = std::fs::read_to_string(dir.path().join("engine_smoke.messages.jsonl")).unwrap();
    let jsonl = &summary.run.recorders["jsonl"];
    let recorded: u64 = jsonl.ports.values().map(|p| p.messages).sum();
    assert_eq!(recorded as usize, log.lines().count() - 2, "the log's messages");
    assert_eq!(jsonl.file_bytes, Some(log.len() as u64));
    assert!(jsonl.path.as_deref().is_some_and(|p| p.ends_with("engine_smoke.messages.jsonl")));
    let digest = &summary.run.recorders["digest"];
    let digests = summary.digests.unwrap();
    for (port, d) in &digests {
        assert_eq!(digest.ports[port].messages, d.count, "{port}");
    }
    assert!(digest.ports.values().map(|p| p.messages).sum::<u64>() > 0);
}

/// A KITTI odometry folder of three 16x12 frames, calibration and times as given.
fn kitti(dir: &Path, calib: &str, times: &str, frames: usize) -> PathBuf {
    let seq = dir.join("sequences/00");
    for cam in ["image_0", "image_1"] {
        std::fs::create_dir_all(seq.join(cam)).unwrap();
        for i in 0..frames {
            png(&seq.join(cam).join(format!("{i:06}.png")), 16, 12);
        }
    }
    std::fs::write(seq.join("calib.txt"), calib).unwrap();
    std::fs::write(seq.join("times.txt"), times).unwrap();
    seq
}

#[test]
fn kitti_refuses_inconsistent_calibration_times_poses_and_sizes_at_load() {
    use dynaflow_datasets::kitti::{KittiSequence, Pair, Poses};
    let p0 = "P0: 700 0 8 0 0 700 6 0 0 0 1 0\n";
    let p1 = "P1: 700 0 8 -350 0 700 6 0 0 0 1 0\n";
    let times = "0\n0.1\n0.2\n";
    let open = |calib: &str, times: &str, frames: usize| {
        let dir = common::TempDir::new("kitti49");
        let seq = kitti(dir.path(), calib, times, frames);
        (KittiSequence::open(&seq, Pair::Gray, Poses::None, 0).map(|s| s.len()).map_err(|e| e.to_string()), dir, seq)
    };
    assert_eq!(open(&format!("{p0}{p1}"), times, 3).0, Ok(3));
    let cases = [
        (format!("{p0}{p1}{p1}"), times, 3, "calib.txt:3", "defined twice"),
        (format!("{p0}P1: 690 0 8 -350 0 700 6 0 0 0 1 0\n"), times, 3, "calib.txt:2", "fx = 690"),
        (format!("{p0}P1: 700 0 8 350 0 700 6 0 0 0 1 0\n"), times, 3, "calib.txt:2", "baseline"),
        (format!("{p0}P1: 700 0 8 0 0 700 6 0 0 0 1 0\n"), times, 3, "calib.txt:2", "baseline of 0"),
        (format!("{p0}{p1}"), "0\n0.1\n", 3, "times.txt", "2 times for 3 images"),
    ];
    for (calib, times, frames, at, what) in cases {
        let (r, _dir, _) = open(&calib, times, frames);
        let e = r.expect_err(what);
        assert!(e.contains(at) && e.contains(what), "expected `{at}` and `{what}` in: {e}");
    }
    // More poses than frames.
    let (_, dir, seq) = open(&format!("{p0}{p1}"), times, 3);
    let poses = dir.path().join("poses.txt");
    std::fs::write(&poses, "1 0 0 0 0 1 0 0 0 0 1 0\n".repeat(4)).unwrap();
    let e = KittiSequence::open(&seq, Pair::Gray, Poses::File(&poses), 0).unwrap_err().to_string();
    assert!(e.contains("poses.txt") && e.contains("4 poses for 3 frames"), "{e}");
    // A frame of another size than the first: refused naming the file, not run with the
    // first frame's intrinsics.
    png(&seq.join("image_0/000002.png"), 20, 12);
    png(&seq.join("image_1/000002.png"), 20, 12);
    let s = KittiSequence::open(&seq, Pair::Gray, Poses::None, 0).unwrap();
    assert!(s.frame(1).is_ok());
    let e = s.frame(2).unwrap_err().to_string();
    assert!(e.contains("000002.png") && e.contains("20x12"), "{e}");
}

fn diagnostics(text: &str) -> Vec<String> {
    let loaded = dynaflow_engine::load_str(
        "test.yaml",
        text,
        None,
        &dynaflow::registry(),
        &dynaflow_engine::LoadRequest::default(),
    );
    loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect()
}

#[test]
fn machines_that_name_one_socket_twice_malformed_endpoints_and_idle_machines_are_refused() {
    let graph = |a: &str, b: &str| {
        format!(
            "name: m\nmachines:\n  robot: {{ endpoint: \"{a}\" }}\n  server: {{ endpoint: \"{b}\" }}\nnodes:\n  cam: {{ op: testing.test_pattern }}\n  sum: {{ op: testing.scalar_sum, machine: server, in: {{ a: cam.tick, b: cam.tick }} }}\n"
        )
    };
    assert!(diagnostics(&graph("tcp/127.0.0.1:7447", "tcp/127.0.0.1:7448")).is_empty());
    for (a, b) in [
        ("tcp/localhost:7447", "tcp/127.0.0.1:7447"),
        ("tcp/127.0.0.1:7447", "tcp/127.0.0.1:07447"),
        ("tcp/[::1]:7447", "tcp/[0:0:0:0:0:0:0:1]:7447"),
        ("tcp/Robot.local:7447", "tcp/robot.local:7447"),
    ] {
        let d = diagnostics(&graph(a, b));
        assert!(d.iter().any(|d| d.contains("test.yaml:4:") && d.contains("both listen on")), "{a} {b}: {d:?}");
    }
    for bad in ["tcp/[::1:7447", "tcp/a:b:7447", " tcp/127.0.0.1:7447", "tcp/ 127.0.0.1:7447", "tcp/127.0.0.1:+7447"] {
        let d = diagnostics(&graph(bad, "tcp/127.0.0.1:7448"));
        assert!(d.iter().any(|d| d.contains("test.yaml:3:") && d.contains("endpoint")), "{bad:?}: {d:?}");
    }
    let idle = "name: m\nmachines:\n  robot: { endpoint: \"tcp/127.0.0.1:7447\" }\n  spare: { endpoint: \"tcp/127.0.0.1:7448\" }\nnodes:\n  cam: { op: testing.test_pattern }\n";
    let d = diagnostics(idle);
    assert!(d.iter().any(|d| d.contains("test.yaml:4:") && d.contains("`spare` runs no node")), "{d:?}");
}

/// A two-message MCAP file as machine `machine` of graph `g` wrote it.
fn machine_mcap(path: &Path, machine: &str, graph_digest: &str, messages: u64) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut w = mcap::WriteOptions::new().compression(None).chunk_size(Some(256)).create(file).unwrap();
    let meta = [("graph", "g"), ("graph_digest", graph_digest), ("machine", machine)]
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect();
    w.write_metadata(&mcap::records::Metadata { name: "dynaflow".into(), metadata: meta }).unwrap();
    let ch = w.add_channel(0, &format!("/{machine}/value"), "json", &Default::default()).unwrap();
    for i in 0..messages {
        let header = mcap::records::MessageHeader { channel_id: ch, sequence: i as u32, log_time: i, publish_time: i };
        w.write_to_known_channel(&header, format!("{{\"i\":{i},\"pad\":\"{}\"}}", "x".repeat(64)).as_bytes()).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn merge_refuses_what_is_not_one_split_run_and_reads_a_cut_recording_up_to_its_cut() {
    let dir = common::TempDir::new("merge49");
    let (a, b) = (dir.path().join("run.a.mcap"), dir.path().join("run.b.mcap"));
    machine_mcap(&a, "a", "d1", 40);
    machine_mcap(&b, "b", "d1", 40);
    let out = dir.path().join("merged.mcap");
    let merge = |files: &[&Path], extra: &[&str]| {
        let mut c = common::bin();
        c.arg("merge").args(files).arg("--out").arg(&out).args(extra);
        c.output().unwrap()
    };
    // One file twice (two spellings), names that are no machine ids.
    let o = merge(&[&a, &dir.path().join(".").join("run.a.mcap")], &["--names", "x,y"]);
    assert!(o.status.code() == Some(2) && text(&o).contains("same file"), "{}", text(&o));
    for names in [",x", "a/b,c", "..,c"] {
        let o = merge(&[&a, &b], &["--names", names]);
        assert!(o.status.code() == Some(2) && text(&o).contains("not a machine id"), "{names}: {}", text(&o));
    }
    // A one-process recording.
    let single = dir.path().join("single.mcap");
    machine_mcap(&single, "", "d1", 5);
    let o = merge(&[&a, &single], &[]);
    assert!(o.status.code() == Some(2) && text(&o).contains("--machine"), "{}", text(&o));
    // Machine b's recording cut mid-file (its process killed): merged up to the cut, said.
    let full = std::fs::read(&b).unwrap();
    std::fs::write(&b, &full[..full.len() * 2 / 3]).unwrap();
    let o = merge(&[&a, &b], &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("run.b.mcap") && text(&o).contains("cut"), "{}", text(&o));
    let merged = std::fs::read(&out).unwrap();
    let n = mcap::MessageStream::new(&merged).unwrap().filter(Result::is_ok).count();
    assert!((41..80).contains(&n), "{n} messages: all of a's 40 and some of b's");
}

#[test]
fn a_map_path_is_checked_before_the_first_frame_and_an_empty_map_is_refused() {
    let dir = common::TempDir::new("maps49");
    let graph = common::repo().join("graphs/orb_baseline.yaml");
    for (path, why) in
        [(dir.path().join("no/such/folder/map.dfmap"), "does not exist"), (dir.path().to_path_buf(), "is a directory")]
    {
        let t0 = Instant::now();
        let o = dynaflow(
            &["run", "--no-progress", "--record", "none", "--frames", "300", "--out"],
            &[&dir.path().join("out"), &graph, Path::new("--save-map"), &path],
        );
        assert_eq!(o.status.code(), Some(2), "{}", text(&o));
        // Located at the tracker, naming the flag that gave the path.
        let flag = format!("`--save-map {}`", path.display());
        assert!(text(&o).contains(&flag) && text(&o).contains("save_map") && text(&o).contains(why), "{}", text(&o));
        assert!(!dir.path().join("out/orb_baseline.summary.json").exists(), "the run started");
        assert!(t0.elapsed() < Duration::from_secs(600));
    }
    // A graph with two trackers: the flags do not guess which one keeps the map.
    let o = dynaflow(
        &["run", "--no-progress", "--record", "none", "--frames", "2", "--out"],
        &[
            &dir.path().join("two"),
            &common::repo().join("graphs/default.yaml"),
            Path::new("--save-map"),
            &dir.path().join("m"),
        ],
    );
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("need one enabled tracker in the graph, it has 2 (baseline, track)"), "{}", text(&o));
    // A run that never relocalises in the loaded map says so (here no pose can have the
    // inliers it is asked for), not that "the tracker never initialised".
    let map = dir.path().join("room.dfmap");
    let o = dynaflow(
        &["run", "--no-progress", "--record", "none", "--frames", "30", "--out"],
        &[&dir.path().join("save"), &graph, Path::new("--save-map"), &map],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = dynaflow(
        &[
            "run",
            "--no-progress",
            "--record",
            "none",
            "--frames",
            "8",
            "--localise",
            "--set",
            "track.min_inliers=100000",
            "--out",
        ],
        &[&dir.path().join("load"), &graph, Path::new("--load-map"), &map],
    );
    assert!(
        text(&o).contains("never relocalised in the loaded map") && text(&o).contains("8 frames lost of 8"),
        "{}",
        text(&o)
    );
    assert!(!text(&o).contains("never initialised"), "{}", text(&o));
    // The map in a run of smaller images (another camera) is refused naming the file.
    let o = dynaflow(
        &[
            "run",
            "--no-progress",
            "--record",
            "none",
            "--frames",
            "3",
            "--set",
            "camera.width=320",
            "--set",
            "camera.height=240",
            "--out",
        ],
        &[&dir.path().join("small"), &graph, Path::new("--load-map"), &map],
    );
    assert!(
        o.status.code() == Some(1) && text(&o).contains("room.dfmap") && text(&o).contains("320x240"),
        "{}",
        text(&o)
    );
    // A vocabulary trained on one small image has a handful of words: said.
    let img = dir.path().join("small.png");
    image::GrayImage::from_fn(128, 128, |x, y| image::Luma([if (x / 12 + y / 12) % 2 == 0 { 30 } else { 220 }]))
        .save(&img)
        .unwrap();
    let o = dynaflow(&["vocab", "train", "--features", "50", "--out"], &[&dir.path().join("small.voc"), &img]);
    assert!(text(&o).contains("warning: only") && text(&o).contains("too few"), "{}", text(&o));
    // A map with no key frame (what a monocular run that never initialised had) is refused.
    let voc = std::sync::Arc::new(
        dynaflow_slam::bow::Vocabulary::from_bytes(dynaflow_operators::tracking::DEFAULT_VOCABULARY, "default")
            .unwrap(),
    );
    let cam = dynaflow_vision::camera::Pinhole { fx: 500.0, fy: 500.0, cx: 320.0, cy: 240.0 };
    let empty = dynaflow_slam::keyframe_map::KeyFrameMap::new(cam, 640.0, 480.0, 1.2, voc.clone());
    let file = dir.path().join("empty.dfmap");
    std::fs::write(&file, dynaflow_slam::map_file::encode(&empty)).unwrap();
    let e = dynaflow_slam::map_file::load(&file, cam, 640.0, 480.0, 1.2, voc).unwrap_err().to_string();
    assert!(e.contains("empty.dfmap") && e.contains("no key frame"), "{e}");
}

#[test]
fn bench_sequences_of_one_folder_name_get_their_own_rows_and_folders() {
    let dir = common::TempDir::new("bench-names");
    let calib = "P0: 700 0 8 0 0 700 6 0 0 0 1 0\nP1: 700 0 8 -350 0 700 6 0 0 0 1 0\n";
    let (a, b) = (dir.path().join("kitti_a"), dir.path().join("kitti_b"));
    let seqs = [kitti(&a, calib, "0\n0.1\n", 2), kitti(&b, calib, "0\n0.1\n", 2)];
    let o = dynaflow(
        &["bench", "--variants", "stereo", "--list", "--out"],
        &[
            &dir.path().join("bench"),
            &common::repo().join("graphs/orb_baseline.yaml"),
            Path::new("--inputs"),
            &seqs[0],
            &seqs[1],
        ],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let rows: Vec<Vec<String>> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("cell"))
        .map(|l| l.split('\t').map(str::to_owned).collect())
        .collect();
    assert_eq!(rows.len(), 2, "{rows:?}");
    assert_ne!(rows[0][3], rows[1][3], "sequence names: {rows:?}");
    assert_ne!(rows[0][4], rows[1][4], "run folders: {rows:?}");
    assert!(rows[0][3].contains("kitti_a") && rows[1][3].contains("kitti_b"), "{rows:?}");
}

#[cfg(unix)]
#[test]
fn an_interrupted_bench_stops_its_runs_and_writes_the_tables_of_what_finished() {
    let dir = common::TempDir::new("bench-int");
    // A run that would take minutes: a slow node on every frame.
    let graph = dir.path().join("slow.yaml");
    std::fs::write(
        &graph,
        "name: slow\nnodes:\n  cam: { op: testing.test_pattern, params: { frames: 100000, width: 32, height: 24 } }\n  slow: { op: testing.simulate_work, in: { input: cam.tick }, params: { work_us: 20000 } }\nvariants:\n  other:\n    slow: { params: { work_us: 30000 } }\n",
    )
    .unwrap();
    let out = dir.path().join("bench");
    let mut bench = common::bin()
        .arg("bench")
        .arg(&graph)
        .args(["--jobs", "2", "--no-progress", "--compare", "--out"])
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Both runs are recording (their signal handlers are installed before their sinks open).
    let mcaps = [out.join("runs/slow-base-synthetic/slow.mcap"), out.join("runs/slow-other-synthetic/slow-other.mcap")];
    let t0 = Instant::now();
    while !mcaps.iter().all(|m| m.exists()) {
        if t0.elapsed() > Duration::from_secs(120) {
            let _ = bench.kill();
            panic!("the runs did not start");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = std::process::Command::new("kill").args(["-s", "TERM", &bench.id().to_string()]).status();
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = bench.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(120) {
            let _ = bench.kill();
            panic!("the bench did not end after SIGTERM");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let o = bench.wait_with_output().unwrap();
    assert_eq!(status.code(), Some(130), "{}", text(&o));
    // Each run ended before the bench did: its summary says interrupted, its recording is
    // complete, and the table marks the rows.
    for (m, summary) in mcaps.iter().zip(["slow.summary.json", "slow-other.summary.json"]) {
        let s = common::summary(&m.with_file_name(summary));
        assert_eq!(s.run.status, dynaflow_engine::runtime::RunStatus::Interrupted);
        let bytes = std::fs::read(m).unwrap();
        assert!(bytes.ends_with(mcap::MAGIC), "{} was not closed", m.display());
    }
    let table = std::fs::read_to_string(out.join("bench.md")).unwrap();
    assert_eq!(table.lines().filter(|l| l.contains("**interrupted**")).count(), 2, "{table}");
}
