//! `dynaflow compare`: three MG-SLAM variants (the paper's ablation rows S, G and
//! S+G) in one recording that `rerun rrd verify` accepts, every run's entities under its own
//! root, the blueprint present; what cannot be compared is refused, naming the file.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

mod common;

fn rerun() -> Option<PathBuf> {
    let exe = common::peers::venv().join("bin/rerun");
    let ok = Command::new(&exe).arg("--version").stdin(Stdio::null()).output().is_ok_and(|o| o.status.success());
    common::peers::peer_runs("rerun", "compare: rerun rrd verify/print of the comparison", || {
        if ok { Ok(()) } else { Err(format!("no {}", exe.display())) }
    })
    .then_some(exe)
}

/// Record `graphs/mg_slam.yaml` (variant `v`, or as written) for 20 frames; its MCAP file.
fn record(dir: &Path, variant: Option<&str>) -> PathBuf {
    let out = dir.join(variant.unwrap_or("base"));
    let mut c = common::bin();
    c.arg("run").arg(common::repo().join("graphs/mg_slam.yaml"));
    if let Some(v) = variant {
        c.args(["--variant", v]);
    }
    let o = c.args(["--frames", "20", "--record", "mcap", "--no-progress", "--out"]).arg(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let stem = variant.map_or_else(|| "mg_slam".to_owned(), |v| format!("mg_slam-{v}"));
    out.join(format!("{stem}.mcap"))
}

fn compare(runs: &[&Path], names: &str, out: &Path) -> std::process::Output {
    common::bin().arg("compare").args(runs).args(["--names", names, "--json", "--out"]).arg(out).output().unwrap()
}

/// Entity paths of `file` with their rows (`rerun rrd print`), blueprint entities included.
fn entities(rerun: &Path, file: &Path) -> std::collections::BTreeMap<String, u64> {
    let out = Command::new(rerun).args(["rrd", "print"]).arg(file).stdin(Stdio::null()).output().unwrap();
    assert!(out.status.success(), "rerun rrd print: {}", String::from_utf8_lossy(&out.stderr));
    let mut rows = std::collections::BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Some(rest) = line.strip_prefix("Chunk(") else { continue };
        let mut parts = rest.split(" - ");
        let n: u64 =
            parts.next().unwrap_or_default().split_whitespace().nth(2).and_then(|n| n.parse().ok()).unwrap_or(0);
        *rows.entry(parts.next().unwrap_or_default().to_owned()).or_insert(0) += n;
    }
    rows
}

#[test]
fn three_mg_slam_variants_in_one_verified_recording_each_under_its_root() {
    let dir = common::TempDir::new("compare");
    let runs = [record(dir.path(), Some("S")), record(dir.path(), Some("G")), record(dir.path(), None)];
    let out = dir.path().join("compare.rrd");
    let o = compare(&[&runs[0], &runs[1], &runs[2]], "S,G,S+G", &out);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = summary.as_array().unwrap();
    assert_eq!(rows.len(), 3);
    // Each run's labels are the ones its tracker decided with (the recording's provenance).
    let labels = [("S", "/semantic/labels"), ("G", "/geometric/labels"), ("S+G", "/combined/labels")];
    for (r, (name, topic)) in rows.iter().zip(labels) {
        assert_eq!(r["name"], name);
        assert_eq!(r["frames"], 20, "{r}");
        assert!(r["ate_rmse_m"].as_f64().is_some_and(|a| a.is_finite() && a >= 0.0), "{r}");
        assert_eq!(r["labels"], topic, "{r}");
    }
    // The first run parts from nobody; S and G decide differently, so G parts from S.
    assert!(rows[0]["parts_at"].is_null() && rows[1]["parts_at"].is_array(), "{summary}");
    let Some(rerun) = rerun() else { return };
    let v = Command::new(&rerun).args(["rrd", "verify"]).arg(&out).stdin(Stdio::null()).output().unwrap();
    assert!(
        v.status.success(),
        "rerun rrd verify: {}{}",
        String::from_utf8_lossy(&v.stdout),
        String::from_utf8_lossy(&v.stderr)
    );
    let e = entities(&rerun, &out);
    // (rerun escapes `+` in entity paths.)
    for name in ["S", "G", "S\\+G"] {
        for part in ["camera", "camera/labels", "world/path"] {
            assert!(e.get(&format!("/runs/{name}/{part}")).is_some_and(|n| *n > 0), "no /runs/{name}/{part}: {e:?}");
        }
        assert!(e.contains_key(&format!("/metrics/ate/{name}")) && e.contains_key(&format!("/metrics/dynamic/{name}")));
    }
    assert!(e.get("/runs/S/camera").is_some_and(|n| *n == 20), "one image per frame: {e:?}");
    assert!(e.contains_key("/ground_truth/path") && e.contains_key("/parting"), "{e:?}");
    // Everything else is a blueprint entity (views, containers, the viewport): it is there.
    let data = |k: &str| {
        ["/runs/", "/metrics/", "/ground_truth", "/parting", "/__properties"].iter().any(|p| k.starts_with(p))
    };
    assert!(
        e.keys().any(|k| k.starts_with("/view/")) && e.keys().any(|k| k.starts_with("/container/")),
        "no blueprint: {e:?}"
    );
    assert!(
        e.keys().filter(|k| !data(k)).all(|k| k.starts_with("/view/")
            || k.starts_with("/container/")
            || k.starts_with("/viewport")
            || k.is_empty()
            || k == "/"),
        "{e:?}"
    );
}

#[test]
fn runs_that_cannot_be_compared_are_refused_naming_the_file() {
    let dir = common::TempDir::new("compare-bad");
    let good = record(dir.path(), None);
    let out = dir.path().join("c.rrd");
    // A file that is not a recording.
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file").unwrap();
    let o = compare(&[&good, &junk], "a,b", &out);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("junk.mcap"), "{err}");
    // A missing file.
    let o = compare(&[&good, &dir.path().join("missing.mcap")], "a,b", &out);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing.mcap"));
    // Another graph whose ports differ.
    let other = dir.path().join("orb");
    let o = common::bin()
        .arg("run")
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .args(["--frames", "5", "--record", "mcap", "--no-progress", "--out"])
        .arg(&other)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0));
    let o = compare(&[&good, &other.join("orb_baseline.mcap")], "a,b", &out);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("orb_baseline.mcap") && err.contains("ports differ"), "{err}");
    // Two runs of one name: which is which would be lost.
    let o = compare(&[&good, &good], "a,a", &out);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("two runs are named `a`"));
    assert!(!out.exists(), "nothing written for a refused comparison");
}
