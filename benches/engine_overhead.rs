//! Engine overhead: µs per message hop through a chain of 10 pass-through nodes, side by side
//! with the same chain built from bare tokio tasks and `tokio::sync::mpsc` channels.
//!
//! `cargo bench --bench engine_overhead` (add `-- FRAMES` to change the frame count).

use std::sync::Arc;
use std::time::Instant;

use dynaflow_engine::msg::{Body, Header, Message, Scalars};
use dynaflow_engine::runtime::{self, RunOptions};
use dynaflow_engine::{LoadRequest, load_str};

const HOPS: usize = 10;

fn chain_yaml(frames: u64) -> String {
    let mut y = format!(
        "name: chain\nnodes:\n  src: {{ op: testing.test_pattern, params: {{ frames: {frames}, width: 1, height: 1 }} }}\n"
    );
    let mut prev = "src.tick".to_owned();
    for i in 0..HOPS {
        y.push_str(&format!("  p{i}: {{ op: passthrough, in: {{ input: {prev} }} }}\n"));
        prev = format!("p{i}.output");
    }
    y
}

fn engine(rt: &tokio::runtime::Runtime, frames: u64) -> f64 {
    let loaded = load_str("chain.yaml", &chain_yaml(frames), None, &dynaflow::registry(), &LoadRequest::default());
    let graph = loaded.graph.expect("chain graph is valid");
    let t = Instant::now();
    let report = rt.block_on(runtime::run(&graph, RunOptions::default(), Vec::new())).expect("run");
    let wall = t.elapsed().as_secs_f64();
    assert_eq!(report.frames, frames);
    wall
}

/// The peer: 10 tasks forwarding `Arc<Message>` over bounded mpsc channels (capacity 4, as
/// our default queue), fed by a task that builds the same scalar message per frame.
fn bare_tokio(rt: &tokio::runtime::Runtime, frames: u64) -> f64 {
    rt.block_on(async {
        let t = Instant::now();
        let (tx0, mut rx) = tokio::sync::mpsc::channel::<Arc<Message>>(4);
        let mut tasks = Vec::new();
        for _ in 0..HOPS {
            let (tx, next) = tokio::sync::mpsc::channel::<Arc<Message>>(4);
            let mut input = std::mem::replace(&mut rx, next);
            tasks.push(tokio::spawn(async move {
                while let Some(m) = input.recv().await {
                    let fwd = Arc::new(Message::new(m.header.clone(), m.body.clone()));
                    if tx.send(fwd).await.is_err() {
                        break;
                    }
                }
            }));
        }
        let sink = tokio::spawn(async move {
            let mut n = 0u64;
            while rx.recv().await.is_some() {
                n += 1;
            }
            n
        });
        for seq in 0..frames {
            let header = Header { seq, stamp: seq as f64 / 30.0, frame_id: "camera".into() };
            let body = Body::Scalars(Scalars {
                values: vec![("frame".into(), seq as f64), ("time".into(), seq as f64 / 30.0)],
            });
            tx0.send(Arc::new(Message::new(header, body))).await.expect("send");
        }
        drop(tx0);
        for task in tasks {
            task.await.expect("task");
        }
        assert_eq!(sink.await.expect("sink"), frames);
        t.elapsed().as_secs_f64()
    })
}

fn main() {
    let frames: u64 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(100_000);
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build().expect("runtime");
    let _ = engine(&rt, 1000); // warm-up
    let _ = bare_tokio(&rt, 1000);
    let mut e = Vec::new();
    let mut b = Vec::new();
    for _ in 0..3 {
        e.push(engine(&rt, frames));
        b.push(bare_tokio(&rt, frames));
    }
    let best = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    let per_hop = |wall: f64| wall * 1e6 / (frames as f64 * HOPS as f64);
    let (ew, bw) = (best(&e), best(&b));
    println!(
        "engine overhead, {HOPS}-node pass-through chain, {frames} frames, best of 3, {} worker threads",
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    println!("  dynaflow runtime : {:8.3} s  {:6.2} µs/hop  {:9.0} frames/s", ew, per_hop(ew), frames as f64 / ew);
    println!("  bare tokio mpsc  : {:8.3} s  {:6.2} µs/hop  {:9.0} frames/s", bw, per_hop(bw), frames as f64 / bw);
    println!("  ratio dynaflow / bare tokio: {:.2}x", ew / bw);
}
