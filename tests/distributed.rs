//! Graphs across machines over zenoh (issue 36), as a user runs them: `graphs/mg_slam.yaml`
//! with its segmenter and detector on a second machine, two `dynaflow run --machine`
//! processes on loopback. The split run's per-port digests equal the one-process run's, the
//! merged recordings verify with the peers, and the failure paths say what went wrong: a
//! machine that never starts, one killed mid-run, an endpoint in use, another graph.
//! Needs the `zenoh` feature (the README's test command builds it).
#![cfg(feature = "zenoh")]
#![allow(clippy::unwrap_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;

/// Two free loopback ports (bound and released: another process could take one meanwhile,
/// which the tests would report as an endpoint in use).
fn free_ports() -> (u16, u16) {
    let a = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let b = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    (a.local_addr().unwrap().port(), b.local_addr().unwrap().port())
}

/// `graphs/mg_slam.yaml` with the segmenter and the detector on `server`, written to `dir`.
fn split_graph(dir: &Path, ports: (u16, u16)) -> PathBuf {
    let mut text = std::fs::read_to_string(common::repo().join("graphs/mg_slam.yaml")).unwrap();
    for (node, op) in [("segmenter", "segment"), ("detector", "detect")] {
        let at = format!("  {node}:\n    op: {op}\n");
        assert!(text.contains(&at), "graphs/mg_slam.yaml changed: no `{node}` as expected");
        text = text.replace(&at, &format!("{at}    machine: server\n"));
    }
    text += &format!(
        "\nmachines:\n  robot: {{ endpoint: \"tcp/127.0.0.1:{}\" }}\n  server: {{ endpoint: \"tcp/127.0.0.1:{}\" }}\n",
        ports.0, ports.1
    );
    let path = dir.join("mg_slam_split.yaml");
    std::fs::write(&path, text).unwrap();
    path
}

fn machine(graph: &Path, name: &str, out: &Path, extra: &[&str]) -> Child {
    common::bin()
        .arg("run")
        .arg(graph)
        .args(["--machine", name, "--no-progress", "--digest", "--out"])
        .arg(out)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

fn digests(summary: &Path) -> serde_json::Map<String, serde_json::Value> {
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(summary).unwrap()).unwrap();
    v["digests"].as_object().unwrap().clone()
}

fn peer(tool: &str, comparison: &str) -> Option<PathBuf> {
    let exe = common::peers::venv().join("bin").join(tool);
    let probe: &[&str] = if tool == "python" { &["-c", "import mcap, google.protobuf"] } else { &["--version"] };
    let name = if tool == "python" { "mcap" } else { tool };
    let works = Command::new(&exe).args(probe).stdin(Stdio::null()).output().is_ok_and(|o| o.status.success());
    common::peers::peer_runs(name, comparison, || if works { Ok(()) } else { Err(format!("no {}", exe.display())) })
        .then_some(exe)
}

/// `rerun rrd verify` and the Python MCAP reader accept the files.
fn peers_accept(rrd: &Path, mcap: &Path) {
    if let Some(rerun) = peer("rerun", "distributed: rerun rrd verify of a merged recording") {
        let out = Command::new("timeout")
            .arg("300")
            .arg(rerun)
            .args(["rrd", "verify"])
            .arg(rrd)
            .stdin(Stdio::null())
            .output()
            .unwrap();
        assert!(out.status.success(), "rerun rrd verify {}: {}", rrd.display(), text(&out));
    }
    if let Some(python) = peer("python", "distributed: mcap reader of a merged recording") {
        let out =
            Command::new(python).arg(common::repo().join("tests/peers/check_mcap.py")).arg(mcap).output().unwrap();
        assert!(out.status.success(), "mcap reader {}: {}", mcap.display(), text(&out));
    }
}

#[test]
fn mg_slam_split_over_two_processes_matches_one_process_and_merges() {
    let dir = common::TempDir::new("split-mg");
    let graph = split_graph(dir.path(), free_ports());
    let frames = ["--frames", "40"];
    let server = machine(&graph, "server", &dir.path().join("server"), &frames);
    let robot = machine(&graph, "robot", &dir.path().join("robot"), &frames);
    let (robot, server) = (robot.wait_with_output().unwrap(), server.wait_with_output().unwrap());
    assert_eq!(robot.status.code(), Some(0), "robot: {}", text(&robot));
    assert_eq!(server.status.code(), Some(0), "server: {}", text(&server));
    // The whole graph in one process, as written.
    let one = dir.path().join("one");
    let out = common::bin()
        .arg("run")
        .arg(common::repo().join("graphs/mg_slam.yaml"))
        .args(["--frames", "40", "--no-progress", "--digest", "--record", "none", "--out"])
        .arg(&one)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let want = digests(&one.join("mg_slam.summary.json"));
    let r = digests(&dir.path().join("robot/mg_slam.robot.summary.json"));
    let s = digests(&dir.path().join("server/mg_slam.server.summary.json"));
    assert!(s.contains_key("segmenter/mask") && !r.contains_key("segmenter/mask"), "{s:?}");
    assert!(r.keys().all(|k| !s.contains_key(k)), "a port recorded on both machines");
    let mut got = r;
    got.extend(s);
    assert_eq!(got, want, "per-port digests of the split run differ from the one-process run");
    // One recording of the whole run from the two machines' files.
    for ext in ["rrd", "mcap"] {
        let out = common::bin()
            .arg("merge")
            .arg(dir.path().join(format!("robot/mg_slam.robot.{ext}")))
            .arg(dir.path().join(format!("server/mg_slam.server.{ext}")))
            .arg("--out")
            .arg(dir.path().join(format!("merged.{ext}")))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(0), "{}", text(&out));
        assert!(text(&out).contains("machines robot, server"));
    }
    peers_accept(&dir.path().join("merged.rrd"), &dir.path().join("merged.mcap"));
    // Which machine recorded what: the merged MCAP's channels say so.
    let buf = std::fs::read(dir.path().join("merged.mcap")).unwrap();
    let summary = mcap::Summary::read(&buf).unwrap().unwrap();
    let machine_of = |topic: &str| {
        summary.channels.values().find(|c| c.topic == topic).map(|c| c.metadata["machine"].clone()).unwrap()
    };
    assert_eq!((machine_of("/segmenter/mask").as_str(), machine_of("/track/pose").as_str()), ("server", "robot"));
    // Merging a machine's file with itself, or another run's, is refused.
    let again = common::bin()
        .arg("merge")
        .arg(dir.path().join("robot/mg_slam.robot.mcap"))
        .arg(dir.path().join("robot/mg_slam.robot.mcap"))
        .arg("--out")
        .arg(dir.path().join("bad.mcap"))
        .output()
        .unwrap();
    assert_eq!(again.status.code(), Some(2));
    assert!(text(&again).contains("are the same file"), "{}", text(&again));
}

#[test]
fn a_machine_that_never_starts_is_named_within_the_timeout() {
    let dir = common::TempDir::new("split-absent");
    let ports = free_ports();
    let graph = split_graph(dir.path(), ports);
    let t0 = Instant::now();
    let robot = machine(&graph, "robot", &dir.path().join("robot"), &["--peer-timeout", "3", "--frames", "5"])
        .wait_with_output()
        .unwrap();
    assert_eq!(robot.status.code(), Some(2), "{}", text(&robot));
    let err = text(&robot);
    assert!(err.contains(&format!("machine `server` (tcp/127.0.0.1:{}) did not join within 3 s", ports.1)), "{err}");
    assert!(t0.elapsed() < Duration::from_secs(60), "gave up after {:?}", t0.elapsed());
}

#[test]
fn machines_started_from_different_graphs_are_refused() {
    let dir = common::TempDir::new("split-mismatch");
    let graph = split_graph(dir.path(), free_ports());
    let args = ["--peer-timeout", "10", "--frames", "5"];
    let server = machine(&graph, "server", &dir.path().join("server"), &[&args[..], &["--seed", "5"]].concat());
    let robot = machine(&graph, "robot", &dir.path().join("robot"), &args);
    let (robot, server) = (robot.wait_with_output().unwrap(), server.wait_with_output().unwrap());
    for (o, other) in [(&robot, "server"), (&server, "robot")] {
        assert_eq!(o.status.code(), Some(2), "{}", text(o));
        assert!(
            text(o).contains(&format!("machine `{other}`")) && text(o).contains("runs a different graph"),
            "{}",
            text(o)
        );
    }
}

#[test]
fn an_endpoint_already_in_use_is_named() {
    let dir = common::TempDir::new("split-inuse");
    let busy = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = busy.local_addr().unwrap().port();
    let graph = split_graph(dir.path(), (port, free_ports().1));
    let robot = machine(&graph, "robot", &dir.path().join("robot"), &["--peer-timeout", "3", "--frames", "5"])
        .wait_with_output()
        .unwrap();
    assert_eq!(robot.status.code(), Some(2), "{}", text(&robot));
    assert!(
        text(&robot).contains(&format!("cannot open its zenoh session on `tcp/127.0.0.1:{port}`")),
        "{}",
        text(&robot)
    );
    drop(busy);
}

#[test]
fn a_machine_killed_mid_run_ends_the_other_with_an_error_and_valid_recordings() {
    let dir = common::TempDir::new("split-killed");
    let graph = split_graph(dir.path(), free_ports());
    let mut server = machine(&graph, "server", &dir.path().join("server"), &[]);
    let robot = machine(&graph, "robot", &dir.path().join("robot"), &[]);
    // Kill the segmenter's machine once the robot is well into its 300 frames.
    std::thread::sleep(Duration::from_secs(4));
    server.kill().unwrap();
    let _ = server.wait();
    let robot = robot.wait_with_output().unwrap();
    let log = text(&robot);
    assert_eq!(robot.status.code(), Some(1), "{log}");
    assert!(log.contains("machine `server`") && log.contains("is gone"), "{log}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("robot/mg_slam.robot.summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["status"], "failed", "{summary}");
    let frames = summary["frames"].as_u64().unwrap();
    assert!(frames > 0 && frames < 300, "stopped mid-run: {frames} frames");
    peers_accept(&dir.path().join("robot/mg_slam.robot.rrd"), &dir.path().join("robot/mg_slam.robot.mcap"));
}
