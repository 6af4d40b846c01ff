//! Recording cost: the default graph (synthetic scene 640×480, MG-SLAM and the baseline) and
//! `graphs/orb_baseline.yaml`, each with recording off and with the rerun + MCAP recorders on,
//! side by side in one process (best of 3, alternating); prints the time ratio, the bytes per
//! frame of each file and the largest ports. Then the encodings themselves on the same frames:
//! the colour JPEG encoders (`image`, `jpeg-encoder`) against raw pixels, and the depth and
//! mask encodings the recorders used before (16-bit millimetre PNG, 8-bit PNG) against the raw samples
//! the recorders store now, each with the MCAP chunk's zstd (level 1).
//!
//! It links the `dynaflow` library, so both runs use the CLI's allocator (jemalloc, as
//! configured there).
//!
//! `cargo bench --bench recording` (add `-- FRAMES`, default 150).

use std::time::Instant;

use dynaflow_engine::msg::{Body, DepthImage, Image, SegmentationMask};
use dynaflow_engine::runtime::{self, RunOptions, RunReport};
use dynaflow_engine::sink::{MemorySink, Sink};
use dynaflow_engine::{LoadRequest, load};
use dynaflow_recordings::encode;
use dynaflow_recordings::{EncodeCache, ImageCodec, McapSink, RrdSink};
use image::ImageEncoder;

const ROUNDS: usize = 3;

fn main() {
    let frames: u64 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(150);
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = std::env::temp_dir().join(format!("dynaflow-bench-rec-{}", std::process::id()));
    std::fs::create_dir_all(&out).expect("out dir");
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build().expect("runtime");
    println!("recording cost: rrd + mcap on vs off, {frames} frames, best of {ROUNDS} (alternating)");
    println!(
        "  {:<14} {:>9} {:>9} {:>7} {:>15} {:>16}",
        "graph", "off s", "on s", "on/off", "rrd KiB/frame", "mcap KiB/frame"
    );
    let mut reports = Vec::new();
    for name in ["default", "orb_baseline"] {
        let loaded = load(&root.join(format!("graphs/{name}.yaml")), &dynaflow::registry(), &LoadRequest::default())
            .expect("read graph");
        let graph = loaded.graph.expect("graph is valid");
        let options = || RunOptions { max_frames: Some(frames), ..RunOptions::default() };
        let (mut off, mut on) = (f64::INFINITY, f64::INFINITY);
        let mut last: Option<RunReport> = None;
        for round in 0..ROUNDS {
            let t = Instant::now();
            rt.block_on(runtime::run(&graph, options(), Vec::new())).expect("run");
            off = off.min(t.elapsed().as_secs_f64());
            // As `dynaflow run` wires them: both recorders share image encodings.
            let cache = EncodeCache::new(2);
            let sinks: Vec<Box<dyn Sink>> = vec![
                Box::new(RrdSink::new(out.join(format!("{name}{round}.rrd"))).with_cache(cache.clone())),
                Box::new(McapSink::new(out.join(format!("{name}{round}.mcap"))).with_cache(cache)),
            ];
            let t = Instant::now();
            let report = rt.block_on(runtime::run(&graph, options(), sinks)).expect("run");
            on = on.min(t.elapsed().as_secs_f64());
            last = Some(report);
        }
        let size = |f: String| std::fs::metadata(out.join(f)).map_or(0, |m| m.len()) as f64 / frames as f64 / 1024.0;
        println!(
            "  {name:<14} {off:>9.2} {on:>9.2} {:>6.2}x {:>15.0} {:>16.0}",
            on / off,
            size(format!("{name}0.rrd")),
            size(format!("{name}0.mcap"))
        );
        reports.push((name, last));
    }
    for (name, report) in &reports {
        let Some(mcap) = report.as_ref().and_then(|r| r.recorders.get("mcap")) else { continue };
        let mut ports: Vec<_> = mcap.ports.iter().collect();
        ports.sort_by_key(|p| std::cmp::Reverse(p.1.bytes));
        let top: Vec<String> =
            ports.iter().take(5).map(|(p, r)| format!("{p} {:.0}", r.bytes as f64 / frames as f64 / 1024.0)).collect();
        println!("  {name}: largest MCAP ports before compression (KiB/frame): {}", top.join(", "));
    }
    let _ = std::fs::remove_dir_all(&out);
    encodings(&root.join("graphs/default.yaml"), &rt);
}

/// One encoding's cost on the sample frames.
struct Row {
    what: &'static str,
    ms: f64,
    bytes: f64,
    note: &'static str,
}

fn timed(what: &'static str, note: &'static str, n: usize, mut f: impl FnMut(usize) -> usize) -> Row {
    let mut best = f64::INFINITY;
    let mut bytes = 0;
    for _ in 0..ROUNDS {
        let t = Instant::now();
        bytes = (0..n).map(&mut f).sum::<usize>();
        best = best.min(t.elapsed().as_secs_f64());
    }
    Row { what, ms: best * 1000.0 / n as f64, bytes: bytes as f64 / n as f64, note }
}

fn zstd1(raw: &[u8]) -> usize {
    zstd::bulk::compress(raw, 1).map_or(0, |c| c.len())
}

fn png(data: &[u8], w: u32, h: u32, color: image::ExtendedColorType) -> usize {
    encode::png(data, w, h, color).map_or(0, |e| e.bytes.len())
}

/// Each encoding of colour, depth and masks on the same 20 frames of the default graph's
/// scene, one thread, per frame (bytes after the container's zstd where it applies).
fn encodings(graph: &std::path::Path, rt: &tokio::runtime::Runtime) {
    let loaded = load(graph, &dynaflow::registry(), &LoadRequest::default()).expect("read graph");
    let graph = loaded.graph.expect("valid");
    let sink = MemorySink::default();
    let options = RunOptions { max_frames: Some(20), ..RunOptions::default() };
    rt.block_on(runtime::run(&graph, options, vec![Box::new(sink.clone())])).expect("run");
    let pick = |port: &str| sink.port("camera", port);
    let rgb: Vec<Image> =
        pick("rgb").iter().filter_map(|m| if let Body::Image(i) = &m.body { Some(i.clone()) } else { None }).collect();
    let depth: Vec<DepthImage> = pick("depth")
        .iter()
        .filter_map(|m| if let Body::Depth(d) = &m.body { Some(d.clone()) } else { None })
        .collect();
    let mask: Vec<SegmentationMask> = pick("gt_mask")
        .iter()
        .filter_map(|m| if let Body::Mask(k) = &m.body { Some(k.clone()) } else { None })
        .collect();
    let n = rgb.len().min(depth.len()).min(mask.len());
    let rows = [
        timed("colour: image-rs JPEG q90", "before", n, |i| {
            let mut out = Vec::new();
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 90)
                .write_image(&rgb[i].data, rgb[i].width, rgb[i].height, image::ExtendedColorType::Rgb8)
                .expect("jpeg");
            out.len()
        }),
        timed("colour: jpeg-encoder q90 4:4:4", "full chroma", n, |i| {
            encode::jpeg_with(&rgb[i], 90, false).map_or(0, |e| e.bytes.len())
        }),
        timed("colour: jpeg-encoder q90 4:2:0", "recorded (default)", n, |i| {
            encode::image(&rgb[i], ImageCodec::Jpeg(90)).map_or(0, |e| e.bytes.len())
        }),
        timed("colour: raw rgb8 + zstd-1", "--image-format raw", n, |i| zstd1(&rgb[i].data)),
        timed("colour: PNG", "--image-format png", n, |i| {
            encode::image(&rgb[i], ImageCodec::Png).map_or(0, |e| e.bytes.len())
        }),
        timed("depth: 16-bit PNG, whole mm", "before (lossy)", n, |i| {
            let mm: Vec<u8> = encode::depth_mm(&depth[i]).iter().flat_map(|v| v.to_ne_bytes()).collect();
            png(&mm, depth[i].width, depth[i].height, image::ExtendedColorType::L16)
        }),
        timed("depth: 32FC1 + zstd-1", "MCAP now (bit-exact)", n, |i| zstd1(&encode::depth_f32_le(&depth[i]))),
        timed("depth: 16UC1 mm + zstd-1", "rrd now (LZ4 there)", n, |i| {
            let mm = encode::depth_mm_le(&depth[i]);
            zstd1(&mm)
        }),
        timed("mask: 8-bit PNG", "before", n, |i| {
            let ids: Vec<u8> = mask[i].classes.iter().map(|&c| c as u8).collect();
            png(&ids, mask[i].width, mask[i].height, image::ExtendedColorType::L8)
        }),
        timed("mask: mono8 + zstd-1", "now", n, |i| zstd1(&encode::mask_raw(&mask[i]).0)),
    ];
    println!("\nencodings of the same {n} frames (640x480), one thread, best of {ROUNDS}, per frame:");
    for r in rows {
        println!("  {:<32} {:>7.2} ms {:>8.1} KiB   {}", r.what, r.ms, r.bytes / 1024.0, r.note);
    }
}
