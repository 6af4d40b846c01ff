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

/// `dynaflow` with the peers' environment active, if it has numpy.
fn dynaflow_with_numpy(comparison: &str) -> Option<Command> {
    let venv = common::peers::venv();
    let probe = || {
        let ok = Command::new(venv.join("bin/python"))
            .args(["-c", "import numpy"])
            .output()
            .is_ok_and(|o| o.status.success());
        if ok { Ok(()) } else { Err(format!("{}/bin/python cannot import numpy", venv.display())) }
    };
    if !common::peers::peer_runs("numpy", comparison, probe) {
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
            "port.py",
            "    def process(self, frame):\n        return {'lables': None}\n",
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
