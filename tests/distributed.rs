//! Graphs across machines over zenoh, as a user runs them: `graphs/mg_slam.yaml`
//! with its segmenter and detector on a second machine, two `dynaflow run --machine`
//! processes on loopback. The split run's per-port digests equal the one-process run's, the
//! merged recordings verify with the peers, and the failure paths say what went wrong: a
//! machine that never starts, one killed mid-run, an endpoint in use, another graph.
//! Needs the `zenoh` feature (the README's test command builds it).
#![cfg(feature = "zenoh")]
#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use dynaflow::summary::PortDigest;

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

fn digests(summary: &Path) -> BTreeMap<String, PortDigest> {
    common::summary(summary).digests.unwrap()
}

/// The per-port digests of shipped graph `name` run whole in one process for `frames` frames.
fn one_process_digests(name: &str, frames: &str, out: &Path) -> BTreeMap<String, PortDigest> {
    let o = common::bin()
        .arg("run")
        .arg(common::repo().join(format!("graphs/{name}.yaml")))
        .args(["--frames", frames, "--no-progress", "--digest", "--record", "none", "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    digests(&out.join(format!("{name}.summary.json")))
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
    // `top` on both machines' folders while they run.
    let top = common::bin()
        .args(["top", "--json", "--follow", "--interval", "0.3", "--wait", "60"])
        .arg(dir.path().join("robot"))
        .arg(dir.path().join("server"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // `top` on the robot's folder alone: the server's view comes over zenoh.
    let t = Instant::now();
    let machines = loop {
        let o = common::bin().args(["top", "--json", "--wait", "60"]).arg(dir.path().join("robot")).output().unwrap();
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_default();
        let machines: Vec<String> = v["runs"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|r| r["machine"].as_str().map(str::to_owned))
            .collect();
        if machines.len() == 2 || !o.status.success() || t.elapsed() > Duration::from_secs(120) {
            break machines;
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(machines, ["robot", "server"], "`top` on the robot's folder during the run");
    let (robot, server) = (robot.wait_with_output().unwrap(), server.wait_with_output().unwrap());
    assert_eq!(robot.status.code(), Some(0), "robot: {}", text(&robot));
    assert_eq!(server.status.code(), Some(0), "server: {}", text(&server));
    let top = top.wait_with_output().unwrap();
    assert_eq!(top.status.code(), Some(0), "top: {}", text(&top));
    let looks: Vec<serde_json::Value> =
        String::from_utf8_lossy(&top.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    for m in ["robot", "server"] {
        let last = looks.iter().rev().find(|l| l["machine"] == m).unwrap_or_else(|| panic!("`top` never showed `{m}`"));
        assert_eq!(last["state"], "completed", "{m}");
        let summary = common::summary(&dir.path().join(format!("{m}/mg_slam.{m}.summary.json")));
        let shown: Vec<(&str, u64)> = last["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|n| (n["node"].as_str().unwrap(), n["frames"].as_u64().unwrap()))
            .collect();
        let want: Vec<(&str, u64)> = summary.run.nodes.iter().map(|n| (n.node.as_str(), n.frames)).collect();
        assert_eq!(shown, want, "`top` on `{m}`");
    }
    // The whole graph in one process, as written.
    let want = one_process_digests("mg_slam", "40", &dir.path().join("one"));
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
    let summary = common::summary(&dir.path().join("robot/mg_slam.robot.summary.json"));
    assert_eq!(summary.run.status, dynaflow_engine::runtime::RunStatus::Failed, "{summary:?}");
    let frames = summary.run.frames;
    assert!(frames > 0 && frames < 300, "stopped mid-run: {frames} frames");
    peers_accept(&dir.path().join("robot/mg_slam.robot.rrd"), &dir.path().join("robot/mg_slam.robot.mcap"));
}

/// `openssl` with arguments in `dir`; panics with its output if it fails.
fn openssl(dir: &Path, args: &[&str]) {
    let o = Command::new("openssl").args(args).current_dir(dir).stdin(Stdio::null()).output().unwrap();
    assert!(o.status.success(), "openssl {args:?}: {}", text(&o));
}

/// A certificate authority in `dir` (`ca.pem`, `ca.key`) and, signed by it, a certificate per
/// `(file stem, common name)` for 127.0.0.1 (`<stem>.pem`, `<stem>.key`): a `--tls` folder.
fn authority(dir: &Path, certs: &[(&str, &str)]) {
    std::fs::create_dir_all(dir).unwrap();
    let ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"];
    openssl(
        dir,
        &[
            &["req", "-x509"][..],
            &ec,
            &["-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=dynaflow test authority"],
        ]
        .concat(),
    );
    std::fs::write(
        dir.join("ext.cnf"),
        "subjectAltName=IP:127.0.0.1,DNS:localhost\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\n",
    )
    .unwrap();
    for (stem, cn) in certs {
        let (key, csr, pem, subj) =
            (format!("{stem}.key"), format!("{stem}.csr"), format!("{stem}.pem"), format!("/CN={cn}"));
        openssl(dir, &[&["req"][..], &ec, &["-keyout", &key, "-out", &csr, "-subj", &subj]].concat());
        openssl(
            dir,
            &[
                "x509",
                "-req",
                "-in",
                &csr,
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca.key",
                "-CAcreateserial",
                "-out",
                &pem,
                "-days",
                "2",
                "-extfile",
                "ext.cnf",
            ],
        );
    }
}

/// The engine smoke graph with `smooth` on machine `server`, over `scheme` (`tls` or `tcp`).
fn smoke_split(dir: &Path, scheme: &str, ports: (u16, u16)) -> PathBuf {
    let text = std::fs::read_to_string(common::repo().join("graphs/engine_smoke.yaml")).unwrap();
    let at = "  smooth:\n    op: testing.scalar_sum\n";
    assert!(text.contains(at), "graphs/engine_smoke.yaml changed");
    let text = text.replace(at, &format!("{at}    machine: server\n"))
        + &format!(
            "\nmachines:\n  robot: {{ endpoint: \"{scheme}/127.0.0.1:{}\" }}\n  server: {{ endpoint: \"{scheme}/127.0.0.1:{}\" }}\n",
            ports.0, ports.1
        );
    let path = dir.join(format!("smoke_{scheme}.yaml"));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_split_run_over_mutual_tls_matches_one_process_and_refuses_peers_without_the_graphs_certificates() {
    if Command::new("openssl").arg("version").output().is_err() {
        panic!("no `openssl` to make the test's certificates (scripts/peers.sh installs it)");
    }
    let dir = common::TempDir::new("split-tls");
    let good = dir.path().join("good");
    authority(&good, &[("robot", "robot"), ("server", "server"), ("intruder", "intruder")]);
    // Another authority's certificate for `robot`, and the right authority's for another name.
    let rogue = dir.path().join("rogue");
    authority(&rogue, &[("robot", "robot")]);
    let renamed = dir.path().join("renamed");
    std::fs::create_dir_all(&renamed).unwrap();
    std::fs::copy(good.join("ca.pem"), renamed.join("ca.pem")).unwrap();
    std::fs::copy(good.join("intruder.pem"), renamed.join("robot.pem")).unwrap();
    std::fs::copy(good.join("intruder.key"), renamed.join("robot.key")).unwrap();

    // The whole run over TLS: per-port digests equal the one-process run's.
    let graph = smoke_split(dir.path(), "tls", free_ports());
    let tls = |d: &Path| vec!["--tls".to_owned(), d.display().to_string(), "--frames".into(), "60".into()];
    let run = |name: &str, certs: &Path, timeout: &str| {
        let args = [tls(certs), vec!["--peer-timeout".into(), timeout.into(), "--require-tls".into()]].concat();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        machine(
            &graph,
            name,
            &dir.path().join(format!("{name}-{}", certs.file_name().unwrap().to_string_lossy())),
            &args,
        )
    };
    let server = run("server", &good, "20");
    let robot = run("robot", &good, "20");
    let (robot, server) = (robot.wait_with_output().unwrap(), server.wait_with_output().unwrap());
    assert_eq!(robot.status.code(), Some(0), "robot: {}", text(&robot));
    assert_eq!(server.status.code(), Some(0), "server: {}", text(&server));
    let want = one_process_digests("engine_smoke", "60", &dir.path().join("one"));
    let mut got = digests(&dir.path().join("robot-good/engine_smoke.robot.summary.json"));
    got.extend(digests(&dir.path().join("server-good/engine_smoke.server.summary.json")));
    assert_eq!(got, want, "the TLS run's digests differ from one process's");

    // A robot with another authority's certificate, or one issued to another name: the server
    // admits nothing from it and names the machine it waited for, with its endpoint.
    for certs in [&rogue, &renamed] {
        let graph_ports = std::fs::read_to_string(&graph).unwrap();
        let server = run("server", &good, "4");
        let robot = run("robot", certs, "4");
        let (robot, server) = (robot.wait_with_output().unwrap(), server.wait_with_output().unwrap());
        assert_eq!(server.status.code(), Some(2), "{}: server: {}", certs.display(), text(&server));
        assert_ne!(robot.status.code(), Some(0), "{}: robot: {}", certs.display(), text(&robot));
        let robot_endpoint =
            graph_ports.lines().find(|l| l.contains("robot: {")).unwrap().split('"').nth(1).unwrap().to_owned();
        assert!(
            text(&server).contains(&format!("machine `robot` ({robot_endpoint}) did not join")),
            "{}: server: {}",
            certs.display(),
            text(&server)
        );
    }

    // No certificates at all, and plain TCP where TLS is required: refused before connecting.
    let o = machine(&graph, "robot", &dir.path().join("bare"), &["--frames", "5"]).wait_with_output().unwrap();
    assert!(o.status.code() == Some(2) && text(&o).contains("--tls DIR"), "{}", text(&o));
    let tcp = smoke_split(dir.path(), "tcp", free_ports());
    let o = machine(&tcp, "robot", &dir.path().join("plain"), &["--require-tls", "--frames", "5"])
        .wait_with_output()
        .unwrap();
    assert!(o.status.code() == Some(2) && text(&o).contains("--require-tls"), "{}", text(&o));
}
