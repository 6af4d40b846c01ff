//! Dynamic-point culling: the rules' graph runs in every variant, its labels are
//! reproducible, and on the synthetic scene the labels follow the ground truth the way the
//! rules promise.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use dynaflow::summary::PortDigest;

/// Run a variant with `--digest`; its per-port digests.
fn run(variant: &str, out: &std::path::Path, record: &str) -> std::collections::BTreeMap<String, PortDigest> {
    let o = common::bin()
        .args(["run", "--no-progress", "--digest", "--frames", "6", "--variant", variant, "--record", record, "--out"])
        .arg(out)
        .arg(common::repo().join("graphs/culling.yaml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{variant}: {}", String::from_utf8_lossy(&o.stderr));
    common::summary(&out.join(format!("culling-{variant}.summary.json"))).digests.unwrap()
}

/// The variants of graphs/culling.yaml, as the graph file lists them.
fn variants() -> Vec<String> {
    let text = std::fs::read_to_string(common::repo().join("graphs/culling.yaml")).unwrap();
    let doc = dynaflow_engine::yaml::parse(&text).unwrap();
    dynaflow_engine::spec::parse_graph(&doc).0.variants.into_iter().map(|v| v.name).collect()
}

/// Per frame, the `dynamic` flags of a recorded label topic.
fn flags(rec: &dynaflow_recordings::diff::Recording, topic: &str) -> Vec<Vec<bool>> {
    let t = rec.topics.get(topic).unwrap_or_else(|| panic!("no {topic}"));
    t.frames.values().map(|f| f["data"]["dynamic"].as_array().unwrap().iter().map(|d| d == true).collect()).collect()
}

/// Per frame, one number of a recorded counts topic.
fn count(rec: &dynaflow_recordings::diff::Recording, topic: &str, name: &str) -> Vec<f64> {
    let t = rec.topics.get(topic).unwrap_or_else(|| panic!("no {topic}"));
    t.frames.values().map(|f| f["data"][name].as_f64().unwrap_or_else(|| panic!("{topic}: {f}"))).collect()
}

#[test]
fn every_variant_runs_reproducibly_and_does_what_it_is_for() {
    let dir = common::TempDir::new("culling");
    let all = variants();
    assert!(all.len() >= 9, "{all:?}");
    let mut mask_labels = None;
    let mut pspnet = None;
    for variant in &all {
        let a = run(variant, &dir.path().join("a"), "mcap");
        let b = run(variant, &dir.path().join("b"), "none");
        let labels = &a["cull/labels"];
        assert_eq!(labels.count, 6, "{variant}: one label set per frame: {labels:?}");
        assert_eq!(labels, &b["cull/labels"], "{variant}: labels differ between two runs");
        assert_eq!(a["fundamental/model"], b["fundamental/model"]);
        assert_eq!(a["homography/model"], b["homography/model"]);
        let rec = dynaflow_recordings::diff::read_mcap(&dir.path().join(format!("a/culling-{variant}.mcap"))).unwrap();
        let cull = flags(&rec, "/cull/labels");
        assert_eq!(cull.len(), 6, "{variant}");
        // LK needs a previous frame: from the second frame on, every rule labels some points
        // dynamic (the walking people are in view) and keeps most static.
        for (k, f) in cull.iter().enumerate().skip(1) {
            let d = f.iter().filter(|d| **d).count();
            assert!(d > 0 && 2 * d < f.len(), "{variant} frame {k}: {d} of {} dynamic", f.len());
        }
        match variant.as_str() {
            "pspnet" => {
                // The screening sees only what the flow rule kept.
                assert_eq!(a["screen/counts"], b["screen/counts"]);
                let kept = count(&rec, "/cull/counts", "static");
                let screened = count(&rec, "/screen/counts", "total");
                assert_eq!(screened, kept, "{variant}: the screening got other tracks than the flow rule kept");
                pspnet = Some((cull.clone(), count(&rec, "/screen/counts", "dynamic")));
            }
            "mask" => mask_labels = Some(cull.clone()),
            "mask_or_epipolar" => {
                assert_eq!(a["combined/labels"], b["combined/labels"]);
                let (geometric, combined) = (flags(&rec, "/geometric/labels"), flags(&rec, "/combined/labels"));
                assert_eq!(combined.len(), 6);
                let mut added = 0;
                for ((m, g), c) in cull.iter().zip(&geometric).zip(&combined) {
                    assert_eq!(c.len(), m.len());
                    for ((m, g), c) in m.iter().zip(g).zip(c) {
                        assert_eq!(*c, *m || *g, "{variant}: combined is not mask OR epipolar");
                        added += usize::from(*g && !*m);
                    }
                }
                assert!(added > 0, "the epipolar rule added nothing to the mask's dynamic points");
            }
            _ => {}
        }
    }
    // The chain removes what the flow rule removed plus, of the rest, what the mask rule
    // (the `mask` variant, on the same tracks) removes: per frame, the screening's dynamic
    // count is the number of tracks the mask marks and the flow rule kept.
    let ((flow, screened), mask) = (pspnet.unwrap(), mask_labels.unwrap());
    for (k, ((f, m), s)) in flow.iter().zip(&mask).zip(&screened).enumerate() {
        let expected = f.iter().zip(m).filter(|(f, m)| !**f && **m).count();
        assert_eq!(
            *s as usize, expected,
            "frame {k}: the screening removed {s}, the mask rule on what flow kept {expected}"
        );
    }
}

#[test]
fn labels_are_recorded_with_reason_and_score() {
    let dir = common::TempDir::new("culling-rec");
    run("mask", dir.path(), "mcap");
    let rec = dynaflow_recordings::diff::read_mcap(&dir.path().join("culling-mask.mcap")).unwrap();
    let labels = &rec.topics["/cull/labels"];
    let frame = labels.frames.values().last().unwrap();
    let data = &frame["data"];
    let dynamic = data["dynamic"].as_array().unwrap();
    let reason = data["reason"].as_array().unwrap();
    let score = data["score"].as_array().unwrap();
    assert_eq!(dynamic.len(), reason.len());
    assert_eq!(dynamic.len(), score.len());
    // The synthetic people are in view: some points are dynamic by the mask, others static.
    assert!(dynamic.iter().any(|d| d == true) && dynamic.iter().any(|d| d == false));
    for (d, r) in dynamic.iter().zip(reason) {
        assert_eq!(r == "semantic", d == true, "{d} {r}");
    }
    let counts = &rec.topics["/cull/counts"].frames.values().last().unwrap()["data"];
    assert!(counts.to_string().contains("dynamic"), "{counts}");
}

#[test]
fn box_to_mask_recovers_the_people_from_their_boxes_and_depth() {
    use dynaflow_culling::{box_depth_mask, instance_boxes};
    use dynaflow_datasets::synth::{Generator, SynthConfig};
    let g = Generator::new(SynthConfig::default());
    let (mut inter, mut union, mut frames, mut ours_n, mut truth_n) = (0usize, 0usize, 0, 0usize, 0usize);
    for k in (0..300).step_by(25) {
        let f = g.frame(k, false);
        let (w, h) = (640, 480);
        let boxes: Vec<[f32; 4]> = instance_boxes(&f.instance, &f.class, w, 200).into_iter().map(|(b, _)| b).collect();
        if boxes.is_empty() {
            continue;
        }
        frames += 1;
        // The boxes a perfect detector would give; the noisy Kinect-like depth.
        let mask = box_depth_mask(&boxes, &f.depth, w, h, 0.1, 0.4);
        for (&m, &c) in mask.iter().zip(&f.class) {
            let (ours, truth) = (m != 0, c != 0);
            inter += usize::from(ours && truth);
            union += usize::from(ours || truth);
            ours_n += usize::from(ours);
            truth_n += usize::from(truth);
        }
    }
    let iou = inter as f64 / union.max(1) as f64;
    let (precision, recall) = (inter as f64 / ours_n.max(1) as f64, inter as f64 / truth_n.max(1) as f64);
    eprintln!(
        "box_to_mask vs ground-truth person masks over {frames} frames: IoU {iou:.3}, precision {precision:.3}, recall {recall:.3}"
    );
    // Depth holes inside a person stay unmasked and the floor at a person's feet shares their
    // depth: the mask is a proxy, not a segmentation.
    assert!(frames >= 5 && iou >= 0.7 && precision >= 0.8, "IoU {iou}, precision {precision} over {frames} frames");
}
