//! Reproductions of defects, one test each: the defects an adversarial pass over the engine
//! found (a deadlock, lost delayed frames, YAML bombs, escaping names, …).
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::time::{Duration, Instant};

use dynaflow_engine::msg::{Body, Message};
use dynaflow_engine::runtime::{self, RunOptions, RunReport, RunStatus};
use dynaflow_engine::sink::{MemorySink, Sink};
use dynaflow_engine::spec::ResolvedGraph;
use dynaflow_engine::{LoadRequest, load_str};

/// Run on its own thread and runtime; fail the test (instead of hanging CI) if the run does
/// not end within `limit`.
fn run_within(graph: &ResolvedGraph, options: RunOptions, limit: Duration) -> (RunReport, MemorySink) {
    let sink = MemorySink::default();
    let (tx, rx) = std::sync::mpsc::channel();
    let (g, s) = (graph.clone(), sink.clone());
    std::thread::Builder::new()
        .name("run".into())
        .spawn(move || {
            let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
            let sinks: Vec<Box<dyn Sink>> = vec![Box::new(s)];
            let report = rt.block_on(runtime::run(&g, options, sinks)).unwrap();
            let _ = tx.send(report);
            // An operator cancelled after a stop may still sleep on the blocking pool.
            rt.shutdown_background();
        })
        .unwrap();
    let report = rx.recv_timeout(limit).unwrap_or_else(|_| panic!("the run did not end within {limit:?}: hang"));
    (report, sink)
}

fn run(graph: &ResolvedGraph) -> (RunReport, MemorySink) {
    run_within(graph, RunOptions::default(), Duration::from_secs(60))
}

fn scalar(m: &Message, key: &str) -> f64 {
    match &m.body {
        Body::Scalars(s) => s.get(key).unwrap(),
        other => panic!("not scalars: {other:?}"),
    }
}

fn edge<'a>(report: &'a RunReport, label: &str) -> &'a dynaflow_engine::runtime::EdgeStats {
    &report
        .edges
        .iter()
        .find(|e| e.edge == label)
        .unwrap_or_else(|| panic!("no edge {label}: {:?}", report.edges))
        .stats
}

fn diagnostics(text: &str) -> Vec<String> {
    let loaded = load_str("test.yaml", text, None, &dynaflow::registry(), &LoadRequest::default());
    loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect()
}

// --- 1. deadlock: a dropping queue into a feedback loop with a `latest` join ---------------

#[test]
fn dropping_queue_into_a_feedback_loop_with_a_latest_join_never_hangs() {
    let hang2 = r"
name: hang2
nodes:
  cam: { op: testing.test_pattern, params: { frames: 100 } }
  acc:
    op: testing.scalar_sum
    in:
      a: { from: cam.tick, queue: latest }
      b: { from: acc.sum, join: latest, delay: 1 }
";
    let two_nodes = r"
name: hang2b
nodes:
  cam: { op: testing.test_pattern, params: { frames: 100 } }
  a: { op: testing.scalar_sum, in: { a: cam.tick, b: { from: b.sum, delay: 1 } } }
  b: { op: testing.scalar_sum, in: { a: { from: cam.tick, queue: latest }, b: { from: a.sum, join: latest } } }
";
    for text in [hang2, two_nodes] {
        for _ in 0..5 {
            let (report, _) = run(&common::graph(text));
            assert_eq!(report.status, RunStatus::Completed);
        }
    }
}

#[test]
fn slow_node_inside_the_loop_drops_frames_and_the_loop_still_runs() {
    // `acc` waits for the slow node's frontier; meanwhile its camera input drops frames. The
    // frames it never runs must still reach the loop as watermarks, or both wait forever
    // (the old engine hung here every time).
    let text = r"
name: loop
nodes:
  cam: { op: testing.test_pattern, params: { frames: 100 } }
  acc:
    op: testing.scalar_sum
    in:
      a: { from: cam.tick, queue: latest }
      b: { from: slow.output, join: latest, delay: 1 }
  slow: { op: testing.simulate_work, in: { input: acc.sum }, params: { work_us: 2000 } }
";
    let (report, sink) = run(&common::graph(text));
    assert_eq!(report.status, RunStatus::Completed);
    let a = edge(&report, "cam.tick -> acc/a");
    let acc = sink.port("acc", "sum");
    assert_eq!(a.sent, 100);
    assert!(a.dropped > 0, "the loop was not slow enough to drop: {a:?}");
    // Every message is accounted for: run by `acc`, or dropped (and counted).
    assert_eq!(acc.len() as u64, a.delivered);
    assert_eq!(a.delivered + a.dropped, a.sent);
    // `b` holds the newest output of `slow` at or before the previous frame.
    let slow = sink.port("slow", "output");
    for m in &acc {
        let k = m.header.seq;
        let want = slow.iter().rev().find(|s| s.header.seq < k).map_or(-1.0, |s| s.header.seq as f64);
        assert_eq!(scalar(m, "b_seq"), want, "frame {k}");
    }
}

#[test]
fn first_stop_request_ends_a_run_whose_operator_is_stuck() {
    // An operator stuck in a 30 s call: after the grace period it is cancelled, the sinks
    // close and the run reports itself interrupted.
    let text = r"
name: stuck
nodes:
  cam: { op: testing.test_pattern, params: { frames: 1000, rate_hz: 1000 } }
  stuck: { op: testing.simulate_work, in: { input: cam.tick }, params: { work_us: 30000000 } }
";
    let options = RunOptions { stop_grace: Some(Duration::from_millis(300)), ..RunOptions::default() };
    let stop = options.stop.clone();
    std::thread::Builder::new()
        .name("stopper".into())
        .spawn(move || {
            std::thread::sleep(Duration::from_millis(300));
            stop.request();
        })
        .unwrap();
    let t = Instant::now();
    let (report, sink) = run_within(&common::graph(text), options, Duration::from_secs(20));
    assert!(t.elapsed() < Duration::from_secs(20));
    assert_eq!(report.status, RunStatus::Interrupted);
    assert!(*sink.closed.lock().unwrap(), "recordings not closed");
}

// --- 2. delay + dropping queue on one edge ------------------------------------------------

#[test]
fn delayed_edge_with_a_dropping_queue_keeps_every_delayed_frame() {
    let text = r"
name: d3
nodes:
  cam: { op: testing.test_pattern, params: { frames: 12 } }
  acc:
    op: testing.scalar_sum
    in:
      a: cam.tick
      b: { from: acc.sum, delay: 3, queue: latest }
";
    let (report, sink) = run(&common::graph(text));
    let acc = sink.port("acc", "sum");
    assert_eq!(acc.len(), 12);
    for (k, m) in acc.iter().enumerate() {
        assert_eq!(scalar(m, "b_present"), if k >= 3 { 1.0 } else { 0.0 }, "frame {k}");
        assert_eq!(scalar(m, "b_seq"), if k >= 3 { (k - 3) as f64 } else { -1.0 }, "frame {k}");
    }
    let b = edge(&report, "acc.sum -> acc/b");
    assert_eq!((b.dropped, b.discarded, b.max_depth), (0, 0, 0), "{b:?}");
    assert_eq!(report.dropped, 0);
    // The last three outputs are for frames 12..=14, which never run: not lost.
    assert_eq!(b.sent - b.delivered, 3);
}

// --- 3. and 5. YAML bombs -------------------------------------------------------------------

#[test]
fn alias_bomb_and_deep_nesting_are_located_errors() {
    let mut bomb = String::from("name: bomb\nx0: &a0 [lol]\n");
    for i in 1..10 {
        bomb.push_str(&format!("x{i}: &a{i} [{}]\n", vec![format!("*a{}", i - 1); 10].join(",")));
    }
    let d = diagnostics(&bomb);
    assert!(d.len() == 1 && d[0].contains("test.yaml:") && d[0].contains("alias bomb"), "{d:?}");

    let deep = format!(
        "name: deep\nnodes:\n  cam:\n    op: testing.test_pattern\n    params:\n      frames:\n        {}1\n",
        "- ".repeat(50_000)
    );
    let d = diagnostics(&deep);
    assert!(d.len() == 1 && d[0].contains("test.yaml:7:") && d[0].contains("nested deeper"), "{d:?}");
}

// --- 4. names that escape `--out` ------------------------------------------------------------

#[test]
fn graph_names_must_be_plain_file_names() {
    for bad in ["../escaped", "/tmp/abs", "\"\"", "a/b", ".hidden", "'a\\b'", "'sp ace'"] {
        let d = diagnostics(&format!("name: {bad}\nnodes:\n  cam: {{ op: testing.test_pattern }}\n"));
        assert!(d.iter().any(|m| m.contains("invalid graph name")), "`{bad}` accepted: {d:?}");
    }
    for good in ["default", "mg_slam-v2", "run.3", "_x"] {
        let d = diagnostics(&format!("name: {good}\nnodes:\n  cam: {{ op: testing.test_pattern }}\n"));
        assert!(d.is_empty(), "`{good}` rejected: {d:?}");
    }
}

// --- 6. drop counts, discards and depths count messages, not watermarks ---------------------

#[test]
fn drop_counts_are_lost_messages_not_watermarks() {
    let text = r"
name: gated
nodes:
  cam: { op: testing.test_pattern, params: { frames: 200 } }
  key: { op: gate, in: { input: cam.tick }, params: { every: 5 } }
  slow: { op: testing.simulate_work, in: { input: { from: key.output, queue: latest } }, params: { work_us: 3000 } }
";
    let (report, sink) = run(&common::graph(text));
    let sent = sink.port("key", "output").len() as u64;
    let received = sink.port("slow", "output").len() as u64;
    assert_eq!(sent, 40);
    let e = edge(&report, "key.output -> slow/input");
    assert_eq!(e.sent, sent);
    assert_eq!(e.dropped, sent - received, "{e:?}");
    assert_eq!(report.dropped, sent - received);
    assert_eq!(e.delivered, received);
}

#[test]
fn completed_runs_with_delays_discard_nothing_and_report_no_reserved_depth() {
    let text = graph_text("smooth", "{ from: smooth.sum, delay: 2 }");
    let (report, _) = run(&common::graph(&text));
    assert_eq!(report.status, RunStatus::Completed);
    for e in &report.edges {
        assert_eq!(e.stats.discarded, 0, "{e:?}");
    }
    assert_eq!(edge(&report, "smooth.sum -> smooth/b").max_depth, 0);
}

fn graph_text(name: &str, b: &str) -> String {
    format!(
        "name: {name}\nnodes:\n  cam: {{ op: testing.test_pattern, params: {{ frames: 50 }} }}\n  smooth: {{ op: testing.scalar_sum, in: {{ a: cam.tick, b: {b} }} }}\n"
    )
}

// --- 10. `--realtime`: a slow node never throttles the camera --------------------------------

#[test]
fn realtime_slow_node_drops_instead_of_throttling_the_camera() {
    // 50 frames at 100 Hz is 0.5 s of data; a 200 ms node behind a blocking queue would
    // stretch the run past 8 s. With no `queue:` written, real time drops (and counts).
    let text = r"
name: rt
nodes:
  cam: { op: testing.test_pattern, params: { frames: 50, rate_hz: 100 } }
  slow: { op: testing.simulate_work, in: { input: cam.tick }, params: { work_us: 200000 } }
";
    let t = Instant::now();
    let (report, sink) = run_within(
        &common::graph(text),
        RunOptions { realtime: true, ..RunOptions::default() },
        Duration::from_secs(60),
    );
    let wall = t.elapsed();
    assert_eq!(report.status, RunStatus::Completed);
    let e = edge(&report, "cam.tick -> slow/input");
    let ran = sink.port("slow", "output").len() as u64;
    assert!(e.dropped > 0, "{e:?}");
    assert_eq!(ran + e.dropped, 50, "{e:?}");
    // The source's stamps were met: the camera kept its rate. Only the slow node's last
    // in-flight frame (200 ms) may trail the half second of data.
    assert!(wall < Duration::from_secs(4), "the slow node throttled the camera: {wall:?}");

    // Offline (no --realtime) the same graph loses nothing.
    let text = text.replace("work_us: 200000", "work_us: 100");
    let (report, sink) = run(&common::graph(&text));
    assert_eq!(sink.port("slow", "output").len(), 50);
    assert_eq!(report.dropped, 0);
}

// --- 11. the smaller ones ---------------------------------------------------------------------

#[test]
fn seed_accepts_the_whole_u64_range_in_yaml_like_the_flag() {
    let g = common::graph("name: s\nseed: 18446744073709551615\nnodes:\n  cam: { op: testing.test_pattern }\n");
    assert_eq!(g.seed, u64::MAX);
    let d = diagnostics("name: s\nseed: 18446744073709551616\nnodes:\n  cam: { op: testing.test_pattern }\n");
    assert!(d.iter().any(|m| m.contains("`seed` must be an integer")), "{d:?}");
}

#[test]
fn variant_patching_an_unknown_node_still_reports_its_other_errors() {
    let text = r"
name: v
nodes:
  cam: { op: testing.test_pattern }
variants:
  bad:
    ghost: { disabled: true }
    cam: { params: { frames: -3 } }
";
    let req = LoadRequest { variant: Some("bad".into()), ..LoadRequest::default() };
    let loaded = load_str("test.yaml", text, None, &dynaflow::registry(), &req);
    let codes: Vec<&str> = loaded.diagnostics.iter().map(|d| d.code).collect();
    assert!(codes.contains(&"unknown-node") && codes.contains(&"param-range"), "{codes:?}");
}

#[test]
fn variants_compose_in_order_and_two_setting_one_thing_differently_is_a_located_error() {
    let text = r"name: v
nodes:
  cam: { op: testing.test_pattern, params: { frames: 5 } }
  p: { op: passthrough, in: { input: cam.tick } }
variants:
  short: { cam: { params: { frames: 3 } } }
  off: { p: { disabled: true } }
  long: { cam: { params: { frames: 9 } } }
  S+G: { p: { disabled: true } }
  same: { cam: { params: { frames: 3 } } }
";
    let load = |v: &str| {
        let req = LoadRequest { variant: Some(v.into()), ..LoadRequest::default() };
        load_str("test.yaml", text, None, &dynaflow::registry(), &req)
    };
    let frames = |v: &str| {
        let spec = load(v).spec.unwrap();
        let (out, diags) = dynaflow_engine::spec::apply_variant(&spec, v).unwrap();
        assert!(diags.is_empty(), "{v}: {diags:?}");
        let cam = out.nodes.iter().find(|n| n.id == "cam").unwrap();
        let f = cam.params.iter().find(|(k, _)| k.text == "frames").map(|(_, y)| format!("{:?}", y.kind)).unwrap();
        (f, out.nodes.iter().find(|n| n.id == "p").unwrap().disabled)
    };
    // Both apply, whatever the order; a name with `+` of its own is taken whole first.
    for v in ["short+off", "off+short", "S+G+short"] {
        let (f, disabled) = frames(v);
        assert!(f.contains("\"3\""), "{v}: {f}");
        assert!(disabled, "{v}");
        assert!(load(v).graph.is_some(), "{v}: {:?}", load(v).diagnostics);
    }
    // The same value twice is no conflict; the later of two values is an error at the later
    // variant's patch, naming both.
    assert!(load("short+same").graph.is_some());
    let bad = load("short+long");
    assert!(bad.graph.is_none());
    let msgs: Vec<String> = bad.diagnostics.iter().map(|d| bad.source.plain(d)).collect();
    let m = msgs.iter().find(|m| m.contains("variant-conflict") || m.contains("which variant `short` before it sets"));
    let m = m.unwrap_or_else(|| panic!("{msgs:?}"));
    assert!(m.contains("test.yaml:8:") && m.contains("param `frames`") && m.contains("variant `long`"), "{m}");
    // An unknown part is named.
    let unknown = load("short+nope");
    let msgs: Vec<String> = unknown.diagnostics.iter().map(|d| unknown.source.plain(d)).collect();
    assert!(msgs.iter().any(|m| m.contains("unknown variant `short+nope`")), "{msgs:?}");
}

#[test]
fn invalid_delay_is_one_error_not_also_a_cycle() {
    let d = diagnostics(&graph_text("bad_delay", "{ from: smooth.sum, delay: -1 }"));
    assert_eq!(d.len(), 1, "{d:?}");
    assert!(d[0].contains("`delay` must be an integer"), "{d:?}");
}

#[test]
fn variant_disabling_the_only_source_is_an_error() {
    let text = "name: v\nnodes:\n  cam: { op: testing.test_pattern }\nvariants:\n  off: { cam: { disabled: true } }\n";
    let req = LoadRequest { variant: Some("off".into()), ..LoadRequest::default() };
    let loaded = load_str("test.yaml", text, None, &dynaflow::registry(), &req);
    assert!(loaded.graph.is_none());
    let msgs: Vec<String> = loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect();
    assert!(msgs.iter().any(|m| m.contains("every source is disabled (with variant `off`)")), "{msgs:?}");
}

#[test]
fn validation_is_linear_in_a_reversed_chain() {
    // A pass-through chain written last-to-first: each node's type depends on the next line.
    // The old validator took 15.6 s for 20k nodes (quadratic); the ratio of two sizes tells
    // linear from quadratic without depending on the machine's speed.
    fn chain(n: usize) -> String {
        let mut s = String::from("name: chain\nnodes:\n");
        for i in (1..n).rev() {
            s.push_str(&format!("  p{i}: {{ op: passthrough, in: {{ input: p{}.output }} }}\n", i - 1));
        }
        s.push_str("  p0: { op: passthrough, in: { input: cam.tick } }\n  cam: { op: testing.test_pattern }\n");
        s
    }
    let once = |text: &str| {
        let t = Instant::now();
        let loaded = load_str("c.yaml", text, None, &dynaflow::registry(), &LoadRequest::default());
        assert!(loaded.graph.is_some());
        t.elapsed().as_secs_f64()
    };
    // The two sizes interleaved, the best of five each: a burst of load elsewhere on the
    // machine slows one try of each, not all tries of one size.
    let (text_small, text_large) = (chain(5_000), chain(20_000));
    let (mut small, mut large) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..5 {
        small = small.min(once(&text_small));
        large = large.min(once(&text_large));
    }
    // Linear: 4x; quadratic: 16x.
    assert!(large / small < 9.0, "5k nodes {small:.3} s, 20k nodes {large:.3} s");
}

// --- a realistic check that nothing above broke plain runs ------------------------------------

#[test]
fn lockstep_feedback_with_block_queues_is_unchanged() {
    let (report, sink) = run(&common::graph(&graph_text("acc", "{ from: smooth.sum, delay: 1 }")));
    assert_eq!(report.dropped, 0);
    let out = sink.port("smooth", "sum");
    let mut acc = 0.0;
    for (k, m) in out.iter().enumerate() {
        acc += k as f64;
        assert_eq!(scalar(m, "sum"), acc);
    }
}

// --- 9. a corrupt MCAP is bad input, never an abort ---------------------------------------------

#[test]
fn diff_reader_survives_every_flipped_bit() {
    let dir = common::TempDir::new("flip");
    let path = common::record_mcap(
        dir.path(),
        "small",
        "name: small\nnodes:\n  cam: { op: testing.test_pattern, params: { frames: 10, width: 4, height: 4 } }\n",
    );
    let good = std::fs::read(&path).unwrap();
    assert_eq!(dynaflow_recordings::diff::read_mcap_bytes(&path, &good).unwrap().topics.len(), 2);
    // Every bit of the file, one at a time: lengths, chunk headers, compressed data, CRCs.
    // Each read is Ok (the flip hit something unchecked, or looks like a cut-off file) or a
    // clean error naming the file; an abort (the old reader asked the allocator for 3.4e18
    // bytes) would end this test process.
    let mut errors = 0;
    for byte in 0..good.len() {
        for bit in 0..8 {
            let mut bad = good.clone();
            bad[byte] ^= 1 << bit;
            if let Err(e) = dynaflow_recordings::diff::read_mcap_bytes(&path, &bad) {
                assert!(e.to_string().contains("small.mcap"), "{e}");
                errors += 1;
            }
        }
    }
    assert!(errors > 0);
}

// Quiet wrong input ----------------------------------------------

#[test]
fn a_mask_of_another_size_than_the_image_is_an_error_naming_both() {
    // ORB's mask and the tracker's mask from a 320x240 source, the image and depth 640x480.
    for (consumer, wiring) in [
        ("orb", "orb: { op: orb_extract, in: { image: camera.rgb, mask: small.gt_mask } }"),
        (
            "track",
            "orb: { op: orb_extract, in: { image: camera.rgb } }\n  track: { op: track_rgbd, in: { keypoints: orb.keypoints, depth: camera.depth, camera_info: camera.camera_info, mask: small.gt_mask } }",
        ),
        (
            "map",
            "map: { op: octomap, in: { depth: camera.depth, camera_info: camera.camera_info, pose: camera.gt_pose, mask: small.gt_mask } }",
        ),
        (
            "map",
            "map: { op: octomap, in: { depth: camera.depth, camera_info: camera.camera_info, pose: camera.gt_pose, image: small.rgb } }",
        ),
    ] {
        let text = format!(
            "name: t\noracle: true\nnodes:\n  camera: {{ op: synth, params: {{ frames: 2 }} }}\n  small: {{ op: synth, params: {{ frames: 2, width: 320, height: 240 }} }}\n  {wiring}\n"
        );
        let g = common::graph(&text);
        let (report, _) = run(&g);
        assert_eq!(report.status, RunStatus::Failed, "{consumer}: {report:?}");
        let failure = report.failures.iter().map(|f| format!("{}: {}", f.node, f.error)).collect::<Vec<_>>().join("\n");
        assert!(failure.contains("320x240") && failure.contains("640x480"), "{consumer}: {failure}");
    }
}

#[test]
fn box_to_mask_gives_each_listed_class_its_own_id() {
    // Boxes from the ground-truth masks are all `person`; listed second, person is class 2.
    let g = common::graph(
        "name: t\noracle: true\nnodes:\n  camera: { op: synth, params: { frames: 3 } }\n  boxes: { op: oracle_boxes, in: { mask: camera.gt_mask } }\n  people: { op: box_to_mask, in: { detections: boxes.detections, depth: camera.depth }, params: { classes: \"chair, person\" } }\n",
    );
    let (report, sink) = run(&g);
    assert_eq!(report.status, RunStatus::Completed, "{report:?}");
    let masks = sink.port("people", "mask");
    assert_eq!(masks.len(), 3);
    for m in &masks {
        let Body::Mask(mask) = &m.body else { panic!("{m:?}") };
        let names: Vec<&str> = mask.class_names.iter().map(|n| &**n).collect();
        assert_eq!(names, ["static", "chair", "person"]);
        assert!(mask.classes.contains(&2), "no person pixel");
        assert!(mask.classes.iter().all(|&c| c == 0 || c == 2), "a pixel of a class no box had");
    }
}

#[test]
fn a_misspelt_class_name_is_a_located_error_with_a_suggestion() {
    // `persn` would switch semantic culling off without a word:
    // class lists are typed, so the graph is refused where it names the class, in either the
    // list or the older comma-separated form.
    for (node, wiring) in [
        (
            "people",
            "people: { op: box_to_mask, in: { detections: boxes.detections, depth: camera.depth }, params: { classes: [persn] } }",
        ),
        (
            "cull",
            "flow: { op: lk_flow, in: { image: camera.rgb } }\n  cull: { op: cull_mask, in: { tracks: flow.tracks, mask: camera.gt_mask }, params: { classes: persn } }",
        ),
        (
            "map",
            "map: { op: octomap, in: { depth: camera.depth, camera_info: camera.camera_info, pose: camera.gt_pose }, params: { dynamic_classes: 'person,persn' } }",
        ),
    ] {
        let text = format!(
            "name: t\noracle: true\nnodes:\n  camera: {{ op: synth, params: {{ frames: 2 }} }}\n  boxes: {{ op: oracle_boxes, in: {{ mask: camera.gt_mask }} }}\n  {wiring}\n"
        );
        let loaded = load_str("t.yaml", &text, None, &dynaflow::registry(), &LoadRequest::default());
        assert!(loaded.graph.is_none(), "{node}: a misspelt class validated");
        let d = loaded.diagnostics.iter().find(|d| d.message.contains("`persn`")).expect(node);
        assert_eq!(d.code, "param-value", "{node}: {d:?}");
        assert!(d.message.contains(&format!("node `{node}`")), "{node}: {d:?}");
        assert_eq!(d.hint.as_deref(), Some("did you mean `person`?"), "{node}: {d:?}");
        // The span is the misspelt item itself, inside the list.
        let span = d.span.expect("located");
        assert_eq!(&text[span.offset..span.offset + span.len], "persn", "{node}: {d:?}");
    }
}
