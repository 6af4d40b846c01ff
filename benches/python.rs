//! What a Python operator costs per frame, beside the Rust `passthrough` on the same message:
//! a 640x480 RGB image in, the same image out. The operators are built from a graph (so the
//! Python class is declared and validated as in a run) and called directly, one frame after
//! another, on one thread; the best of 5 rounds of `FRAMES` calls.
//!
//! - `passthrough` (Rust): the image cloned into the output message (one copy).
//! - Python `return frame["image"]`: a read-only numpy view in (no copy), the array copied
//!   into the output message (one copy), plus the interpreter: the call, the frame, the dict.
//! - Python `np.array(frame["image"])`: what an input copy (a path without the view) adds.
//! - Python `return None`: the call alone (inputs converted, nothing returned).
//!
//! `cargo bench --features python --bench python` with numpy importable (`VIRTUAL_ENV`);
//! `-- FRAMES` changes the count (default 2000).

use std::sync::Arc;
use std::time::Instant;

use dynaflow_engine::msg::{Body, Header, Image, Message, PixelFormat};
use dynaflow_engine::op::{Context, Inputs, Instance, Operator};
use dynaflow_engine::{LoadRequest, load_str};
use rand_core::SeedableRng;

const CLASSES: &str = r#"
import numpy as np

class Same:
    inputs = {"image": "image"}
    outputs = {"image": "image"}
    def __init__(self, params, rng):
        pass
    def process(self, frame):
        return {"image": frame["image"]}

class Copied:
    inputs = {"image": "image"}
    outputs = {"image": "image"}
    def __init__(self, params, rng):
        pass
    def process(self, frame):
        return {"image": np.array(frame["image"])}

class Nothing:
    inputs = {"image": "image"}
    outputs = {"image": "image"}
    def __init__(self, params, rng):
        pass
    def process(self, frame):
        return None
"#;

fn operators(dir: &std::path::Path) -> Vec<(&'static str, Box<dyn Operator>)> {
    std::fs::write(dir.join("bench_ops.py"), CLASSES).expect("write the classes");
    let yaml = "name: bench\nnodes:\n  src: { op: testing.test_pattern, params: { frames: 1, width: 640, height: 480 } }\n  rust: { op: passthrough, in: { input: src.image } }\n  same: { op: python, in: { image: src.image }, params: { module: bench_ops.py, class: Same } }\n  copied: { op: python, in: { image: src.image }, params: { module: bench_ops.py, class: Copied } }\n  nothing: { op: python, in: { image: src.image }, params: { module: bench_ops.py, class: Nothing } }\n";
    let loaded = load_str("bench.yaml", yaml, Some(dir.to_path_buf()), &dynaflow::registry(), &LoadRequest::default());
    let rendered: Vec<String> = loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect();
    let graph = loaded.graph.unwrap_or_else(|| panic!("bench graph: {}", rendered.join("\n")));
    [
        ("rust passthrough", "rust"),
        ("python: return the view", "same"),
        ("python: copy the input", "copied"),
        ("python: return None", "nothing"),
    ]
    .into_iter()
    .map(|(label, id)| {
        let node = graph.nodes.iter().find(|n| &*n.id == id).expect("node");
        match (node.op.build)(&node.params).expect("build") {
            Instance::Transform(op) => (label, op),
            Instance::Source(_) => unreachable!("a transform"),
        }
    })
    .collect()
}

fn context() -> Context {
    Context {
        node: "bench".into(),
        seed: 1,
        rng: rand_chacha::ChaCha8Rng::seed_from_u64(1),
        out_dir: None,
        stem: "bench".into(),
        realtime: false,
        report: None,
    }
}

fn main() {
    let frames: u64 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(2000);
    let dir = std::env::temp_dir().join(format!("dynaflow-bench-python-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let data: Vec<u8> = (0..640 * 480 * 3).map(|i| (i * 7 % 251) as u8).collect();
    let image = Arc::new(Message::new(
        Header { seq: 0, stamp: 0.0, frame_id: "camera".into() },
        Body::Image(Image { width: 640, height: 480, format: PixelFormat::Rgb8, data }),
    ));
    println!("per-frame cost of an operator on a 640x480 RGB image, {frames} calls, best of 5, one thread");
    let mut baseline = None;
    for (label, mut op) in operators(&dir) {
        let mut ctx = context();
        op.start(&mut ctx).expect("start");
        let port: &'static str = if label.starts_with("rust") { "input" } else { "image" };
        let mut best = f64::INFINITY;
        for round in 0..6 {
            let t = Instant::now();
            for seq in 0..frames {
                let inputs = Inputs::new(seq, vec![(port, Some(Arc::clone(&image)))]);
                let out = op.process(&mut ctx, &inputs).expect("process");
                std::hint::black_box(out);
            }
            // Round 0 warms up (the interpreter, numpy's first calls).
            if round > 0 {
                best = best.min(t.elapsed().as_secs_f64() * 1e3 / frames as f64);
            }
        }
        op.stop(&mut ctx).expect("stop");
        let base = *baseline.get_or_insert(best);
        println!("  {label:<26} {best:7.4} ms/frame  ({:+.4} ms on the Rust pass-through)", best - base);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
