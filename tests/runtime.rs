//! Runtime semantics on a whole graph (the engine-smoke graph: a detector beside the
//! engine's testing operators): determinism, joins, feedback, variants. Queue policies,
//! failures, pacing and stopping are tested in the engine crate (`engine/tests/runtime.rs`).
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::sync::Arc;

use dynaflow_engine::LoadRequest;
use dynaflow_engine::msg::Message;
use dynaflow_engine::runtime::RunStatus;
use dynaflow_engine::spec::ResolvedGraph;

#[path = "../engine/tests/common/runs.rs"]
mod runs;

use runs::{run, scalar};

fn default_graph(req: &LoadRequest) -> ResolvedGraph {
    common::graph_with(include_str!("../graphs/engine_smoke.yaml"), req)
}

#[test]
fn seeded_random_operator_is_identical_across_lockstep_runs() {
    let g = default_graph(&LoadRequest::default());
    let (r1, a) = run(&g);
    let (r2, b) = run(&g);
    assert_eq!(r1.status, RunStatus::Completed);
    assert_eq!(r2.status, RunStatus::Completed);
    let a = a.messages.lock().unwrap().clone();
    let b = b.messages.lock().unwrap().clone();
    // Interleaving across ports may differ; per-port sequences must not.
    let per_port = |v: &[(String, String, Arc<Message>)]| {
        let mut map: std::collections::BTreeMap<(String, String), Vec<Message>> = Default::default();
        for (n, p, m) in v {
            map.entry((n.clone(), p.clone())).or_default().push((**m).clone());
        }
        map
    };
    let (pa, pb) = (per_port(&a), per_port(&b));
    assert_eq!(pa.keys().collect::<Vec<_>>(), pb.keys().collect::<Vec<_>>());
    assert_eq!(pa, pb, "two lockstep runs with the same seed differ");
    let draws = &pa[&("detector".to_owned(), "value".to_owned())];
    assert_eq!(draws.len(), 60, "one draw per key frame");

    // Not vacuous: another seed gives other draws, and the draws are not constant.
    let (_, c) = run(&default_graph(&LoadRequest { seed: Some(8), ..LoadRequest::default() }));
    let other = c.port("detector", "value");
    assert_ne!(scalar(&other[0], "value"), scalar(&draws[0], "value"));
    assert!(draws.iter().any(|m| scalar(m, "value") != scalar(&draws[0], "value")));
}

#[test]
fn latest_join_takes_newest_at_or_before_the_frame_and_delay_feeds_back() {
    let g = default_graph(&LoadRequest::default());
    let (report, sink) = run(&g);
    let fuse = sink.port("fuse", "sum");
    let detector = sink.port("detector", "value");
    let smooth = sink.port("smooth", "sum");
    assert_eq!(fuse.len(), 300);
    for (k, m) in fuse.iter().enumerate() {
        // The detector runs on every 5th frame; `latest` holds its newest value.
        let key = (k / 5 * 5) as f64;
        assert_eq!(m.header.seq, k as u64);
        assert_eq!(scalar(m, "b_seq"), key, "frame {k}");
        let d = detector.iter().find(|d| d.header.seq as f64 == key).unwrap();
        assert_eq!(scalar(m, "sum"), k as f64 + scalar(d, "value"));
    }
    // smooth(k) = fuse(k) + smooth(k-1), smooth(0) = fuse(0): a delay-1 self loop.
    let mut acc = 0.0;
    for (k, m) in smooth.iter().enumerate() {
        acc += scalar(&fuse[k], "sum");
        assert_eq!(scalar(m, "sum"), acc, "frame {k}");
        assert_eq!(scalar(m, "b_present"), if k == 0 { 0.0 } else { 1.0 });
    }
    let detector_node = report.nodes.iter().find(|n| n.node == "detector").unwrap();
    assert_eq!((detector_node.frames, detector_node.skipped), (60, 240));
}

#[test]
fn disabled_node_in_a_variant() {
    let g = default_graph(&LoadRequest { variant: Some("no_detector".into()), ..LoadRequest::default() });
    let (report, sink) = run(&g);
    assert_eq!(report.status, RunStatus::Completed);
    assert!(sink.port("detector", "value").is_empty());
    let fuse = sink.port("fuse", "sum");
    assert_eq!(fuse.len(), 300);
    assert!(fuse.iter().all(|m| scalar(m, "b_present") == 0.0));
}
