//! Recording cost: the default graph (synthetic scene 640×480, MG-SLAM and the baseline) with
//! recording off and with
//! the rerun + MCAP recorders on, side by side in one process; prints the time ratio and the
//! bytes per frame of each file.
//!
//! `cargo bench --bench recording` (add `-- FRAMES`, default 150).

use std::time::Instant;

use dynaflow_engine::runtime::{self, RunOptions};
use dynaflow_engine::sink::Sink;
use dynaflow_engine::{LoadRequest, load};
use dynaflow_recordings::{EncodeCache, McapSink, RrdSink};

fn main() {
    let frames: u64 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(150);
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let loaded =
        load(&root.join("graphs/default.yaml"), &dynaflow::registry(), &LoadRequest::default()).expect("read graph");
    let graph = loaded.graph.expect("default graph is valid");
    let out = std::env::temp_dir().join(format!("dynaflow-bench-rec-{}", std::process::id()));
    std::fs::create_dir_all(&out).expect("out dir");
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build().expect("runtime");
    let options = || RunOptions { max_frames: Some(frames), ..RunOptions::default() };
    let mut off = Vec::new();
    let mut on = Vec::new();
    for round in 0..2 {
        let t = Instant::now();
        rt.block_on(runtime::run(&graph, options(), Vec::new())).expect("run");
        off.push(t.elapsed().as_secs_f64());
        // As `dynaflow run` wires them: both recorders share image encodings.
        let cache = EncodeCache::new(2);
        let sinks: Vec<Box<dyn Sink>> = vec![
            Box::new(RrdSink::new(out.join(format!("r{round}.rrd"))).with_cache(cache.clone())),
            Box::new(McapSink::new(out.join(format!("r{round}.mcap"))).with_cache(cache)),
        ];
        let t = Instant::now();
        rt.block_on(runtime::run(&graph, options(), sinks)).expect("run");
        on.push(t.elapsed().as_secs_f64());
    }
    let best = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    let size = |f: &str| std::fs::metadata(out.join(f)).map_or(0, |m| m.len()) as f64 / frames as f64;
    let (a, b) = (best(&off), best(&on));
    println!(
        "recording cost, default graph (synth 640x480, MG-SLAM S+G next to the ORB-SLAM2-style baseline), {frames} frames, best of 2"
    );
    println!("  recording off : {a:7.2} s  {:6.1} frames/s", frames as f64 / a);
    println!("  rrd + mcap on : {b:7.2} s  {:6.1} frames/s", frames as f64 / b);
    println!("  ratio on / off: {:.2}x", b / a);
    println!("  bytes per frame: rrd {:.0} KiB, mcap {:.0} KiB", size("r1.rrd") / 1024.0, size("r1.mcap") / 1024.0);
    let _ = std::fs::remove_dir_all(&out);
}
