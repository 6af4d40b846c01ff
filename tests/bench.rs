//! `dynaflow bench`: every variant of the seed graphs runs end to end on a short
//! synthetic sequence, the tables and plots are written, and a failed run is a row, not the
//! end of the bench.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

fn csv_rows(path: &std::path::Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(path).unwrap().lines().skip(1).map(|l| l.split(',').map(str::to_string).collect()).collect()
}

#[test]
fn every_seed_graph_variant_runs_and_the_tables_compare_them_with_the_baseline() {
    let dir = common::TempDir::new("bench-all");
    let graphs = ["orb_baseline", "mg_slam", "yg_slam", "pspnet_slam", "ysag", "yoec_dslam"];
    let out = common::bin()
        .arg("bench")
        .args(graphs.iter().map(|g| common::repo().join(format!("graphs/{g}.yaml"))))
        .args(["--variants", "all", "--frames", "6", "--jobs", "2", "--no-progress", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let rows = csv_rows(&dir.path().join("bench.csv"));
    // Six frames give a single camera too little parallax (xyz, and the hand-held motion's
    // rest): the `mono` and `mono_inertial` rows fail saying so (no pose claimed), which makes
    // the bench exit 1; every other row is ok.
    let (mono, rows): (Vec<_>, Vec<_>) =
        rows.into_iter().partition(|r| r[0] == "orb_baseline" && r[1].starts_with("mono"));
    assert_eq!(mono.len(), 2, "{mono:?}");
    for m in &mono {
        assert_eq!(m[3], "failed", "{m:?}");
        assert!(m[5].is_empty() && m[13].contains("monocular tracker never initialised"), "{m:?}");
    }
    assert_eq!(out.status.code(), Some(1), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    // Each graph as written plus every variant: orb_baseline 1 + 10, mg_slam 1 + 10, yg_slam
    // 1 + 6, pspnet_slam 1 + 4, ysag 1 + 4, yoec_dslam 1 + 5.
    assert_eq!(rows.len() + mono.len(), 45, "{rows:?}");
    for r in &rows {
        assert_eq!(r[3], "ok", "{r:?}");
        assert_eq!(r[4], "6", "{r:?}");
        // A number, never NaN or infinite (a run whose ATE is not finite is a failed row).
        assert!(r[5].parse::<f64>().is_ok_and(|a| a.is_finite() && a >= 0.0), "ATE of {r:?}");
        // The oracle variants (ground-truth masks or boxes), and only they, are marked.
        assert_eq!(r[14], (r[1].starts_with("oracle") || r[1] == "masked").to_string(), "{r:?}");
    }
    // Each rule's labels scored against the generator's masks (`label_accuracy`): the mask
    // rule fed the ground-truth mask agrees with it point for point, and the geometric-only
    // row scores its epipolar rule (a precision and a recall, each in 0..=1).
    let labels = |g: &str, v: &str| rows.iter().find(|r| r[0] == g && r[1] == v).unwrap()[15].clone();
    assert!(labels("mg_slam", "oracle").contains("semantic_pr 1.00/1.00"), "{}", labels("mg_slam", "oracle"));
    let g = labels("mg_slam", "G");
    let pr: Vec<f64> = g.strip_prefix("geometric_pr ").unwrap().split('/').map(|v| v.parse().unwrap()).collect();
    assert!(pr.len() == 2 && pr.iter().all(|v| (0.0..=1.0).contains(v)), "{g}");
    assert!(labels("orb_baseline", "base").is_empty());
    let md = std::fs::read_to_string(dir.path().join("bench.md")).unwrap();
    assert!(md.contains("| mg_slam | oracle (oracle) | synthetic |"), "{md}");
    // The improvement over orb_baseline is computed for every other row on the same sequence.
    let seed: Vec<&Vec<String>> = rows.iter().filter(|r| r[0] != "orb_baseline").collect();
    assert!(seed.iter().all(|r| r[12].parse::<f64>().is_ok()), "{seed:?}");
    assert!(stdout.contains("| mg_slam | S+G | synthetic |"), "{stdout}");
    for f in [
        "bench.md",
        "ate.png",
        "time.png",
        "runs/mg_slam-G-synthetic/trajectory.png",
        "runs/pspnet_slam-base-synthetic/pspnet_slam.octomap.ot",
    ] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
}

#[test]
fn a_failed_run_is_a_row_and_the_rest_still_run() {
    let dir = common::TempDir::new("bench-fail");
    let empty = dir.path().join("empty-sequence");
    std::fs::create_dir_all(&empty).unwrap();
    let out = common::bin()
        .arg("bench")
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .args(["--variants", "base", "--no-progress", "--intrinsics", "fr2", "--inputs"])
        .arg(common::repo().join("tests/fixtures/slambook2_rgbd_pair"))
        .arg(&empty)
        .arg("--out")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = csv_rows(&dir.path().join("out/bench.csv"));
    assert_eq!(rows.len(), 2);
    assert_eq!((rows[0][2].as_str(), rows[0][3].as_str()), ("slambook2_rgbd_pair", "ok"));
    assert_eq!((rows[1][2].as_str(), rows[1][3].as_str()), ("empty-sequence", "failed"));
    assert!(rows[1][13].contains("empty-sequence"), "the error names the folder: {:?}", rows[1]);
    // Bad input to the bench itself: exit 2.
    let out = common::bin().args(["bench", "/nonexistent.yaml"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn the_seed_graphs_run_unchanged_on_a_tum_folder() {
    let dir = common::TempDir::new("bench-tum");
    let graphs = ["mg_slam", "yg_slam", "pspnet_slam", "ysag", "yoec_dslam"];
    let out = common::bin()
        .arg("bench")
        .args(graphs.iter().map(|g| common::repo().join(format!("graphs/{g}.yaml"))))
        .args(["--variants", "base", "--no-progress", "--jobs", "2", "--intrinsics", "fr2", "--inputs"])
        .arg(common::repo().join("tests/fixtures/slambook2_rgbd_pair"))
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stdout));
    let rows = csv_rows(&dir.path().join("bench.csv"));
    assert_eq!(rows.len(), graphs.len());
    assert!(rows.iter().all(|r| r[3] == "ok" && r[4] == "2"), "{rows:?}");
}

/// The bench spread as a cluster's array job would spread it: `--list` names the
/// cells, each `--cell I` runs in its own process into its own folder (two "machines" here),
/// and `--collect` merges them into the same tables as one `dynaflow bench` (every column but
/// the wall time per frame, which no two runs share).
#[test]
fn cells_run_apart_and_collected_give_the_one_machine_tables() {
    let dir = common::TempDir::new("bench-cells");
    let graphs = ["orb_baseline", "mg_slam"].map(|g| common::repo().join(format!("graphs/{g}.yaml")));
    let bench = |extra: &[&str], out: &std::path::Path| {
        common::bin()
            .arg("bench")
            .args(&graphs)
            .args(["--variants", "base,S", "--frames", "6", "--no-progress"])
            .args(extra)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let whole = bench(&["--jobs", "2"], &dir.path().join("whole"));
    assert_eq!(whole.status.code(), Some(0), "{}", String::from_utf8_lossy(&whole.stderr));
    let list = bench(&["--list"], &dir.path().join("unused"));
    assert_eq!(list.status.code(), Some(0));
    let list = String::from_utf8_lossy(&list.stdout).into_owned();
    let cells: Vec<&str> = list.lines().filter(|l| !l.starts_with('#') && !l.starts_with("cell\t")).collect();
    // orb_baseline has no variant `S`: its plain graph only; mg_slam as written and `S`.
    assert_eq!(cells.len(), 3, "{list}");
    assert!(cells[2].starts_with("2\tmg_slam\tS\tsynthetic\t"), "{list}");
    assert!(!dir.path().join("unused").exists(), "--list runs nothing");
    for i in 0..cells.len() {
        let machine = dir.path().join(format!("machine{}", i % 2));
        let out = bench(&["--cell", &i.to_string()], &machine);
        assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
        assert!(String::from_utf8_lossy(&out.stdout).starts_with(&format!("cell {i} of 3: ")));
        assert!(!machine.join("bench.csv").exists(), "a cell writes no tables");
    }
    let collected = dir.path().join("collected");
    let out = common::bin()
        .args(["bench", "--collect"])
        .arg(dir.path().join("machine0"))
        .arg(dir.path().join("machine1"))
        .arg("--out")
        .arg(&collected)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let without_time = |rows: Vec<Vec<String>>| -> Vec<Vec<String>> {
        rows.into_iter()
            .map(|mut r| {
                r.remove(11);
                r
            })
            .collect()
    };
    let want = without_time(csv_rows(&dir.path().join("whole/bench.csv")));
    assert_eq!(want.len(), 3);
    assert!(want.iter().all(|r| r[3] == "ok" && r[5].parse::<f64>().is_ok()), "{want:?}");
    assert_eq!(without_time(csv_rows(&collected.join("bench.csv"))), want);
    assert!(collected.join("ate.png").exists() && collected.join("time.png").exists());

    // A missing cell is a failed row naming it, never a shorter table.
    let out = common::bin()
        .args(["bench", "--collect"])
        .arg(dir.path().join("machine0"))
        .arg("--out")
        .arg(dir.path().join("half"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let rows = csv_rows(&dir.path().join("half/bench.csv"));
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[1][3], "failed");
    assert!(
        rows[1][13].contains("cell 1 of 3") && rows[1][13].contains("none of the collected folders"),
        "{:?}",
        rows[1]
    );
    // Cells of another bench (other options) are refused, naming both.
    let other = dir.path().join("other");
    let out = common::bin()
        .arg("bench")
        .arg(&graphs[0])
        .args(["--variants", "base", "--frames", "5", "--no-progress", "--cell", "0", "--out"])
        .arg(&other)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let out = common::bin()
        .args(["bench", "--collect"])
        .arg(dir.path().join("machine0"))
        .arg(&other)
        .arg("--out")
        .arg(dir.path().join("mixed"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("belongs to another bench"), "{err}");
    // A cell out of range: bad input, saying how many there are.
    let out = bench(&["--cell", "3"], &dir.path().join("unused"));
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("this bench has 3"));
}

/// `--compare`: the bench records each run and writes its variants side by side.
#[test]
fn bench_compare_writes_the_variants_side_by_side() {
    let dir = common::TempDir::new("bench-compare");
    let out = common::bin()
        .arg("bench")
        .arg(common::repo().join("graphs/mg_slam.yaml"))
        .args(["--variants", "base,S,G", "--frames", "6", "--jobs", "2", "--no-progress", "--compare", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("compare-mg_slam-synthetic.rrd (3 runs side by side)"), "{stdout}");
    let file = dir.path().join("compare-mg_slam-synthetic.rrd");
    assert!(std::fs::metadata(&file).is_ok_and(|m| m.len() > 100_000), "no comparison recording");
}
