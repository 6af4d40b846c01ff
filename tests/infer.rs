//! Inference: the ONNX reader, the reference executor and the CPU backend (rten)
//! on both vendored detectors, raw outputs against onnxruntime on real images, YOLOX-nano's
//! detections on the real Kinect frames, every backend giving the same detections, and
//! corrupt models or unsupported ops as clear errors.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;
#[path = "../vision/tests/common/frontend.rs"]
mod frontend;

use std::path::{Path, PathBuf};
use std::process::Command;

use dynaflow::summary::GateReport;
use dynaflow_infer::Error;
use dynaflow_infer::detect::{decode_yolox, letterbox_bgr, nms};
use dynaflow_infer::onnx::{load, parse};
use dynaflow_infer::reference::{SUPPORTED, run};
use dynaflow_infer::rten_cpu::RtenModel;
use dynaflow_infer::tensor::Tensor;

fn yolox() -> PathBuf {
    common::repo().join("models/yolox_nano/yolox_nano.onnx")
}
fn fastestdet() -> PathBuf {
    common::repo().join("models/fastestdet/FastestDet.onnx")
}

fn rgb(path: &Path) -> (Vec<u8>, usize, usize) {
    let img = image::open(path).unwrap().into_rgb8();
    let (w, h) = img.dimensions();
    (img.into_raw(), w as usize, h as usize)
}

/// FastestDet's input: plain resize to 352, BGR, /255 (nearest, enough for a comparison).
fn fastestdet_input(rgb: &[u8], w: usize, h: usize) -> Vec<f32> {
    let s = 352;
    let mut out = vec![0.0f32; 3 * s * s];
    for y in 0..s {
        for x in 0..s {
            let (sx, sy) = (x * w / s, y * h / s);
            for c in 0..3 {
                out[(2 - c) * s * s + y * s + x] = f32::from(rgb[(sy * w + sx) * 3 + c]) / 255.0;
            }
        }
    }
    out
}

fn ort(python: &Path, model: &Path, input: &[f32], shape: &[usize], dir: &Path) -> Vec<Vec<f32>> {
    let inp = dir.join("input.f32");
    std::fs::write(&inp, input.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
    let dims = shape.iter().map(ToString::to_string).collect::<Vec<_>>().join(",");
    let prefix = dir.join("ort");
    let o = Command::new(python)
        .arg(common::repo().join("tests/peers/onnx_ort.py"))
        .arg(model)
        .arg(&inp)
        .arg(&dims)
        .arg(&prefix)
        .output()
        .unwrap();
    assert!(o.status.success(), "onnxruntime: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    (0..v["shapes"].as_array().unwrap().len())
        .map(|k| {
            let b = std::fs::read(format!("{}.{k}.f32", prefix.display())).unwrap();
            b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
        })
        .collect()
}

#[test]
fn both_models_parse_and_use_only_supported_ops() {
    for (path, input, output) in
        [(yolox(), vec![1, 3, 416, 416], vec![1, 3549, 85]), (fastestdet(), vec![1, 3, 352, 352], vec![1, 85, 22, 22])]
    {
        let m = load(&path).unwrap();
        assert_eq!(m.opset, 11, "{}", path.display());
        let shape: Vec<i64> = m.inputs[0].shape.iter().map(|d| d.unwrap()).collect();
        assert_eq!(shape, input.iter().map(|&d| d as i64).collect::<Vec<_>>());
        let out: Vec<i64> = m.outputs[0].shape.iter().map(|d| d.unwrap()).collect();
        assert_eq!(out, output.iter().map(|&d| d as i64).collect::<Vec<_>>());
        for n in &m.nodes {
            assert!(SUPPORTED.contains(&n.op.name()), "{}: {}", path.display(), n.op);
        }
    }
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max)
}

#[test]
fn reference_executor_and_rten_equal_onnxruntime_on_real_images() {
    let Some(python) =
        frontend::python_with("onnxruntime", "onnxruntime, numpy", "infer: reference executor and rten vs onnxruntime")
    else {
        return;
    };
    let dir = common::TempDir::new("infer-ort");
    let images = [frontend::ch7()[0].clone(), common::repo().join("tests/fixtures/slambook2_dense_rgbd/color/1.png")];
    let (ym, fm) = (load(&yolox()).unwrap(), load(&fastestdet()).unwrap());
    for img in &images {
        let (px, w, h) = rgb(img);
        let (x, _) = letterbox_bgr(&px, w, h, 416);
        let ours = run(&ym, &[("images", Tensor::F32 { shape: vec![1, 3, 416, 416], data: x.clone() })]).unwrap();
        let theirs = ort(&python, &yolox(), &x, &[1, 3, 416, 416], dir.path());
        let max = max_abs(&ours[0].floats(), &theirs[0]);
        eprintln!("YOLOX-nano {}: max |ours - onnxruntime| = {max:e}", img.display());
        assert!(max <= 1e-3, "YOLOX {}: {max}", img.display());
        let rten = RtenModel::load(std::fs::read(yolox()).unwrap()).unwrap();
        let input = || vec![("images", Tensor::F32 { shape: vec![1, 3, 416, 416], data: x.clone() })];
        let first = rten.run(&input()).unwrap();
        let max = max_abs(&first[0].floats(), &theirs[0]);
        eprintln!("YOLOX-nano {}: max |rten - onnxruntime| = {max:e}", img.display());
        assert!(max <= 1e-3, "rten YOLOX {}: {max}", img.display());
        // The CPU backend is deterministic run to run (threads included).
        assert_eq!(rten.run(&input()).unwrap(), first);

        let x = fastestdet_input(&px, w, h);
        let name = fm.inputs[0].name.clone();
        let ours = run(&fm, &[(name.as_str(), Tensor::F32 { shape: vec![1, 3, 352, 352], data: x.clone() })]).unwrap();
        let theirs = ort(&python, &fastestdet(), &x, &[1, 3, 352, 352], dir.path());
        let max = max_abs(&ours[0].floats(), &theirs[0]);
        eprintln!("FastestDet {}: max |ours - onnxruntime| = {max:e}", img.display());
        assert!(max <= 1e-3, "FastestDet {}: {max}", img.display());
        let rten = RtenModel::load(std::fs::read(fastestdet()).unwrap()).unwrap();
        let got = rten.run(&[(name.as_str(), Tensor::F32 { shape: vec![1, 3, 352, 352], data: x })]).unwrap();
        let max = max_abs(&got[0].floats(), &theirs[0]);
        eprintln!("FastestDet {}: max |rten - onnxruntime| = {max:e}", img.display());
        assert!(max <= 1e-3, "rten FastestDet {}: {max}", img.display());
    }
}

#[test]
fn yolox_finds_what_a_person_sees_on_the_kinect_frames() {
    let names: Vec<String> = std::fs::read_to_string(common::repo().join("models/yolox_nano/coco.names"))
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    let m = load(&yolox()).unwrap();
    let mut seen = Vec::new();
    for img in frontend::ch7() {
        let (px, w, h) = rgb(&img);
        let (x, lb) = letterbox_bgr(&px, w, h, 416);
        let out = run(&m, &[("images", Tensor::F32 { shape: vec![1, 3, 416, 416], data: x })]).unwrap();
        let dets = nms(decode_yolox(&out[0].floats(), 80, &lb, 0.3), 0.45);
        let labels: Vec<String> = dets.iter().map(|d| format!("{} {:.2}", names[d.class], d.score)).collect();
        eprintln!("{}: {labels:?}", img.display());
        seen.push(dets.iter().map(|d| names[d.class].clone()).collect::<Vec<_>>());
    }
    // Two views of the same desk: the same objects are found in both.
    for want in ["tvmonitor", "keyboard", "mouse", "cup"] {
        assert!(seen.iter().all(|s| s.iter().any(|n| n == want)), "{want} not found in every frame: {seen:?}");
    }
}

#[test]
fn corrupt_and_truncated_models_are_errors_not_panics() {
    let bytes = std::fs::read(fastestdet()).unwrap();
    // Every prefix length class: header, inside the graph, inside an initializer, near the end.
    for cut in [0, 1, 7, 100, 1000, 50_000, bytes.len() / 2, bytes.len() - 10, bytes.len() - 1] {
        match parse(&bytes[..cut]) {
            Err(Error::Malformed(_)) => {}
            other => panic!("cut at {cut}: {:?}", other.map(|m| m.nodes.len())),
        }
    }
    let mut flipped = bytes.clone();
    for i in (0..flipped.len()).step_by(9973) {
        flipped[i] ^= 0x5a;
        let _ = parse(&flipped);
    }
    assert!(matches!(load(Path::new("/nonexistent/model.onnx")), Err(Error::Io { .. })));
    let text = load(&common::repo().join("README.md"));
    assert!(text.is_err(), "a text file is not a model");
}

#[test]
fn detect_graph_runs_on_real_frames_and_bad_models_are_clear_errors() {
    let dir = common::TempDir::new("infer-graph");
    let graph = common::repo().join("graphs/detect.yaml");
    let fixture = common::repo().join("tests/fixtures/slambook2_rgbd_pair");
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "jsonl", "--intrinsics", "fr2", "--out"])
        .arg(dir.path())
        .arg("--input")
        .arg(&fixture)
        .arg(&graph)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let log = std::fs::read_to_string(dir.path().join("detect.messages.jsonl")).unwrap();
    let counts: Vec<u64> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|m| m["node"] == "detector")
        .map(|m| m["summary"]["count"].as_u64().unwrap())
        .collect();
    assert_eq!(counts.len(), 2);
    assert!(counts.iter().all(|&c| c >= 4), "{counts:?}");
    // A missing file and a file that is not a model: exit 2, the file named.
    for (model, says) in
        [("/nonexistent/model.onnx", "cannot read /nonexistent/model.onnx"), ("../README.md", "not a valid ONNX model")]
    {
        let out = common::bin()
            .args(["run", "--no-progress", "--record", "none", "--frames", "1", "--out"])
            .arg(dir.path())
            .args(["--set", &format!("detector.model={model}")])
            .arg(&graph)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_ne!(out.status.code(), Some(0), "{model}");
        assert!(err.contains(says), "{model}: {err}");
    }
}

#[test]
fn infer_command_prints_json_per_image_for_both_models() {
    let img = frontend::ch7()[1].clone();
    let out = common::bin().arg("infer").arg(&img).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v["width"].as_u64(), v["height"].as_u64()), (Some(640), Some(480)));
    let classes: Vec<&str> = v["detections"].as_array().unwrap().iter().map(|d| d["class"].as_str().unwrap()).collect();
    assert!(classes.contains(&"tvmonitor") && classes.contains(&"keyboard"), "{classes:?}");
    let out = common::bin()
        .args(["infer", "--decoder", "fastestdet", "--model"])
        .arg(fastestdet())
        .arg(&img)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let classes: Vec<&str> = v["detections"].as_array().unwrap().iter().map(|d| d["class"].as_str().unwrap()).collect();
    assert!(classes.contains(&"tvmonitor"), "FastestDet: {classes:?}");
    let out = common::bin().args(["infer", "/nonexistent.png"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent.png"));
}

#[test]
fn keyframe_gate_fires_each_rule_and_counts_them() {
    use std::sync::Arc;

    use dynaflow_engine::msg::{Body, Header, Image, Message, PixelFormat, Scalars};
    use dynaflow_engine::op::{Context, Inputs, Instance, Params};
    use rand_core::SeedableRng;

    let spec = *dynaflow::registry().get("keyframe_gate").unwrap();
    let params = Params::new(serde_json::json!({"dynamic_below": 10, "max_gap": 4}).as_object().unwrap().clone(), None);
    let Ok(Instance::Transform(mut op)) = (spec.build)(&params) else { panic!("gate did not build") };
    let mut ctx = Context {
        node: Arc::from("gate"),
        seed: 0,
        rng: rand_chacha::ChaCha8Rng::seed_from_u64(0),
        out_dir: None,
        stem: Arc::from("t"),
        realtime: false,
        report: None,
    };
    let header = |seq: u64| Header { seq, stamp: seq as f64, frame_id: Arc::from("camera") };
    let msg = |seq: u64, body: Body| Some(Arc::new(Message::new(header(seq), body)));
    let scalars =
        |v: &[(&str, f64)]| Body::Scalars(Scalars { values: v.iter().map(|(k, x)| (Arc::from(*k), *x)).collect() });
    let image = Body::Image(Image { width: 1, height: 1, format: PixelFormat::Rgb8, data: vec![0, 0, 0] });
    // (tracking state, key frame flag, dynamic count) of the previous frame; expected rule.
    type Frame = (Option<(f64, f64)>, Option<f64>, u8);
    let frames: [Frame; 9] = [
        (None, None, 1),                   // first
        (Some((2.0, 0.0)), Some(50.0), 0), // tracked, many dynamic points: skip
        (Some((2.0, 0.0)), Some(50.0), 0),
        (Some((2.0, 0.0)), Some(50.0), 0),
        (Some((2.0, 0.0)), Some(50.0), 5), // fourth frame since the last inference: gap
        (Some((3.0, 0.0)), Some(50.0), 2), // relocalised
        (Some((2.0, 0.0)), Some(5.0), 3),  // few dynamic points
        (Some((2.0, 1.0)), Some(50.0), 4), // tracking key frame
        (Some((2.0, 0.0)), Some(50.0), 0),
    ];
    for (seq, (tracking, dynamic, want)) in frames.iter().enumerate() {
        let seq = seq as u64;
        let inputs = Inputs::new(
            seq,
            vec![
                ("image", msg(seq, image.clone())),
                ("tracking", tracking.and_then(|(s, k)| msg(seq, scalars(&[("state", s), ("keyframe", k)])))),
                ("counts", dynamic.and_then(|d| msg(seq, scalars(&[("dynamic", d)])))),
            ],
        );
        let out = op.process(&mut ctx, &inputs).unwrap();
        let (mut rule, mut passed) = (None, false);
        for (port, m) in out.iter() {
            match (port, &m.body) {
                ("stats", Body::Scalars(s)) => rule = s.values.iter().find(|(k, _)| &**k == "rule").map(|(_, v)| *v),
                ("image", _) => passed = true,
                _ => {}
            }
        }
        assert_eq!(rule, Some(f64::from(*want)), "frame {seq}");
        assert_eq!(passed, *want != 0, "frame {seq}");
    }
    op.stop(&mut ctx).unwrap();
    let r = ctx.report.unwrap();
    assert_eq!(r["frames"], 9);
    assert_eq!(r["inferred"], 5);
    for (k, n) in [("first", 1), ("gap", 1), ("relocalised", 1), ("few_dynamic", 1), ("keyframe", 1), ("skipped", 4)] {
        assert_eq!(r["rules"][k], n, "{k}: {r}");
    }
}

#[test]
fn detector_gate_graph_runs_and_reports_its_gate() {
    let dir = common::TempDir::new("infer-gate");
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", "8", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/detector_gate.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let s = common::summary(&dir.path().join("detector_gate.summary.json"));
    let gate = s.report_as::<GateReport>("gate").unwrap();
    let rules = &gate.rules;
    let rule = |k: &str| rules[k];
    assert_eq!(rules.values().sum::<u64>(), 8);
    assert_eq!(gate.frames, 8);
    // The gate both skips and infers, and not only by its clock: the tracker's key frames and
    // relocalisations and the culling's dynamic count (its feedback inputs) open it too.
    let inferred = gate.inferred;
    assert!(rule("skipped") > 0 && inferred > 1, "{rules:?}");
    assert_eq!(inferred, 8 - rule("skipped"));
    assert!(rule("keyframe") + rule("relocalised") + rule("few_dynamic") > 0, "no feedback rule fired: {rules:?}");
    // The detector ran on exactly the frames the gate passed.
    let detector = s.run.nodes.iter().find(|n| n.node == "detector").unwrap();
    assert_eq!(detector.frames, inferred, "{detector:?}");
    assert!(s.ate.is_some_and(|a| a.rmse.is_finite()));
}

#[test]
fn wgpu_backend_gives_the_cpu_detections_and_falls_back_with_a_warning() {
    let img = frontend::ch7()[0].clone();
    let classes = |backend: &str, extra: &[&str]| {
        let mut cmd = common::bin();
        if backend == "none" {
            // Only the GL backend, which this build leaves out: no adapter at all.
            cmd.env("WGPU_BACKEND", "gl");
        }
        let backend = if backend == "none" { "wgpu" } else { backend };
        let out = cmd.args(["infer", "--backend", backend]).args(extra).arg(&img).output().unwrap();
        assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let list: Vec<(String, f64)> = v["detections"]
            .as_array()
            .unwrap()
            .iter()
            .map(|d| (d["class"].as_str().unwrap().to_string(), d["score"].as_f64().unwrap()))
            .collect();
        (list, String::from_utf8_lossy(&out.stderr).into_owned())
    };
    // The same classes in the same order, scores within 1e-3.
    let same = |a: &[(String, f64)], b: &[(String, f64)]| {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.0 == y.0 && (x.1 - y.1).abs() <= 1e-3)
    };
    let (cpu, _) = classes("cpu", &[]);
    let (reference, _) = classes("reference", &[]);
    assert!(same(&reference, &cpu), "{reference:?} vs {cpu:?}");
    // Where an adapter exists, `--backend wgpu` must run on it: a fallback to the CPU would
    // compare the CPU with itself.
    let mut software = false;
    let adapter = common::peers::peer_runs("gpu", "infer: `--backend wgpu` detections vs the CPU's", || {
        software = dynaflow_gpu::Gpu::new().map_err(|e| e.to_string())?.software;
        Ok(())
    });
    if adapter {
        // A software adapter (CI's lavapipe) counts as no GPU unless allowed.
        if software {
            let (_, err) = classes("wgpu", &[]);
            assert!(err.contains("is a software renderer on the CPU") && err.contains("running on the CPU"), "{err}");
        }
        // YOLOX-nano: every op has a kernel; the same detections and scores (to 1e-3) as the CPU.
        let (gpu, err) = classes("wgpu", &["--allow-software"]);
        assert!(!err.contains("running on the CPU"), "an adapter exists, yet wgpu fell back: {err}");
        assert!(same(&gpu, &cpu), "{gpu:?} vs {cpu:?}: {err}");
        // FastestDet too (its Pad, AveragePool, channel-split Gather and Softmax included).
        let model = fastestdet();
        let fd = ["--decoder", "fastestdet", "--model", model.to_str().unwrap()];
        let (cpu, _) = classes("cpu", &fd);
        let fd_gpu = ["--decoder", "fastestdet", "--allow-software", "--model", model.to_str().unwrap()];
        let (gpu, err) = classes("wgpu", &fd_gpu);
        assert!(!err.contains("running on the CPU"), "an adapter exists, yet wgpu fell back: {err}");
        assert!(same(&gpu, &cpu), "{gpu:?} vs {cpu:?}: {err}");
    }
    // No adapter: the documented fallback to the CPU, with a warning; the same detections.
    let (fallback, err) = classes("none", &[]);
    assert!(err.contains("no GPU adapter") && err.contains("running on the CPU"), "{err}");
    assert!(same(&fallback, &classes("cpu", &[]).0));
}

#[test]
fn an_unsupported_op_is_named_on_every_backend() {
    // FastestDet with its Softmax op renamed: `NodeProto.op_type` is field 4, a 7-byte
    // string (tag 0x22, length 7); the same length keeps the protobuf valid.
    let mut bytes = std::fs::read(fastestdet()).unwrap();
    let at = bytes.windows(9).position(|w| w == b"\x22\x07Softmax").unwrap();
    bytes[at + 2..at + 9].copy_from_slice(b"Softmay");
    let dir = common::TempDir::new("infer-unsupported");
    let model = dir.path().join("odd.onnx");
    std::fs::write(&model, &bytes).unwrap();
    let img = frontend::ch7()[0].clone();
    for (backend, says) in [("reference", "unsupported ONNX op `Softmay`"), ("cpu", "Softmay"), ("wgpu", "Softmay")] {
        let out = common::bin()
            .args(["infer", "--decoder", "fastestdet", "--allow-software", "--backend", backend, "--model"])
            .arg(&model)
            .arg(&img)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        eprintln!("{backend}: {err}");
        assert_eq!(out.status.code(), Some(2), "{backend}: {err}");
        assert!(err.contains(says) && !err.contains("panicked"), "{backend}: {err}");
    }
}

#[test]
fn yolox_finds_the_photo_textured_synthetic_people() {
    use dynaflow_datasets::synth::{Generator, SynthConfig};
    use dynaflow_infer::detect::{Decoder, Detector};
    let detector = Detector::new(load(&yolox()).unwrap(), Decoder::Yolox).unwrap();
    let rten = RtenModel::load(std::fs::read(yolox()).unwrap()).unwrap();
    let g = Generator::new(SynthConfig::default());
    let (w, h) = (g.config().intrinsics.width as usize, g.config().intrinsics.height as usize);
    let iou = |a: [f32; 4], b: [f32; 4]| {
        let iw = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
        let ih = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
        let area = |r: [f32; 4]| (r[2] - r[0]) * (r[3] - r[1]);
        iw * ih / (area(a) + area(b) - iw * ih)
    };
    let (mut visible, mut found) = (0, 0);
    for k in (0..300).step_by(10) {
        let f = g.frame(k, false);
        let dets = detector.detect_with(&f.rgb, w, h, 80, 0.3, 0.45, |n, t| rten.run(&[(n, t)])).unwrap();
        let people: Vec<[f32; 4]> = dets.iter().filter(|d| d.class == 0).map(|d| d.bbox).collect();
        // Ground-truth boxes of the people with at least 3000 visible pixels.
        for id in 1..=g.config().people as u16 {
            let (mut b, mut n) = ([f32::MAX, f32::MAX, 0.0f32, 0.0f32], 0);
            for (i, _) in f.instance.iter().enumerate().filter(|(_, v)| **v == id) {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                b = [b[0].min(x), b[1].min(y), b[2].max(x + 1.0), b[3].max(y + 1.0)];
                n += 1;
            }
            if n >= 3000 {
                visible += 1;
                found += usize::from(people.iter().any(|&p| iou(p, b) >= 0.5));
            }
        }
    }
    let recall = found as f64 / visible.max(1) as f64;
    eprintln!("YOLOX-nano finds {found} of {visible} visible synthetic people (IoU >= 0.5): {:.0} %", 100.0 * recall);
    assert!(visible >= 20, "{visible}");
    assert!(recall >= 0.5, "{recall}");
}

#[test]
fn a_detector_of_the_other_family_is_refused_at_load() {
    // FastestDet read as YOLOX gave boxes of negative size and scores of
    // 229; YOLOX-nano read as FastestDet found nothing. Both are errors naming the model, the
    // decoder and the shapes, on the command line and in a graph.
    let img = frontend::ch7()[0].clone();
    for (model, decoder, shapes) in [
        (fastestdet(), "yolox", "1 x 85 x 22 x 22 but the Yolox decoder reads 1 x 2541 x (5 + classes)"),
        (yolox(), "fastestdet", "1 x 3549 x 85 but the FastestDet decoder reads 1 x (5 + classes) x 26 x 26"),
    ] {
        let out =
            common::bin().args(["infer", "--decoder", decoder, "--model"]).arg(&model).arg(&img).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains(&model.display().to_string()) && err.contains(shapes), "{err}");
        let text = format!(
            "name: t\nnodes:\n  camera: {{ op: synth, params: {{ frames: 1 }} }}\n  det: {{ op: detect, in: {{ image: camera.rgb }}, params: {{ model: '{}', decoder: {decoder} }} }}\n",
            model.display()
        );
        let g = common::graph(&text);
        let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
        let e = rt.block_on(dynaflow_engine::runtime::run(&g, Default::default(), Vec::new())).unwrap_err().to_string();
        assert!(e.contains("det") && e.contains(shapes), "{e}");
    }
}

/// The vendored segmenters: model file, class count, input range.
fn segmenters() -> Vec<(PathBuf, usize, dynaflow_infer::segment::Normalise)> {
    use dynaflow_infer::segment::Normalise;
    let seg = common::repo().join("models/seg");
    vec![
        (seg.join("pp_humansegv2_lite/pp_humansegv2_lite_256x144.onnx"), 2, Normalise::Symmetric),
        (seg.join("mediapipe_selfie_segmentation/selfie_segmentation.onnx"), 2, Normalise::Unit),
        (seg.join("mediapipe_selfie_segmentation/selfie_segmentation_landscape.onnx"), 2, Normalise::Unit),
        (seg.join("deeplabv3_mnv2_voc/deeplabv3_257_mv.onnx"), 21, Normalise::Symmetric),
    ]
}

#[test]
fn segmenters_on_the_reference_executor_and_rten_equal_onnxruntime_on_real_images() {
    use dynaflow_infer::segment::{Segmenter, read_classes};
    let Some(python) = frontend::python_with(
        "onnxruntime",
        "onnxruntime, numpy",
        "infer: segmenters on the reference executor and rten vs onnxruntime",
    ) else {
        return;
    };
    let dir = common::TempDir::new("seg-ort");
    // Two real Kinect frames and a synthetic frame with two people in view.
    let mut images: Vec<(String, Vec<u8>, usize, usize)> =
        [frontend::ch7()[0].clone(), common::repo().join("tests/fixtures/slambook2_dense_rgbd/color/1.png")]
            .iter()
            .map(|p| {
                let (px, w, h) = rgb(p);
                (p.display().to_string(), px, w, h)
            })
            .collect();
    let g = dynaflow_datasets::synth::Generator::new(dynaflow_datasets::synth::SynthConfig::default());
    let k = g.config().intrinsics.clone();
    images.push(("synthetic frame 40".into(), g.frame(40, false).rgb, k.width as usize, k.height as usize));
    for (path, classes, range) in segmenters() {
        let model = load(&path).unwrap();
        let names = read_classes(&path.with_file_name("classes.txt")).unwrap();
        assert_eq!(names.len(), classes, "{}", path.display());
        let seg = Segmenter::new(model.clone(), names, range).unwrap();
        let rten = RtenModel::load(std::fs::read(&path).unwrap()).unwrap();
        for (img, px, w, h) in &images {
            let input = seg.input(px, *w, *h);
            let shape = input.shape().to_vec();
            let theirs = ort(&python, &path, &input.floats(), &shape, dir.path());
            let ours = run(&model, &[(seg.input_name(), input.clone())]).unwrap();
            let max = max_abs(&ours[0].floats(), &theirs[0]);
            eprintln!("{} {img}: max |reference - onnxruntime| = {max:e}", path.display());
            assert!(max <= 1e-3, "reference {} {img}: {max}", path.display());
            let got = rten.run(&[(seg.input_name(), input)]).unwrap();
            let max = max_abs(&got[0].floats(), &theirs[0]);
            eprintln!("{} {img}: max |rten - onnxruntime| = {max:e}", path.display());
            assert!(max <= 1e-3, "rten {} {img}: {max}", path.display());
        }
    }
}
