//! A graph split over machines, run as two "processes" joined by the in-process
//! loopback wire: the same messages on every port as the whole graph in one process, with
//! images, key-frame gating (watermarks), a `latest` join and a delayed feedback loop across
//! the boundary in both directions; and the errors of a bad placement.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::BTreeMap;

use dynaflow_engine::runtime::remote::{Placement, loopback::Hub};
use dynaflow_engine::runtime::{self, RunOptions, RunStatus};
use dynaflow_engine::sink::{MemorySink, Sink};

mod common;

const SPLIT: &str = r#"
name: split
machines:
  a: { endpoint: "tcp/127.0.0.1:17447" }
  b: { endpoint: "tcp/127.0.0.1:17448" }
nodes:
  camera: { op: testing.test_pattern, params: { frames: 60, width: 16, height: 8 } }
  gate: { op: gate, in: { input: camera.tick }, params: { every: 3 } }
  draw: { op: testing.random_scalar, machine: b, in: { trigger: gate.output } }
  work: { op: testing.simulate_work, machine: b, in: { input: camera.image }, params: { work_us: 100 } }
  sum:
    op: testing.scalar_sum
    in: { a: camera.tick, b: { from: draw.value, join: latest } }
  back:
    op: testing.scalar_sum
    machine: b
    in: { a: camera.tick, b: { from: sum.sum, delay: 1 } }
  seen: { op: passthrough, in: { input: work.output } }
"#;

/// `node.port` -> digests of its messages in order.
fn digests(sink: &MemorySink) -> BTreeMap<String, Vec<u64>> {
    let mut out: BTreeMap<String, Vec<u64>> = BTreeMap::new();
    for (n, p, m) in sink.messages.lock().unwrap().iter() {
        out.entry(format!("{n}.{p}")).or_default().push(m.digest());
    }
    out
}

fn rt() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap()
}

#[test]
fn a_graph_split_over_two_machines_gives_the_one_process_messages() {
    let graph = common::graph(SPLIT);
    assert_eq!(graph.nodes.iter().filter(|n| n.machine.as_deref() == Some("b")).count(), 3);
    let whole = MemorySink::default();
    let sinks: Vec<Box<dyn Sink>> = vec![Box::new(whole.clone())];
    let report = rt().block_on(runtime::run(&graph, RunOptions::default(), sinks)).unwrap();
    assert_eq!(report.status, RunStatus::Completed);
    let want = digests(&whole);
    assert_eq!(want["camera.tick"].len(), 60);
    assert_eq!(want["draw.value"].len(), 20, "one draw per key frame");

    let hub = Hub::new(2);
    let (sink_a, sink_b) = (MemorySink::default(), MemorySink::default());
    let run_on = |machine: &str, sink: &MemorySink| {
        let options = RunOptions {
            placement: Some(Placement { machine: machine.into(), wire: hub.wire() }),
            ..RunOptions::default()
        };
        let sinks: Vec<Box<dyn Sink>> = vec![Box::new(sink.clone())];
        runtime::run(&graph, options, sinks)
    };
    let (ra, rb) = rt().block_on(async { futures::join!(run_on("a", &sink_a), run_on("b", &sink_b)) });
    let (ra, rb) = (ra.unwrap(), rb.unwrap());
    assert_eq!(
        (ra.status, rb.status),
        (RunStatus::Completed, RunStatus::Completed),
        "{:?} {:?}",
        ra.failures,
        rb.failures
    );
    // Each machine ran its own nodes only.
    let names = |r: &runtime::RunReport| r.nodes.iter().map(|n| n.node.clone()).collect::<Vec<_>>();
    assert_eq!(names(&ra), ["camera", "gate", "sum", "seen"]);
    assert_eq!(names(&rb), ["draw", "work", "back"]);
    let (da, db) = (digests(&sink_a), digests(&sink_b));
    assert!(da.keys().all(|k| !db.contains_key(k)), "a port recorded on both machines");
    let mut got = da;
    got.extend(db);
    assert_eq!(got, want, "per-port messages of the split run differ from the one-process run");
    assert_eq!(ra.dropped + rb.dropped, 0);
}

#[test]
fn a_placement_on_an_unknown_machine_is_refused() {
    let graph = common::graph(SPLIT);
    let options = RunOptions {
        placement: Some(Placement { machine: "c".into(), wire: Hub::new(1).wire() }),
        ..RunOptions::default()
    };
    let err = rt().block_on(runtime::run(&graph, options, Vec::new())).unwrap_err().to_string();
    assert!(err.contains("no machine `c`") && err.contains("a, b"), "{err}");
}

#[test]
fn placement_errors_are_reported_where_they_are_written() {
    let bad = |text: &str| {
        let loaded = dynaflow_engine::load_str(
            "t.yaml",
            text,
            None,
            &dynaflow_engine::testing::registry(),
            &dynaflow_engine::LoadRequest::default(),
        );
        assert!(loaded.graph.is_none(), "accepted: {text}");
        loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect::<Vec<_>>().join("\n")
    };
    let undefined = bad(&SPLIT.replace("machine: b, in: { trigger", "machine: bb, in: { trigger"));
    assert!(undefined.contains("undefined machine `bb`") && undefined.contains("did you mean `b`"), "{undefined}");
    assert!(undefined.contains("t.yaml:9:"), "at the node's line: {undefined}");
    let no_map = bad("name: x\nnodes:\n  camera: { op: testing.test_pattern, machine: a }\n");
    assert!(no_map.contains("has no `machines:`"), "{no_map}");
    let same = bad(&SPLIT.replace("17448", "17447"));
    assert!(same.contains("both listen on `127.0.0.1:17447`"), "{same}");
    let udp = bad(&SPLIT.replace("tcp/127.0.0.1:17448", "udp/127.0.0.1:17448"));
    assert!(udp.contains("not a `tcp/` or `tls/` endpoint"), "{udp}");
    let port = bad(&SPLIT.replace(":17448", ":70000"));
    assert!(port.contains("port `70000`"), "{port}");
}
