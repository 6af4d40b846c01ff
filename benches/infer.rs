//! Detector and segmenter inference, every backend side by side in one run on the same real
//! frame:
//! our reference executor, the CPU backend (rten), onnxruntime (the peer, one thread and its
//! default threads), our wgpu executor (whatever adapter there is: lavapipe here, an NVIDIA
//! GPU through the device tool), and, where `DYNAFLOW_GPU_ANCHOR` names
//! `gpu_anchor.py`, PyTorch on the same GPU (eager and CUDA graph). Then the per-dispatch
//! GPU time table from timestamp queries.
//!
//! `cargo bench --bench infer` (add `-- REPS`, default 10). `DYNAFLOW_PEERS` (default
//! `<target folder>/peers`, as `scripts/peers.sh` makes it) is the venv with onnxruntime; `DYNAFLOW_REPO` overrides where the
//! models and fixtures are (for a copied binary); `DYNAFLOW_BENCH_JSON` writes the figures.
#![allow(clippy::unwrap_used, clippy::panic)]

#[path = "common/timing.rs"]
mod timing;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use timing::median_ms;

use dynaflow_gpu::{Gpu, GpuModel};
use dynaflow_infer::detect::{Decoder, Detector, letterbox_bgr, resize_bgr_unit};
use dynaflow_infer::onnx::load_with_bytes;
use dynaflow_infer::reference::run;
use dynaflow_infer::rten_cpu::RtenModel;
use dynaflow_infer::tensor::Tensor;
use serde_json::json;

fn repo() -> PathBuf {
    std::env::var_os("DYNAFLOW_REPO").map_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")), PathBuf::from)
}

fn max_diff(a: &[Tensor], b: &[f32]) -> f64 {
    f64::from(a[0].floats().iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max))
}

fn python_with(module: &str) -> Option<PathBuf> {
    // The venv `scripts/peers.sh` makes: `DYNAFLOW_PEERS`, else `<target folder>/peers`.
    let venv = std::env::var_os("DYNAFLOW_PEERS").map_or_else(
        || {
            std::env::var_os("CARGO_TARGET_DIR")
                .map_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/target")), PathBuf::from)
                .join("peers")
        },
        PathBuf::from,
    );
    [venv.join("bin/python"), PathBuf::from("python3")]
        .into_iter()
        .find(|p| Command::new(p).args(["-c", &format!("import {module}")]).output().is_ok_and(|o| o.status.success()))
}

/// onnxruntime on the same input: its output and timings.
fn onnxruntime(
    python: &Path,
    model: &Path,
    x: &[f32],
    shape: &[usize],
    reps: usize,
) -> Option<(Vec<f32>, serde_json::Value)> {
    let dir = std::env::temp_dir().join(format!("dynaflow-bench-infer-{}", std::process::id()));
    std::fs::create_dir_all(&dir).ok()?;
    let input = dir.join("x.f32");
    std::fs::write(&input, x.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).ok()?;
    let dims: Vec<String> = shape.iter().map(ToString::to_string).collect();
    let out = Command::new(python)
        .arg(repo().join("tests/peers/onnx_ort.py"))
        .arg(model)
        .arg(&input)
        .arg(dims.join(","))
        .arg(dir.join("y"))
        .arg(reps.to_string())
        .output()
        .ok()?;
    if !out.status.success() {
        eprintln!("onnxruntime failed: {}", String::from_utf8_lossy(&out.stderr));
        return None;
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).ok()?;
    let b = std::fs::read(dir.join("y.0.f32")).ok()?;
    let _ = std::fs::remove_dir_all(&dir);
    Some((b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(), v))
}

/// A table row: backend, model ms, end-to-end ms, max abs difference from the reference.
type Row = (String, f64, Option<f64>, Option<f64>);

/// onnxruntime's two rows (one thread, its default threads) for `model` on input `x`, their
/// outputs against the reference's `want`; a note when there is no peer.
fn peer_rows(
    python: Option<&Path>,
    model: &Path,
    x: &[f32],
    shape: &[usize],
    reps: usize,
    want: &[f32],
    rows: &mut Vec<Row>,
) {
    let Some((theirs, v)) = python.and_then(|py| onnxruntime(py, model, x, shape, reps)) else {
        println!("note: no Python with onnxruntime (DYNAFLOW_PEERS); the peer rows are missing");
        return;
    };
    let d = theirs.iter().zip(want).map(|(a, b)| f64::from((a - b).abs())).fold(0.0, f64::max);
    let version = v["version"].as_str().unwrap_or("?").to_string();
    for (threads, key) in [("1 thread", "ms_1thread"), ("default threads", "ms_threads")] {
        rows.push((
            format!("onnxruntime {version} CPU, {threads} (peer)"),
            v[key].as_f64().unwrap_or(f64::NAN),
            None,
            Some(d),
        ));
    }
}

fn main() {
    let reps: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(10);
    let frame = repo().join("tests/fixtures/slambook2_rgbd_pair/rgb/1.png");
    let img = image::open(&frame).unwrap().into_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let ort_python = python_with("onnxruntime");
    let mut report = serde_json::Map::new();
    println!("# detector inference, {w}x{h} real Kinect frame, median of {reps}\n");
    for (name, file, decoder, side) in [
        ("YOLOX-nano", "models/yolox_nano/yolox_nano.onnx", Decoder::Yolox, 416),
        ("FastestDet", "models/fastestdet/FastestDet.onnx", Decoder::FastestDet, 352),
    ] {
        let path = repo().join(file);
        let (model, bytes) = load_with_bytes(&path).unwrap();
        let input_name = model.inputs[0].name.clone();
        let x = match decoder {
            Decoder::Yolox => letterbox_bgr(img.as_raw(), w, h, side).0,
            Decoder::FastestDet => resize_bgr_unit(img.as_raw(), w, h, side),
        };
        let shape = vec![1, 3, side, side];
        let input = || vec![(input_name.as_str(), Tensor::F32 { shape: shape.clone(), data: x.clone() })];
        let detector = Detector::new(model.clone(), decoder).unwrap();
        let mut rows: Vec<Row> = Vec::new();

        let mut want = Vec::new();
        let ms = median_ms(reps.min(3), || want = run(&model, &input()).unwrap()[0].floats());
        rows.push(("reference executor (ours, plain loops, 1 thread)".into(), ms, None, Some(0.0)));

        let rten = RtenModel::load(bytes.clone()).unwrap();
        let mut got = Vec::new();
        let ms = median_ms(reps, || got = rten.run(&input()).unwrap());
        let e2e = median_ms(reps, || {
            detector.detect_with(img.as_raw(), w, h, 80, 0.3, 0.45, |n, t| rten.run(&[(n, t)])).unwrap();
        });
        rows.push((
            format!("cpu: rten 0.27 ({} threads)", std::thread::available_parallelism().map_or(1, |n| n.get())),
            ms,
            Some(e2e),
            Some(max_diff(&got, &want)),
        ));

        peer_rows(ort_python.as_deref(), &path, &x, &shape, reps, &want, &mut rows);

        let mut kernels: Option<Vec<dynaflow_gpu::KernelTime>> = None;
        let mut stats = None;
        match Gpu::new() {
            Ok(gpu) => {
                let t = Instant::now();
                let g = GpuModel::new(gpu, &model).unwrap();
                let plan_ms = t.elapsed().as_secs_f64() * 1e3;
                let mut got = Vec::new();
                let ms = median_ms(reps, || got = g.run(&input()).unwrap());
                let e2e = median_ms(reps, || {
                    detector
                        .detect_with(img.as_raw(), w, h, 80, 0.3, 0.45, |n, t| {
                            g.run(&[(n, t)]).map_err(|e| e.to_string())
                        })
                        .unwrap();
                });
                rows.push((format!("wgpu (ours): {}", g.adapter()), ms, Some(e2e), Some(max_diff(&got, &want))));
                println!("{name}: GPU plan in {plan_ms:.0} ms: {:?}", g.stats());
                stats = Some(format!("{:?}", g.stats()));
                kernels = g.profile(&input()).map_err(|e| println!("note: {e}")).ok();
            }
            Err(e) => println!("note: {e}; no wgpu row"),
        }

        println!("\n## {name} {side}x{side}\n");
        println!(
            "| backend | model ms/frame | end to end ms (prep + model + decode + NMS) | max abs diff vs reference |"
        );
        println!("|---|---|---|---|");
        for (b, ms, e2e, d) in &rows {
            let e2e = e2e.map_or("".into(), |v| format!("{v:.2}"));
            let d = d.map_or("".into(), |v| format!("{v:.1e}"));
            println!("| {b} | {ms:.2} | {e2e} | {d} |");
        }
        let mut by_kernel: BTreeMap<&str, (usize, f64)> = BTreeMap::new();
        if let Some(k) = &kernels {
            let total: f64 = k.iter().map(|t| t.ns).sum();
            for t in k {
                let e = by_kernel.entry(t.kernel).or_default();
                e.0 += 1;
                e.1 += t.ns;
            }
            println!("\nGPU time per kernel (timestamp queries, one pass per dispatch): total {:.3} ms\n", total / 1e6);
            println!("| kernel | dispatches | ms | share |");
            println!("|---|---|---|---|");
            let mut list: Vec<_> = by_kernel.iter().collect();
            list.sort_by(|a, b| b.1.1.total_cmp(&a.1.1));
            for (kernel, (n, ns)) in list {
                println!("| {kernel} | {n} | {:.3} | {:.0} % |", ns / 1e6, 100.0 * ns / total.max(1.0));
            }
            let mut top: Vec<_> = k.iter().collect();
            top.sort_by(|a, b| b.ns.total_cmp(&a.ns));
            println!(
                "\nslowest dispatches: {}",
                top.iter()
                    .take(5)
                    .map(|t| format!("{} {} {:.3} ms", t.node, t.kernel, t.ns / 1e6))
                    .collect::<Vec<_>>()
                    .join("; ")
            );
        }
        report.insert(
            name.into(),
            json!({
                "rows": rows.iter().map(|(b, ms, e2e, d)| json!({"backend": b, "ms": ms, "end_to_end_ms": e2e, "max_diff": d})).collect::<Vec<_>>(),
                "plan": stats,
                "kernels_ms": by_kernel.iter().map(|(k, (n, ns))| (k.to_string(), json!({"dispatches": n, "ms": ns / 1e6}))).collect::<serde_json::Map<_, _>>(),
            }),
        );
        if name == "YOLOX-nano"
            && let Some(anchor) = std::env::var_os("DYNAFLOW_GPU_ANCHOR")
        {
            let python = std::env::var_os("DYNAFLOW_ANCHOR_PYTHON").unwrap_or_else(|| "python3".into());
            println!("\nPyTorch anchor (gpu_anchor.py {} {side} {side}), same GPU, same run:", path.display());
            match Command::new(python).arg(anchor).arg(&path).arg(side.to_string()).arg(side.to_string()).output() {
                Ok(o) => print!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr)),
                Err(e) => println!("gpu_anchor.py did not run: {e}"),
            }
        }
    }
    segmenters(&img, reps, ort_python.as_deref(), &mut report);
    if let Some(p) = std::env::var_os("DYNAFLOW_BENCH_JSON") {
        std::fs::write(p, serde_json::to_string_pretty(&report).unwrap()).unwrap();
    }
}

/// The vendored segmenters on the same frame: reference, rten, onnxruntime (1 thread and its
/// default threads) and wgpu (a plan, or why there is none), the model alone and end to end
/// (input resize + model + scores resized to the frame and decided per pixel).
fn segmenters(
    img: &image::RgbImage,
    reps: usize,
    python: Option<&Path>,
    report: &mut serde_json::Map<String, serde_json::Value>,
) {
    use dynaflow_infer::segment::{Normalise, Segmenter, read_classes};
    let (w, h) = (img.width() as usize, img.height() as usize);
    println!("\n# segmenters, {w}x{h} real Kinect frame, median of {reps}");
    for (name, file, range) in [
        ("PP-HumanSegV2-Lite", "models/seg/pp_humansegv2_lite/pp_humansegv2_lite_256x144.onnx", Normalise::Symmetric),
        ("MediaPipe selfie", "models/seg/mediapipe_selfie_segmentation/selfie_segmentation.onnx", Normalise::Unit),
        (
            "MediaPipe selfie landscape",
            "models/seg/mediapipe_selfie_segmentation/selfie_segmentation_landscape.onnx",
            Normalise::Unit,
        ),
        ("DeepLabV3-MobileNetV2 VOC", "models/seg/deeplabv3_mnv2_voc/deeplabv3_257_mv.onnx", Normalise::Symmetric),
    ] {
        let path = repo().join(file);
        let (model, bytes) = load_with_bytes(&path).unwrap();
        let seg =
            Segmenter::new(model.clone(), read_classes(&path.with_file_name("classes.txt")).unwrap(), range).unwrap();
        let x = seg.input(img.as_raw(), w, h);
        let shape = x.shape().to_vec();
        let input = || vec![(seg.input_name(), x.clone())];
        let mut rows: Vec<Row> = Vec::new();
        let mut want = Vec::new();
        let ms = median_ms(reps.min(3), || want = run(&model, &input()).unwrap()[0].floats());
        rows.push(("reference executor (ours, plain loops, 1 thread)".into(), ms, None, Some(0.0)));
        let rten = RtenModel::load(bytes).unwrap();
        let mut got = Vec::new();
        let ms = median_ms(reps, || got = rten.run(&input()).unwrap());
        let e2e = median_ms(reps, || {
            let out = rten.run(&[(seg.input_name(), seg.input(img.as_raw(), w, h))]).unwrap();
            seg.decode(&out[0], w, h, 0.5).unwrap();
        });
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        rows.push((format!("cpu: rten 0.27 ({threads} threads)"), ms, Some(e2e), Some(max_diff(&got, &want))));
        peer_rows(python, &path, &x.floats(), &shape, reps, &want, &mut rows);
        let wgpu = match Gpu::new() {
            Ok(gpu) => match GpuModel::new(gpu, &model) {
                Ok(g) => {
                    let mut got = Vec::new();
                    let ms = median_ms(reps, || got = g.run(&input()).unwrap());
                    rows.push((format!("wgpu (ours): {}", g.adapter()), ms, None, Some(max_diff(&got, &want))));
                    None
                }
                Err(e) => Some(format!("no wgpu row: the plan refuses the model ({e})")),
            },
            Err(e) => Some(format!("no wgpu row: {e}")),
        };
        println!("\n## {name} {}x{} ({} classes)\n", shape[3], shape[2], seg.classes().len());
        println!(
            "| backend | model ms/frame | end to end ms (resize + model + per-pixel decision at {w}x{h}) | max abs diff vs reference |"
        );
        println!("|---|---|---|---|");
        for (b, ms, e2e, d) in &rows {
            let e2e = e2e.map_or("".into(), |v| format!("{v:.2}"));
            let d = d.map_or("".into(), |v| format!("{v:.1e}"));
            println!("| {b} | {ms:.2} | {e2e} | {d} |");
        }
        if let Some(why) = &wgpu {
            println!("\n{why}");
        }
        report.insert(
            name.into(),
            json!({
                "rows": rows.iter().map(|(b, ms, e2e, d)| json!({"backend": b, "ms": ms, "end_to_end_ms": e2e, "max_diff": d})).collect::<Vec<_>>(),
                "wgpu": wgpu,
            }),
        );
    }
}
