//! Dynamic-point culling (issue 10): the rules' graph runs in every variant, its labels are
//! reproducible, and on the synthetic scene the labels follow the ground truth the way the
//! rules promise.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

fn run(variant: &str, out: &std::path::Path, record: &str) -> serde_json::Value {
    let o = common::bin()
        .args(["run", "--no-progress", "--digest", "--frames", "6", "--variant", variant, "--record", record, "--out"])
        .arg(out)
        .arg(common::repo().join("graphs/culling.yaml"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{variant}: {}", String::from_utf8_lossy(&o.stderr));
    let path = out.join(format!("culling-{variant}.summary.json"));
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn every_rule_runs_and_the_same_seed_gives_the_same_labels() {
    let dir = common::TempDir::new("culling");
    for variant in
        ["epipolar_fixed", "epipolar_adaptive", "mask", "semantic_prior", "flow_consistency", "depth_consistency"]
    {
        let a = run(variant, &dir.path().join("a"), "none");
        let b = run(variant, &dir.path().join("b"), "none");
        let labels = &a["digests"]["cull/labels"];
        assert_eq!(labels["count"], 6, "{variant}: one label set per frame: {labels}");
        assert_eq!(labels, &b["digests"]["cull/labels"], "{variant}: labels differ between two runs");
        assert_eq!(a["digests"]["fundamental/model"], b["digests"]["fundamental/model"]);
        assert_eq!(a["digests"]["homography/model"], b["digests"]["homography/model"]);
        if variant == "pspnet" {
            // The screening sees only what the flow rule kept, and removes more.
            assert_eq!(a["digests"]["screen/counts"], b["digests"]["screen/counts"]);
            assert_eq!(a["digests"]["screen/counts"]["count"], 6);
        }
        if variant == "mask_or_epipolar" {
            assert_eq!(a["digests"]["combined/labels"], b["digests"]["combined/labels"]);
            assert_eq!(a["digests"]["combined/labels"]["count"], 6);
        }
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
