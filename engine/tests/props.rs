//! Random graphs against the documented runtime rules: gates, fan-out, both join kinds,
//! delays 1-3, feedback cycles, disabled nodes and all three queue policies. Every graph must
//! end (no hang), every message must be accounted for (run or counted as dropped), and where
//! all queues block, the outputs must equal a reference model of the rules (docs/graph-spec.md,
//! "Frames, watermarks, drops and delays").
#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::BTreeMap;
use std::time::Duration;

use dynaflow_engine::msg::Body;
use dynaflow_engine::runtime::{self, RunOptions, RunReport, RunStatus};
use dynaflow_engine::sink::{MemorySink, Sink};

mod common;

#[derive(Clone, Debug)]
enum Queue {
    Block(usize),
    Latest,
    DropOldest(usize),
}

impl Queue {
    fn yaml(&self) -> String {
        match self {
            Queue::Block(c) => format!("queue: block, capacity: {c}"),
            Queue::Latest => "queue: latest".into(),
            Queue::DropOldest(n) => format!("queue: {{ drop_oldest: {n} }}"),
        }
    }
    fn blocks(&self) -> bool {
        matches!(self, Queue::Block(_))
    }
}

#[derive(Clone, Debug)]
struct Wire {
    /// Producer node index (0 = the camera).
    from: usize,
    latest: bool,
    delay: u32,
    queue: Queue,
}

#[derive(Clone, Debug)]
enum Kind {
    Gate {
        every: u64,
        offset: u64,
    },
    Pass,
    /// `testing.simulate_work`: a pass-through that takes time, so dropping queues do drop.
    Work,
    Sum {
        b: Option<Wire>,
    },
}

#[derive(Clone, Debug)]
struct Node {
    kind: Kind,
    /// The driving input: lockstep, no delay, from an earlier node.
    input: Wire,
    disabled: bool,
}

#[derive(Clone, Debug)]
struct Graph {
    frames: u64,
    nodes: Vec<Node>,
}

fn queue(rng: &mut common::Rng) -> Queue {
    match rng.below(5) {
        0..=2 => Queue::Block(rng.range(1, 4) as usize),
        3 => Queue::Latest,
        _ => Queue::DropOldest(rng.range(1, 3) as usize),
    }
}

/// Node `i` (1-based; 0 is the camera) of `n` transforms.
fn node(rng: &mut common::Rng, i: usize, n: usize) -> Node {
    let input = Wire { from: rng.below(i as u64) as usize, latest: false, delay: 0, queue: queue(rng) };
    let kind = match rng.below(4) {
        0 => {
            let every = rng.range(1, 4);
            Kind::Gate { every, offset: rng.below(4) }
        }
        1 => Kind::Pass,
        2 => Kind::Work,
        _ => {
            // `b` of a sum: from anywhere; an edge to this node or a later one closes a cycle
            // and needs a delay.
            let b = rng.chance(0.8).then(|| {
                let from = rng.below(n as u64 + 1) as usize;
                let latest = rng.chance(0.5);
                let delay = rng.range(0, 3) as u32;
                let delay = if from >= i { delay.max(1) } else { delay };
                Wire { from, latest, delay, queue: queue(rng) }
            });
            Kind::Sum { b }
        }
    };
    Node { kind, input, disabled: rng.chance(0.15) }
}

fn graph(case: u64) -> Graph {
    let mut rng = common::Rng::new(case);
    let n = rng.range(1, 7) as usize;
    let frames = rng.range(1, 30);
    Graph { frames, nodes: (1..=n).map(|i| node(&mut rng, i, n)).collect() }
}

fn name(i: usize) -> String {
    if i == 0 { "cam".into() } else { format!("n{i}") }
}

fn port(g: &Graph, i: usize) -> &'static str {
    match i.checked_sub(1).and_then(|j| g.nodes.get(j)).map(|n| &n.kind) {
        None => "tick",
        Some(Kind::Sum { .. }) => "sum",
        Some(_) => "output",
    }
}

fn wire_yaml(g: &Graph, w: &Wire) -> String {
    let join = if w.latest { "latest" } else { "lockstep" };
    format!("{{ from: {}.{}, join: {join}, delay: {}, {} }}", name(w.from), port(g, w.from), w.delay, w.queue.yaml())
}

fn yaml(g: &Graph) -> String {
    let mut s = format!(
        "name: prop\nnodes:\n  cam: {{ op: testing.test_pattern, params: {{ frames: {}, width: 4, height: 4 }} }}\n",
        g.frames
    );
    for (j, n) in g.nodes.iter().enumerate() {
        let i = j + 1;
        let input = wire_yaml(g, &n.input);
        let body = match &n.kind {
            Kind::Gate { every, offset } => {
                format!("op: gate, in: {{ input: {input} }}, params: {{ every: {every}, offset: {offset} }}")
            }
            Kind::Pass => format!("op: passthrough, in: {{ input: {input} }}"),
            Kind::Work => format!("op: testing.simulate_work, in: {{ input: {input} }}, params: {{ work_us: 300 }}"),
            Kind::Sum { b: None } => format!("op: testing.scalar_sum, in: {{ a: {input} }}"),
            Kind::Sum { b: Some(b) } => format!("op: testing.scalar_sum, in: {{ a: {input}, b: {} }}", wire_yaml(g, b)),
        };
        s.push_str(&format!("  {}: {{ {body}, disabled: {} }}\n", name(i), n.disabled));
    }
    s
}

fn all_block(g: &Graph) -> bool {
    g.nodes.iter().all(|n| {
        n.input.queue.blocks()
            && match &n.kind {
                Kind::Sum { b: Some(b) } => b.queue.blocks(),
                _ => true,
            }
    })
}

/// The documented rules, frame by frame: `out[i][k]` is node i's message of frame k (its
/// first scalar and, for sums, the frame of `b`), or `None` (a watermark).
fn model(g: &Graph) -> Vec<Vec<Option<(f64, f64)>>> {
    let frames = g.frames as usize;
    let mut out: Vec<Vec<Option<(f64, f64)>>> = vec![vec![None; frames]; g.nodes.len() + 1];
    for k in 0..frames {
        out[0][k] = Some((k as f64, -1.0));
        // Undelayed inputs come from earlier nodes, so index order is a topological order.
        for (j, n) in g.nodes.iter().enumerate() {
            let i = j + 1;
            if n.disabled {
                continue;
            }
            let a = out[n.input.from][k].map(|(v, _)| v);
            out[i][k] = match &n.kind {
                Kind::Gate { every, offset } => {
                    if k as u64 % every == offset % every {
                        out[n.input.from][k]
                    } else {
                        None
                    }
                }
                Kind::Pass | Kind::Work => out[n.input.from][k],
                Kind::Sum { b } => a.map(|a| {
                    let b = b.as_ref().and_then(|w| {
                        let at = k.checked_sub(w.delay as usize)?;
                        if w.latest {
                            (0..=at).rev().find_map(|f| out[w.from][f].map(|(v, _)| (v, f as f64)))
                        } else {
                            out[w.from][at].map(|(v, _)| (v, at as f64))
                        }
                    });
                    (a + b.map_or(0.0, |b| b.0), b.map_or(-1.0, |b| b.1))
                }),
            };
        }
    }
    out
}

fn run(text: &str) -> (RunReport, MemorySink) {
    let graph = common::graph(text);
    let sink = MemorySink::default();
    let (tx, rx) = std::sync::mpsc::channel();
    let s = sink.clone();
    std::thread::Builder::new()
        .name("prop-run".into())
        .spawn(move || {
            let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
            let sinks: Vec<Box<dyn Sink>> = vec![Box::new(s)];
            let _ = tx.send(rt.block_on(runtime::run(&graph, RunOptions::default(), sinks)).unwrap());
            rt.shutdown_background();
        })
        .unwrap();
    let report = rx.recv_timeout(Duration::from_secs(30)).unwrap_or_else(|_| panic!("hang:\n{text}"));
    (report, sink)
}

fn recorded(sink: &MemorySink, node: &str, port: &str) -> BTreeMap<u64, (f64, f64)> {
    sink.port(node, port)
        .iter()
        .map(|m| {
            let Body::Scalars(s) = &m.body else { panic!("not scalars") };
            let first = s.values.first().map(|(_, v)| *v).unwrap();
            (m.header.seq, (first, s.get("b_seq").unwrap_or(-1.0)))
        })
        .collect()
}

/// Graphs drawn per run; each case is reproducible from its number.
const CASES: u64 = 96;

#[test]
fn random_graphs_end_account_for_every_message_and_follow_the_rules() {
    let mut with_drops = 0;
    let mut exact = 0;
    for case in 0..CASES {
        let g = graph(case);
        let text = format!("# case {case}\n{}", yaml(&g));
        let (report, sink) = run(&text);
        assert_eq!(report.status, RunStatus::Completed, "{}", text);

        // Accounting, edge by edge: what the producer sent (seen by the recorder) was handed
        // over, dropped (counted), or is the tail of a delay (frames after the last one).
        let by_label: BTreeMap<String, usize> =
            (0..=g.nodes.len()).map(|i| (format!("{}.{}", name(i), port(&g, i)), i)).collect();
        for e in &report.edges {
            let producer = e.edge.split(" -> ").next().unwrap();
            let i = by_label[producer];
            let (node, p) = producer.split_once('.').unwrap();
            let sent = sink.port(node, p).len() as u64;
            let s = e.stats;
            assert_eq!(s.sent, sent, "{}: {:?}\n{}", e.edge, s, text);
            assert_eq!(s.discarded, 0, "{}: {:?}\n{}", e.edge, s, text);
            let accounted = s.delivered + s.dropped;
            assert!(accounted <= sent, "{}: {:?}\n{}", e.edge, s, text);
            let wire = g.nodes.iter().flat_map(|n| {
                let b = match &n.kind {
                    Kind::Sum { b: Some(b) } => Some(b),
                    _ => None,
                };
                std::iter::once(&n.input).chain(b)
            });
            let max_tail = wire.filter(|w| w.from == i).map(|w| u64::from(w.delay)).max().unwrap_or(0);
            assert!(sent - accounted <= max_tail, "{}: {:?}\n{}", e.edge, s, text);
        }
        // A pass-through runs exactly the messages its input delivered.
        for (j, n) in g.nodes.iter().enumerate() {
            if matches!(n.kind, Kind::Pass | Kind::Work) && !n.disabled {
                let label = format!("{}.{} -> {}/input", name(n.input.from), port(&g, n.input.from), name(j + 1));
                let e = report.edges.iter().find(|e| e.edge == label).unwrap();
                assert_eq!(sink.port(&name(j + 1), "output").len() as u64, e.stats.delivered, "{}", text);
            }
        }

        with_drops += u64::from(report.dropped > 0);
        if all_block(&g) {
            exact += 1;
            assert_eq!(report.dropped, 0);
            let want = model(&g);
            for (i, frames) in want.iter().enumerate() {
                let expected: BTreeMap<u64, (f64, f64)> =
                    frames.iter().enumerate().filter_map(|(k, v)| v.map(|v| (k as u64, v))).collect();
                let got = recorded(&sink, &name(i), port(&g, i));
                assert_eq!(&got, &expected, "node {}\n{}", name(i), text);
            }
        }
    }
    // Not vacuous: both kinds of graph were drawn, and dropping queues did drop.
    assert!(exact >= 10 && with_drops >= 5, "{exact} exact, {with_drops} with drops");
}
