//! Python operators (`op: python`, the `python` feature): PSPNet-SLAM's flow rule written in
//! numpy (examples/python/cull_flow.py) labels the walking scene exactly as dynaflow's own
//! `cull_flow` does; a broken module, a class that declares badly, an exception at a frame and
//! a value of the wrong dtype or shape are each an error that says where, with the Python
//! traceback; a failed run's recording still reads back. The interpreter finds numpy in the
//! peers' virtual environment (`VIRTUAL_ENV`, as an activated environment sets it).
#![cfg(feature = "python")]
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::Path;
use std::process::Command;

/// Whether the environment `venv` imports `modules` (`numpy, cv2`): the probe of a peer.
fn imports(venv: &Path, modules: &str) -> Result<(), String> {
    let ok = Command::new(venv.join("bin/python"))
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok { Ok(()) } else { Err(format!("{}/bin/python cannot import {modules}", venv.display())) }
}

/// The environment `scripts/test.sh` installs the package into (`DYNAFLOW_PY_PACKAGE`), if
/// it imports `modules`.
fn package_env(comparison: &str, modules: &str) -> Option<std::path::PathBuf> {
    let venv = std::env::var_os("DYNAFLOW_PY_PACKAGE").map(std::path::PathBuf::from);
    let probe = || match &venv {
        Some(v) => imports(v, modules),
        None => Err("DYNAFLOW_PY_PACKAGE names no environment with the package (scripts/test.sh makes it)".to_owned()),
    };
    if common::peers::peer_runs("numpy", comparison, probe) { venv } else { None }
}

/// `dynaflow` with the peers' environment active, if it has numpy.
fn dynaflow_with_numpy(comparison: &str) -> Option<Command> {
    let venv = common::peers::venv();
    if !common::peers::peer_runs("numpy", comparison, || imports(&venv, "numpy")) {
        return None;
    }
    let mut cmd = common::bin();
    cmd.env("VIRTUAL_ENV", &venv);
    Some(cmd)
}

fn run(cmd: &mut Command, graph: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    cmd.args(["run", "--no-progress", "--out"]).arg(out).args(extra).arg(graph).output().unwrap()
}

#[test]
fn the_numpy_flow_rule_labels_the_scene_exactly_as_cull_flow() {
    let Some(mut py) = dynaflow_with_numpy("python: the numpy flow rule against cull_flow") else {
        return;
    };
    let dir = common::TempDir::new("python-cull-flow");
    let args = ["--frames", "60", "--digest", "--record", "none"];
    let o = run(&mut py, &common::repo().join("examples/python/cull_flow.yaml"), &dir.path().join("py"), &args);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let mut rust = common::bin();
    let mut with_variant = args.to_vec();
    with_variant.extend(["--variant", "flow_consistency"]);
    let o = run(&mut rust, &common::repo().join("graphs/culling.yaml"), &dir.path().join("rust"), &with_variant);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let py = common::summary(&dir.path().join("py/python_cull_flow.summary.json")).digests.unwrap();
    let rust = common::summary(&dir.path().join("rust/culling-flow_consistency.summary.json")).digests.unwrap();
    // The same tracks go in (same generator, same LK)...
    assert_eq!(py["flow/tracks"], rust["flow/tracks"]);
    // ... and the same labels and counts come out, on every frame (the reference does not
    // record the kept tracks, so they have no digest there).
    for port in ["labels", "counts"] {
        let (p, r) = (&py[&format!("rule/{port}")], &rust[&format!("cull/{port}")]);
        assert_eq!(p.count, 60, "{port}");
        assert_eq!(p, r, "{port}: Python {p:?}, cull_flow {r:?}");
    }
}

/// A graph with one Python node running `class` of `module` (written beside it) on the
/// synthetic scene's tracks.
fn graph(dir: &Path, module: &str, class: &str, code: &str) -> std::path::PathBuf {
    std::fs::write(dir.join(module), code).unwrap();
    let yaml = format!(
        "name: py\nnodes:\n  camera:\n    op: synth\n    params: {{ frames: 8, width: 160, height: 120 }}\n  flow:\n    op: lk_flow\n    in: {{ image: camera.rgb }}\n  node:\n    op: python\n    in: {{ tracks: flow.tracks }}\n    params: {{ module: {module}, class: {class} }}\n"
    );
    let path = dir.join(format!("{}.yaml", module.trim_end_matches(".py")));
    std::fs::write(&path, yaml).unwrap();
    path
}

const GOOD_HEAD: &str = "import numpy as np\n\nclass Rule:\n    inputs = {\"tracks\": \"tracks\"}\n    outputs = {\"labels\": \"point_labels\"}\n\n    def __init__(self, params, rng):\n        pass\n\n";

#[test]
fn python_failures_name_the_node_the_frame_and_the_line() {
    let Some(_) = dynaflow_with_numpy("python: located errors") else {
        return;
    };
    let dir = common::TempDir::new("python-errors");
    let d = dir.path();
    let validate = |graph: &Path| {
        let o = common::bin().env("VIRTUAL_ENV", common::peers::venv()).arg("validate").arg(graph).output().unwrap();
        (o.status.code(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    // A syntax error: the graph is invalid at the node, the error names the file and line.
    let g = graph(d, "syntax.py", "Rule", "class Rule:\n    def process(self, frame)\n        return None\n");
    let (code, err) = validate(&g);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("syntax.yaml:") && err.contains("node"), "{err}");
    assert!(err.contains("syntax.py\", line 2") && err.contains("SyntaxError"), "{err}");
    // An import error: the traceback names the missing module.
    let g = graph(d, "imports.py", "Rule", "import no_such_package_here\n");
    let (code, err) = validate(&g);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("No module named 'no_such_package_here'") && err.contains("imports.py\", line 1"), "{err}");
    // A class that is not there, and a port of an unknown type: named.
    let g = graph(d, "noclass.py", "Missing", GOOD_HEAD);
    let (code, err) = validate(&g);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("no class `Missing`") && err.contains("Rule"), "{err}");
    let bad_type = GOOD_HEAD.replace("\"point_labels\"", "\"pointlabels\"")
        + "    def process(self, frame):\n        return None\n";
    let g = graph(d, "badtype.py", "Rule", &bad_type);
    let (code, err) = validate(&g);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("port `labels`") && err.contains("unknown type `pointlabels`"), "{err}");

    // At run time: an exception at frame 3, a float64 score, a wrong shape, an undeclared port.
    let cases = [
        (
            "raises.py",
            "    def process(self, frame):\n        if frame.seq == 3:\n            raise ValueError('frame three')\n        return None\n",
            vec!["node `node`", "Rule.process raised at frame 3", "raises.py\", line 12", "ValueError: frame three"],
        ),
        (
            "dtype.py",
            "    def process(self, frame):\n        n = len(frame['tracks']['id'])\n        return {'labels': {'dynamic': np.zeros(n, bool), 'reason': np.zeros(n, np.uint8), 'score': np.zeros(n)}}\n",
            vec!["`labels`.score: expected a float32 numpy array, got a float64 array"],
        ),
        (
            "shape.py",
            "    def process(self, frame):\n        n = len(frame['tracks']['id'])\n        return {'labels': {'dynamic': np.zeros(n, bool), 'reason': np.zeros(n + 1, np.uint8), 'score': np.zeros(n, np.float32)}}\n",
            vec!["`labels`.reason: expected shape ("],
        ),
        (
            "missing.py",
            "    def process(self, frame):\n        return {}\n",
            vec!["Rule.process returned no `labels` at frame"],
        ),
        (
            "port.py",
            "    def process(self, frame):\n        return {'labels': None, 'lables': None}\n",
            vec!["returned port `lables`", "outputs: labels"],
        ),
    ];
    for (module, body, wanted) in cases {
        let g = graph(d, module, "Rule", &(GOOD_HEAD.to_owned() + body));
        let out = d.join(module.trim_end_matches(".py"));
        let o = run(common::bin().env("VIRTUAL_ENV", common::peers::venv()), &g, &out, &["--record", "mcap"]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{module}: {err}");
        for w in wanted {
            assert!(err.contains(w), "{module}: `{w}` not in:\n{err}");
        }
        // The run's recording is whole: the frames before the failure read back.
        let rec = dynaflow_recordings::diff::read_mcap(&out.join("py.mcap")).unwrap();
        assert!(!rec.topics["/camera/rgb"].frames.is_empty(), "{module}");
    }
}

#[test]
fn opencv_lk_in_python_agrees_with_lk_flow() {
    let comparison = "python: OpenCV's LK as an operator against lk_flow";
    let Some(mut py) = dynaflow_with_numpy(comparison) else {
        return;
    };
    if !common::peers::peer_runs("opencv", comparison, || imports(&common::peers::venv(), "cv2")) {
        return;
    }
    let dir = common::TempDir::new("python-opencv-lk");
    let graph = common::repo().join("examples/python/opencv_lk.yaml");
    let o = run(&mut py, &graph, dir.path(), &["--frames", "30", "--record", "mcap"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let rec = dynaflow_recordings::diff::read_mcap(&dir.path().join("python_opencv_lk.mcap")).unwrap();
    let points = |v: &serde_json::Value| -> std::collections::BTreeMap<u64, (f64, f64)> {
        let d = &v["data"];
        let ids = d["id"].as_array().unwrap().iter().map(|i| i.as_u64().unwrap());
        let cur = d["cur"].as_array().unwrap().iter().map(|c| (c[0].as_f64().unwrap(), c[1].as_f64().unwrap()));
        ids.zip(cur).collect()
    };
    let (ours, theirs) = (&rec.topics["/flow/tracks"].frames, &rec.topics["/opencv/tracks"].frames);
    let (mut tracked, mut found, mut dist) = (0usize, 0usize, Vec::new());
    for (seq, msg) in ours {
        let a = points(msg);
        tracked += a.len();
        let Some(b) = theirs.get(seq).map(points) else { continue };
        found += b.len();
        for (id, (x, y)) in b {
            let (ax, ay) = a[&id];
            dist.push((x - ax).hypot(y - ay));
        }
    }
    dist.sort_by(f64::total_cmp);
    let median = dist[dist.len() / 2];
    // The front-end tests' bounds against OpenCV (vision/tests/frontend.rs).
    assert!(tracked > 5000, "{tracked} tracks");
    assert!(found as f64 >= 0.95 * tracked as f64, "OpenCV found {found} of lk_flow's {tracked} tracks");
    assert!(median < 0.05, "median distance between lk_flow's and OpenCV's tracks: {median} px");
}

#[cfg(unix)]
#[test]
fn ctrl_c_stops_a_run_stuck_in_python_and_the_recording_is_whole() {
    let Some(mut py) = dynaflow_with_numpy("python: Ctrl-C with an operator stuck in Python") else {
        return;
    };
    let dir = common::TempDir::new("python-stuck");
    let d = dir.path();
    let marker = d.join("asleep");
    let body = format!(
        "    def process(self, frame):\n        if frame.seq == 2:\n            open({:?}, 'w').close()\n            import time\n            time.sleep(10 ** 6)\n        return None\n",
        marker.display().to_string()
    );
    let g = graph(d, "stuck.py", "Rule", &(GOOD_HEAD.to_owned() + &body));
    let child = py
        .args(["run", "--no-progress", "--record", "mcap", "--out"])
        .arg(d.join("out"))
        .arg(&g)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t = std::time::Instant::now();
    while !marker.exists() {
        assert!(t.elapsed() < std::time::Duration::from_secs(120), "the operator never reached frame 2");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let sent = std::time::Instant::now();
    assert!(Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap().success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    // The engine waits its grace period (10 s) for in-flight frames, then cancels the node:
    // the sleeping Python call is abandoned, the recorders close their files.
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(sent.elapsed() < std::time::Duration::from_secs(60), "{err}");
    assert!(err.contains("cancelling"), "{err}");
    let rec = dynaflow_recordings::diff::read_mcap(&d.join("out/py.mcap")).unwrap();
    assert!(!rec.truncated);
    assert!(rec.topics["/camera/rgb"].frames.len() >= 3);
}

#[test]
fn the_python_package_runs_a_graph_and_its_recording_gives_back_the_ate() {
    // `scripts/test.sh` installs the package (`pip install .`) into a fresh virtual
    // environment and names it in DYNAFLOW_PY_PACKAGE.
    let comparison = "python: the dynaflow package installed by pip";
    let Some(venv) = package_env(comparison, "dynaflow") else {
        return;
    };
    let dir = common::TempDir::new("python-package");
    let script = r#"
import json, sys
import dynaflow
graph, out = sys.argv[1], sys.argv[2]
s = dynaflow.run(graph, out=out, frames=60, record="mcap")
rec = dynaflow.Recording(s.path.with_name(s.path.name.replace(".summary.json", ".mcap")))
est, gt = rec.poses("/track/pose"), rec.poses("/camera/gt_pose")
report = dynaflow.eval(gt, est, align=s.ate["align"])
try:
    dynaflow.run(graph, out=out, set={"camera.nonsense": 1})
    bad = None
except dynaflow.RunError as e:
    bad = e.status
# A graph with a Python operator, run from Python: the operator runs in this interpreter.
py_op = dynaflow.run(sys.argv[3], out=out, frames=10)
print(json.dumps({"py_op_frames": py_op.frames, "py_op_status": py_op.status, "summary": s.ate["rmse"], "eval": report["ate"]["rmse"], "pairs": s.ate["pairs"],
                  "matched": report["matched"], "rows": len(est), "graph": rec.provenance.get("graph"),
                  "bad": bad, "version": dynaflow.version()}))
"#;
    let o = Command::new(venv.join("bin/python"))
        .args(["-c", script])
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .arg(dir.path())
        .arg(common::repo().join("examples/python/cull_flow.yaml"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let r: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    let (summary, eval) = (r["summary"].as_f64().unwrap(), r["eval"].as_f64().unwrap());
    // The trajectory read back from the recording, evaluated from Python, is the run's own ATE.
    assert_eq!(r["rows"], 60, "{r}");
    assert_eq!(r["matched"], r["pairs"], "{r}");
    assert!((summary - eval).abs() <= 1e-9 * summary.max(1e-3), "summary ATE {summary} vs dynaflow.eval {eval}");
    assert_eq!(r["bad"], 2, "an unknown parameter is bad input: {r}");
    assert_eq!(r["version"], env!("CARGO_PKG_VERSION"));
    assert_eq!((r["py_op_frames"].as_u64(), r["py_op_status"].as_str()), (Some(10), Some("completed")), "{r}");
}

#[test]
fn the_notebook_style_ablation_runs_from_python_and_plots_each_rows_ate() {
    let comparison = "python: the ablation script (dynaflow package, matplotlib)";
    let Some(venv) = package_env(comparison, "dynaflow, matplotlib") else {
        return;
    };
    let dir = common::TempDir::new("python-ablation");
    let o = Command::new(venv.join("bin/python"))
        .arg(common::repo().join("examples/python/ablation.py"))
        .args(["--frames", "40", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let r: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    let rows = r["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3, "{r}");
    // Each row's ATE is its run's (read back from the summary the run wrote), and a table line.
    for row in rows {
        let s = common::summary(std::path::Path::new(row["summary"].as_str().unwrap()));
        assert_eq!(row["ate_rmse"].as_f64(), s.ate.map(|a| a.rmse), "{row}");
        assert!(stdout.contains(row["label"].as_str().unwrap()), "{stdout}");
    }
    // The chart: a PNG of the size the script draws (6 x 3.2 in at 100 dpi).
    let plot = image::open(r["plot"].as_str().unwrap()).unwrap();
    assert_eq!((plot.width(), plot.height()), (600, 320));
}

#[test]
fn two_python_nodes_draw_from_their_own_seeded_generators_run_after_run() {
    let Some(_) = dynaflow_with_numpy("python: seeded generators") else {
        return;
    };
    let dir = common::TempDir::new("python-seeded");
    let d = dir.path();
    std::fs::write(
        d.join("draw.py"),
        "class Draw:\n    inputs = {\"tracks\": \"tracks\"}\n    outputs = {\"draw\": \"scalars\"}\n\n    def __init__(self, params, rng):\n        self.rng = rng\n\n    def process(self, frame):\n        return {\"draw\": {\"numpy\": float(self.rng.random()), \"seed\": float(frame.seed % 2**52)}}\n",
    )
    .unwrap();
    let yaml = "name: draw\nnodes:\n  camera:\n    op: synth\n    params: { frames: 6, width: 160, height: 120 }\n  flow:\n    op: lk_flow\n    in: { image: camera.rgb }\n  a:\n    op: python\n    in: { tracks: flow.tracks }\n    params: { module: draw.py, class: Draw }\n  b:\n    op: python\n    in: { tracks: flow.tracks }\n    params: { module: draw.py, class: Draw }\n";
    std::fs::write(d.join("draw.yaml"), yaml).unwrap();
    let digests = |seed: &str, out: &str| {
        let mut cmd = common::bin();
        cmd.env("VIRTUAL_ENV", common::peers::venv());
        let o = run(&mut cmd, &d.join("draw.yaml"), &d.join(out), &["--digest", "--record", "none", "--seed", seed]);
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        let s = common::summary(&d.join(out).join("draw.summary.json")).digests.unwrap();
        (s["a/draw"].digest.clone(), s["b/draw"].digest.clone())
    };
    let (first, again, other) = (digests("1", "r1"), digests("1", "r2"), digests("2", "r3"));
    assert_eq!(first, again, "the same seed draws the same numbers");
    assert_ne!(first.0, first.1, "two nodes draw from generators of their own");
    assert_ne!(first.0, other.0, "another graph seed draws others");
}
