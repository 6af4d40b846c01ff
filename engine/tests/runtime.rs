//! Runtime semantics on real runs of the engine's own `testing.*` operators: queue policies,
//! failures, pacing, stopping. No operator crate is needed (the graphs use
//! `dynaflow_engine::testing`'s registry); the joins and feedback of a whole graph are tested
//! in the root crate's `tests/runtime.rs`.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::time::Instant;

use dynaflow_engine::runtime::{RunOptions, RunStatus};

mod common;

use common::runs::{run, run_with, scalar};

const SLOW: &str = r"
name: slow
nodes:
  camera: { op: testing.test_pattern, params: { frames: 200, width: 8, height: 8 } }
  slow:
    op: testing.simulate_work
    in: { input: { from: camera.tick, QUEUE } }
    params: { work_us: 1500 }
";

#[test]
fn slow_consumer_loses_nothing_with_block() {
    let g = common::graph(&SLOW.replace("QUEUE", "queue: block, capacity: 2"));
    let (report, sink) = run(&g);
    let out = sink.port("slow", "output");
    assert_eq!(out.len(), 200);
    assert!(out.iter().enumerate().all(|(k, m)| m.header.seq == k as u64 && scalar(m, "frame") == k as f64));
    assert_eq!(report.dropped, 0);
    let edge = &report.edges[0];
    assert_eq!(edge.stats.dropped, 0);
    assert_eq!(edge.stats.delivered, 200);
    assert!(edge.stats.max_depth <= 2, "{edge:?}");
}

#[test]
fn drop_oldest_counts_exactly_the_lost_messages() {
    let g = common::graph(&SLOW.replace("QUEUE", "queue: { drop_oldest: 2 }"));
    let (report, sink) = run(&g);
    let produced = sink.port("camera", "tick").len() as u64;
    let seen = sink.port("slow", "output");
    assert_eq!(produced, 200);
    let lost = produced - seen.len() as u64;
    assert!(lost > 0, "the consumer was not slow enough to drop anything");
    assert_eq!(report.dropped, lost, "counted drops differ from real ones");
    assert_eq!(report.nodes.iter().find(|n| n.node == "slow").unwrap().dropped, lost);
    // What survives is in order and without duplicates.
    assert!(seen.windows(2).all(|w| w[0].header.seq < w[1].header.seq));
}

#[test]
fn operator_error_and_panic_stop_the_run_and_close_sinks() {
    for mode in ["error", "panic"] {
        let text = format!(
            "name: f\nnodes:\n  camera: {{ op: testing.test_pattern, params: {{ frames: 100000 }} }}\n  bad: {{ op: testing.fault, in: {{ input: camera.tick }}, params: {{ at_frame: 20, mode: {mode} }} }}\n"
        );
        let (report, sink) = run(&common::graph(&text));
        assert_eq!(report.status, RunStatus::Failed, "{mode}");
        assert_eq!(report.failures.len(), 1);
        assert_eq!(report.failures[0].node, "bad");
        assert!(report.failures[0].error.contains("fault injected at frame 20"), "{:?}", report.failures);
        assert!(*sink.closed.lock().unwrap(), "sinks not closed after {mode}");
        assert_eq!(sink.port("bad", "output").len(), 20);
        assert!(report.frames < 100000, "source kept running after the failure");
    }
}

#[test]
fn realtime_paces_sources_at_sensor_rate() {
    let g = common::graph(
        "name: rt\nnodes:\n  camera: { op: testing.test_pattern, params: { frames: 11, rate_hz: 50 } }\n",
    );
    let t = Instant::now();
    let (report, _) = run_with(&g, RunOptions { realtime: true, ..RunOptions::default() });
    // 10 intervals of 20 ms; a slow machine can only make this longer.
    assert!(t.elapsed().as_secs_f64() >= 0.19, "{:?}", t.elapsed());
    assert_eq!(report.frames, 11);
}

#[test]
fn realtime_latest_join_never_waits_for_a_slow_detector() {
    // The detector takes 30 ms per key frame; tracking must not wait for it in realtime mode.
    let text = r"
name: lag
nodes:
  camera: { op: testing.test_pattern, params: { frames: 40, rate_hz: 100 } }
  detector:
    op: testing.simulate_work
    in: { input: { from: camera.tick, queue: latest } }
    params: { work_us: 30000 }
  fuse:
    op: testing.scalar_sum
    in:
      a: camera.tick
      b: { from: detector.output, join: latest }
";
    let g = common::graph(text);
    let (report, sink) = run_with(&g, RunOptions { realtime: true, ..RunOptions::default() });
    assert_eq!(report.status, RunStatus::Completed);
    let fuse = sink.port("fuse", "sum");
    // Tracking is fast, but in real time even it drops (and counts) a frame it was too late
    // for, e.g. on a loaded machine.
    let fuse_node = report.nodes.iter().find(|n| n.node == "fuse").unwrap();
    assert_eq!(fuse.len() as u64 + fuse_node.dropped, 40);
    // The detector could not keep up, so its input dropped frames (counted) and tracking saw
    // stale detector values rather than waiting.
    let det = report.nodes.iter().find(|n| n.node == "detector").unwrap();
    assert!(det.dropped > 0 && det.frames + det.dropped == 40, "{det:?}");
    assert!(fuse.iter().any(|m| scalar(m, "b_seq") < m.header.seq as f64));
}

#[test]
fn max_frames_and_stop_handle() {
    let g = common::graph("name: s\nnodes:\n  camera: { op: testing.test_pattern, params: { frames: 1000 } }\n");
    let (report, _) = run_with(&g, RunOptions { max_frames: Some(7), ..RunOptions::default() });
    assert_eq!(report.frames, 7);
    assert_eq!(report.status, RunStatus::Completed);
    let options = RunOptions::default();
    options.stop.request();
    let (report, sink) = run_with(&g, options);
    assert_eq!(report.status, RunStatus::Interrupted);
    assert!(*sink.closed.lock().unwrap());
}
