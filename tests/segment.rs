//! Segmentation: the `segment` operator and `dynaflow segment` on the vendored
//! segmenters, the mask quality docs/benchmarks.md reports (graphs/segmentation.yaml), the
//! backends (rten, reference, wgpu) agreeing, and wrong models, missing class files and unsupported ops as errors
//! that name the model, the node and the parameter. The raw outputs against onnxruntime are
//! in `tests/infer.rs`.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::Path;

use dynaflow_datasets::synth::{Generator, SynthConfig};

/// A synthetic frame with people in view, written as a PNG; its ground-truth person mask.
fn synthetic_frame(dir: &Path, frame: u64) -> (std::path::PathBuf, Vec<bool>) {
    let g = Generator::new(SynthConfig::default());
    let f = g.frame(frame, false);
    let k = &g.config().intrinsics;
    let path = dir.join(format!("synth{frame}.png"));
    image::RgbImage::from_raw(k.width, k.height, f.rgb).unwrap().save(&path).unwrap();
    (path, f.class.iter().map(|&c| c != 0).collect())
}

#[test]
fn segment_command_writes_a_class_image_and_counts_per_image() {
    let dir = common::TempDir::new("segment-cli");
    let (synth, truth) = synthetic_frame(dir.path(), 40);
    let real = common::repo().join("tests/fixtures/slambook2_rgbd_pair/rgb/1.png");
    let voc = common::repo().join("models/seg/deeplabv3_mnv2_voc/deeplabv3_257_mv.onnx");
    for (model, classes) in [(None, 2usize), (Some(&voc), 21)] {
        let out = dir.path().join(format!("out{classes}"));
        let mut cmd = common::bin();
        cmd.args(["segment", "--out"]).arg(&out);
        if let Some(m) = model {
            cmd.arg("--model").arg(m);
        }
        let o = cmd.arg(&synth).arg(&real).output().unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        for stem in ["synth40", "1"] {
            let png = image::open(out.join(format!("{stem}.png"))).unwrap().into_luma8();
            let json: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(out.join(format!("{stem}.json"))).unwrap()).unwrap();
            let (w, h) = (json["width"].as_u64().unwrap() as u32, json["height"].as_u64().unwrap() as u32);
            assert_eq!(png.dimensions(), (w, h), "{stem}: the class image has the image's size");
            let names: Vec<&str> = json["classes"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
            assert_eq!(names.len(), classes);
            // The counts are the class image's.
            let mut counts = vec![0u64; classes];
            for &v in png.as_raw() {
                assert!(usize::from(v) < classes, "{stem}: class id {v}");
                counts[usize::from(v)] += 1;
            }
            for (name, n) in names.iter().zip(&counts) {
                assert_eq!(
                    json["pixels"].get(*name).and_then(serde_json::Value::as_u64).unwrap_or(0),
                    *n,
                    "{stem} {name}"
                );
            }
            if stem == "synth40" {
                // The person pixels overlap the generator's people (the IoU over a whole
                // sequence is graphs/segmentation.yaml's, below).
                let person = names.iter().position(|n| *n == "person").unwrap() as u8;
                let ours: Vec<bool> = png.as_raw().iter().map(|&v| v == person).collect();
                let inter = ours.iter().zip(&truth).filter(|(a, b)| **a && **b).count();
                let union = ours.iter().zip(&truth).filter(|(a, b)| **a || **b).count();
                assert!(inter * 10 >= union, "{classes} classes: IoU {inter}/{union} on a frame with two people");
            }
        }
    }
}

/// The table of docs/benchmarks.md's "Segmentation masks": (node, pooled IoU, precision,
/// recall) of graphs/segmentation.yaml as written.
fn documented_ious() -> Vec<(String, [f64; 3])> {
    let doc = std::fs::read_to_string(common::repo().join("docs/benchmarks.md")).unwrap();
    let section = doc.split("## Segmentation masks").nth(1).unwrap().split("\n## ").next().unwrap();
    section
        .lines()
        .filter(|l| l.starts_with("| `iou_"))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let num = |i: usize| cells[i].parse::<f64>().unwrap_or_else(|_| panic!("{l}"));
            (cells[1].trim_matches('`').to_owned(), [num(3), num(4), num(5)])
        })
        .collect()
}

#[test]
fn mask_quality_on_the_synthetic_scene_is_what_the_benchmarks_say() {
    let dir = common::TempDir::new("segment-iou");
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/segmentation.yaml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = common::summary(&dir.path().join("segmentation.summary.json"));
    let documented = documented_ious();
    assert_eq!(documented.len(), 5, "one row per mask source: {documented:?}");
    for (node, [iou, precision, recall]) in documented {
        let r = summary
            .report_as::<dynaflow::summary::MaskAccuracyReport>(&node)
            .unwrap_or_else(|| panic!("no mask accuracy report of {node}"));
        assert_eq!(r.frames, 60, "{node}");
        for (key, got, want) in
            [("iou", r.iou, iou), ("precision", r.precision, precision), ("recall", r.recall, recall)]
        {
            assert!((got - want).abs() <= 0.0005, "{node} {key}: the run gives {got:.3}, docs/benchmarks.md {want}");
        }
        // Every mask source finds people on this scene (none is empty or everywhere).
        assert!(iou > 0.2 && precision > 0.5, "{node}: IoU {iou}, precision {precision}");
    }
}

#[test]
fn backends_give_the_same_mask() {
    let dir = common::TempDir::new("segment-backends");
    let (synth, _) = synthetic_frame(dir.path(), 20);
    let mut images = Vec::new();
    for backend in ["cpu", "reference", "wgpu"] {
        let out = dir.path().join(backend);
        let o = common::bin()
            .args(["segment", "--allow-software", "--backend", backend, "--out"])
            .arg(&out)
            .arg(&synth)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(0), "{backend}: {err}");
        if backend == "wgpu" {
            // Planned on the adapter there is (lavapipe in CI), no fallback to the CPU.
            assert!(!err.contains("running on the CPU"), "{err}");
        }
        images.push(image::open(out.join("synth20.png")).unwrap().into_luma8().into_raw());
    }
    // The backends differ by ~1e-6 in the scores (tests/infer.rs, gpu/tests/models.rs): the
    // threshold may flip a pixel whose probability is within that of 0.5, no more.
    for (k, name) in [(1, "reference"), (2, "wgpu")] {
        let differ = images[0].iter().zip(&images[k]).filter(|(a, b)| a != b).count();
        assert!(differ * 10_000 <= images[0].len(), "{differ} pixels differ between cpu and {name}");
    }
}

#[test]
fn wrong_models_missing_classes_and_unsupported_ops_name_the_model_node_and_parameter() {
    let dir = common::TempDir::new("segment-bad");
    let graph = dir.path().join("g.yaml");
    std::fs::write(
        &graph,
        "name: g\nnodes:\n  camera:\n    op: synth\n    params: { frames: 1, people: 1 }\n  segmenter:\n    op: segment\n    in: { image: camera.rgb }\n",
    )
    .unwrap();
    // A detector (rank-3 output), a model without classes.txt, FastestDet with a classes file
    // of two names (85 output channels), PP-HumanSeg with its Softmax renamed.
    let repo = common::repo();
    let fastest = dir.path().join("fastest");
    std::fs::create_dir_all(&fastest).unwrap();
    std::fs::copy(repo.join("models/fastestdet/FastestDet.onnx"), fastest.join("m.onnx")).unwrap();
    std::fs::write(fastest.join("classes.txt"), "background\nperson\n").unwrap();
    let bare = dir.path().join("bare");
    std::fs::create_dir_all(&bare).unwrap();
    std::fs::copy(repo.join("models/seg/mediapipe_selfie_segmentation/selfie_segmentation.onnx"), bare.join("m.onnx"))
        .unwrap();
    let odd = dir.path().join("odd");
    std::fs::create_dir_all(&odd).unwrap();
    let mut bytes = std::fs::read(repo.join("models/seg/pp_humansegv2_lite/pp_humansegv2_lite_256x144.onnx")).unwrap();
    let at = bytes.windows(9).position(|w| w == b"\x22\x07Softmax").unwrap();
    bytes[at + 2..at + 9].copy_from_slice(b"Softmay");
    std::fs::write(odd.join("m.onnx"), &bytes).unwrap();
    std::fs::write(odd.join("classes.txt"), "background\nperson\n").unwrap();
    let yolox = repo.join("models/yolox_nano/yolox_nano.onnx");
    let cases: Vec<(std::path::PathBuf, &str, &str, &str)> = vec![
        (yolox.clone(), "cpu", "model", "has shape 1x3549x85; a segmenter gives 1xCxHxW class scores"),
        (bare.join("m.onnx"), "cpu", "classes", "classes.txt: No such file"),
        (fastest.join("m.onnx"), "cpu", "model", "the model scores 85 classes but 2 class names are given"),
        (odd.join("m.onnx"), "reference", "model", "unsupported ONNX op `Softmay` at node"),
        (odd.join("m.onnx"), "cpu", "model", "Softmay"),
    ];
    for (model, backend, param, says) in cases {
        let o = common::bin()
            .args(["run", "--no-progress", "--record", "none", "--out"])
            .arg(dir.path().join("out"))
            .args(["--set", &format!("segmenter.model={}", model.display())])
            .args(["--set", &format!("segmenter.backend={backend}")])
            .arg(&graph)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{}: {err}", model.display());
        let line = err.lines().find(|l| l.contains("error[")).unwrap_or_else(|| panic!("{err}"));
        assert!(line.contains("g.yaml:6:3"), "located at the node: {line}");
        assert!(line.contains("node `segmenter`") && line.contains(&format!("param `{param}`")), "{line}");
        assert!(line.contains(&model.display().to_string()), "names the model: {line}");
        assert!(line.contains(says), "{line}");
        assert!(!err.contains("panicked"), "{err}");
    }
}
