//! `dynaflow eval` against evo (PyPI `evo`, in the peers venv): ATE with SE(3), Sim(3) and no
//! alignment and RPE (translation, rotation) equal to 1e-6 on a real TUM-format pair and on
//! generated pairs with noise, gaps, unequal rates and a scale error.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;
#[path = "../vision/tests/common/frontend.rs"]
mod frontend;

use std::path::{Path, PathBuf};
use std::process::Command;

use dynaflow_datasets::tum::read_trajectory;
use dynaflow_slam::eval::{Align, Evaluation, RpeDelta, Stats, evaluate_with};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

fn write_tum(path: &Path, poses: &[(f64, Isometry3<f64>)]) {
    let mut s = String::from("# timestamp tx ty tz qx qy qz qw\n");
    for (t, p) in poses {
        let (v, q) = (p.translation.vector, p.rotation.coords);
        s.push_str(&format!("{t:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}\n", v.x, v.y, v.z, q.x, q.y, q.z, q.w));
    }
    std::fs::write(path, s).unwrap();
}

/// A smooth ground truth (a loop with turning orientation) at `rate` Hz.
fn ground_truth(n: usize, rate: f64) -> Vec<(f64, Isometry3<f64>)> {
    (0..n)
        .map(|i| {
            let t = i as f64 / rate;
            let p = Vector3::new(1.5 * (0.3 * t).cos(), 1.0 * (0.3 * t).sin(), 0.2 * (0.7 * t).sin());
            let q = UnitQuaternion::from_euler_angles(0.1 * (0.5 * t).sin(), 0.2 * (0.3 * t).cos(), 0.3 * t);
            (1_000.0 + t, Isometry3::from_parts(Translation3::from(p), q))
        })
        .collect()
}

/// A deterministic pseudo-random value in [-1, 1).
fn jitter(i: usize, k: u64) -> f64 {
    let mut z = (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ k.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 31)).wrapping_mul(0x94d0_49bb_1331_11eb);
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// An estimate of `gt`: in another frame, scaled, noisy, with stamps off by a few ms, every
/// `step`-th pose, with a gap.
fn estimate(
    gt: &[(f64, Isometry3<f64>)],
    scale: f64,
    noise: f64,
    step: usize,
    gap: std::ops::Range<usize>,
) -> Vec<(f64, Isometry3<f64>)> {
    let offset =
        Isometry3::from_parts(Translation3::new(0.4, -1.0, 0.2), UnitQuaternion::from_euler_angles(0.2, -0.1, 0.7));
    gt.iter()
        .enumerate()
        .filter(|(i, _)| i % step == 0 && !gap.contains(i))
        .map(|(i, (t, p))| {
            let mut q = offset * p;
            q.translation.vector =
                q.translation.vector * scale + Vector3::new(jitter(i, 1), jitter(i, 2), jitter(i, 3)) * noise;
            let dq =
                UnitQuaternion::from_euler_angles(jitter(i, 4) * noise, jitter(i, 5) * noise, jitter(i, 6) * noise);
            q.rotation = dq * q.rotation;
            (t + 0.003 * jitter(i, 7), q)
        })
        .collect()
}

fn close(ours: &Stats, theirs: &serde_json::Value, what: &str) {
    for (name, v) in [
        ("rmse", ours.rmse),
        ("mean", ours.mean),
        ("median", ours.median),
        ("std", ours.std),
        ("min", ours.min),
        ("max", ours.max),
        ("sse", ours.sse),
    ] {
        let t = theirs[name].as_f64().unwrap_or_else(|| panic!("{what}: evo has no {name}: {theirs}"));
        assert!((v - t).abs() <= 1e-6 * t.abs().max(1.0), "{what} {name}: ours {v}, evo {t}");
    }
}

#[test]
fn eval_equals_evo_on_real_and_generated_pairs() {
    let Some(python) = frontend::python_with("evo", "evo", "eval: ATE/RPE vs evo") else { return };
    let dir = common::TempDir::new("eval");
    let fixtures = common::repo().join("tests/fixtures/slambook2_trajectories");
    let gt = ground_truth(600, 30.0);
    let dense_gt = ground_truth(2000, 100.0);
    let real = (fixtures.join("groundtruth.txt"), fixtures.join("estimated.txt"));
    // Frames, and metres of travelled path (evo `--delta_unit m`).
    let mut cases: Vec<(PathBuf, PathBuf, RpeDelta)> = vec![
        (real.0.clone(), real.1.clone(), RpeDelta::Frames(1)),
        (real.0.clone(), real.1.clone(), RpeDelta::Meters(0.1)),
    ];
    for (k, (g, est, delta)) in [
        (&gt, estimate(&gt, 1.0, 0.01, 1, 0..0), 1),
        (&gt, estimate(&gt, 1.0, 0.02, 1, 200..260), 5),
        (&dense_gt, estimate(&dense_gt, 0.5, 0.005, 3, 900..1000), 2),
    ]
    .into_iter()
    .enumerate()
    {
        let (gp, ep) = (dir.path().join(format!("gt{k}.txt")), dir.path().join(format!("est{k}.txt")));
        write_tum(&gp, g);
        write_tum(&ep, &est);
        cases.push((gp.clone(), ep.clone(), RpeDelta::Frames(delta)));
        if k == 1 {
            cases.push((gp, ep, RpeDelta::Meters(0.5)));
        }
    }
    let job: Vec<serde_json::Value> = cases
        .iter()
        .map(|(g, e, d)| {
            let (delta, unit) = match d {
                RpeDelta::Frames(n) => (serde_json::json!(n), "frames"),
                RpeDelta::Meters(m) => (serde_json::json!(m), "m"),
            };
            serde_json::json!({ "gt": g, "est": e, "max_diff": 0.01, "delta": delta, "unit": unit })
        })
        .collect();
    let job_path = dir.path().join("job.json");
    std::fs::write(&job_path, serde_json::Value::Array(job).to_string()).unwrap();
    let out =
        Command::new(&python).arg(common::repo().join("tests/peers/evo_eval.py")).arg(&job_path).output().unwrap();
    assert!(out.status.success(), "evo: {}", String::from_utf8_lossy(&out.stderr));
    let evo: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    for ((g, e, delta), theirs) in cases.iter().zip(&evo) {
        let (gt, est) = (read_trajectory(g).unwrap(), read_trajectory(e).unwrap());
        for (align, key) in [(Align::Se3, "se3"), (Align::Sim3, "sim3"), (Align::None, "none")] {
            let ours: Evaluation = evaluate_with(&gt, &est, 0.01, align, *delta).unwrap();
            let what = format!("{} ({key}, {delta:?})", e.display());
            assert_eq!(ours.matched as u64, theirs["matched"].as_u64().unwrap(), "{what}");
            close(&ours.ate, &theirs[format!("ate_{key}")], &format!("{what} ATE"));
            close(&ours.rpe_translation, &theirs[format!("rpe_t_{key}")], &format!("{what} RPE t"));
            close(&ours.rpe_rotation_deg, &theirs[format!("rpe_r_{key}")], &format!("{what} RPE r"));
        }
    }
}

#[test]
fn eval_cli_reports_and_rejects_bad_input() {
    let fixtures = common::repo().join("tests/fixtures/slambook2_trajectories");
    let out = common::bin()
        .args(["eval", "--json", "--gt"])
        .arg(fixtures.join("groundtruth.txt"))
        .arg("--est")
        .arg(fixtures.join("estimated.txt"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["matched"], 610);
    assert!(v["ate"]["rmse"].as_f64().unwrap() > 0.0);
    // A missing file names it; disjoint times say so.
    let out = common::bin()
        .args(["eval", "--gt", "/nonexistent/gt.txt", "--est"])
        .arg(fixtures.join("estimated.txt"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/gt.txt"));
    let dir = common::TempDir::new("eval-cli");
    let shifted = dir.path().join("shifted.txt");
    write_tum(&shifted, &ground_truth(10, 30.0).into_iter().map(|(t, p)| (t + 1e6, p)).collect::<Vec<_>>());
    let out = common::bin()
        .args(["eval", "--gt"])
        .arg(fixtures.join("groundtruth.txt"))
        .arg("--est")
        .arg(&shifted)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no timestamps"));
}

#[test]
fn eval_plot_is_a_png_of_both_panels_and_a_bad_path_is_an_error() {
    let fixtures = common::repo().join("tests/fixtures/slambook2_trajectories");
    let dir = common::TempDir::new("eval-plot");
    let png = dir.path().join("ate.png");
    let out = common::bin()
        .args(["eval", "--gt"])
        .arg(fixtures.join("groundtruth.txt"))
        .arg("--est")
        .arg(fixtures.join("estimated.txt"))
        .arg("--plot")
        .arg(&png)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let img = image::open(&png).unwrap().into_rgb8();
    assert_eq!(img.dimensions(), (1400, 600));
    // Both curves are drawn: black (ground truth) and red (estimate) in the top view on the
    // left, blue (ATE over time) on the right.
    let count = |x0: u32, x1: u32, want: [u8; 3]| {
        img.enumerate_pixels().filter(|(x, _, p)| (x0..x1).contains(x) && p.0 == want).count()
    };
    assert!(count(0, 620, [255, 0, 0]) > 200, "estimate curve");
    assert!(count(620, 1400, [0, 0, 255]) > 200, "ATE curve");
    let out = common::bin()
        .args(["eval", "--gt"])
        .arg(fixtures.join("groundtruth.txt"))
        .arg("--est")
        .arg(fixtures.join("estimated.txt"))
        .args(["--plot", "/nonexistent/dir/ate.png"])
        .output()
        .unwrap();
    // A path the user gave that cannot be written is bad input (exit 2), not a failed run.
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/dir/ate.png"));
}

#[test]
fn the_ate_a_run_prints_on_a_tum_folder_is_evos() {
    // A TUM folder whose motion capture runs at 100 Hz on its own clock (3.3 ms after the
    // camera's), as the real sequences' do: the run must pair each frame with the pose evo
    // pairs it with (nearest within 10 ms), not with one interpolated at the frame time.
    let Some(python) = frontend::python_with("evo", "evo", "eval: a run's printed ATE vs evo_ape on the folder") else {
        return;
    };
    use dynaflow_datasets::synth::Motion;
    let dir = common::TempDir::new("eval-run-tum");
    let seq = dir.path().join("rgbd_dataset_freiburg3_synthetic");
    let o = common::bin()
        .args(["synth", "--motion", "xyz", "--people", "2", "--frames", "40", "--out"])
        .arg(&seq)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rgb = std::fs::read_to_string(seq.join("rgb.txt")).unwrap();
    let first: f64 =
        rgb.lines().find(|l| !l.starts_with('#')).unwrap().split_whitespace().next().unwrap().parse().unwrap();
    let gt: Vec<(f64, Isometry3<f64>)> =
        (0..150).map(|i| first - 0.1 + 0.0033 + i as f64 * 0.01).map(|t| (t, Motion::Xyz.pose(t - first))).collect();
    write_tum(&seq.join("groundtruth.txt"), &gt);
    let out = dir.path().join("out");
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--out"])
        .arg(&out)
        .arg("--input")
        .arg(&seq)
        .arg(common::repo().join("graphs/orb_baseline.yaml"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let ate = common::summary(&out.join("orb_baseline.summary.json")).ate.unwrap();
    let printed = ate.rmse;
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains(&format!("rmse {printed:.4} m")), "{stdout}");
    let job = serde_json::json!([{
        "gt": seq.join("groundtruth.txt"),
        "est": out.join("orb_baseline.track.trajectory.txt"),
        "max_diff": 0.01, "delta": 1, "unit": "frames"
    }]);
    let job_path = dir.path().join("job.json");
    std::fs::write(&job_path, job.to_string()).unwrap();
    let o = Command::new(&python).arg(common::repo().join("tests/peers/evo_eval.py")).arg(&job_path).output().unwrap();
    assert!(o.status.success(), "evo: {}", String::from_utf8_lossy(&o.stderr));
    let evo: Vec<serde_json::Value> = serde_json::from_slice(&o.stdout).unwrap();
    let theirs = evo[0]["ate_se3"]["rmse"].as_f64().unwrap();
    eprintln!("run's ATE {printed:.9} m, evo_ape on the folder {theirs:.9} m over {} poses", evo[0]["matched"]);
    assert_eq!(Some(ate.pairs), evo[0]["matched"].as_u64());
    assert!((printed - theirs).abs() <= 1e-6 * theirs.max(1e-3), "run {printed}, evo {theirs}");
}

#[test]
fn eval_reads_euroc_ground_truth_as_evo_does_and_reports_the_scale_error() {
    // A EuRoC ground-truth file (200 Hz, nanosecond stamps, `q_RS` as w, x, y, z and the
    // velocity and bias columns) and a monocular-like estimate at 20 Hz: 0.8 times too small,
    // turned and moved, with millimetre noise. `dynaflow eval` reads the CSV as `evo_ape euroc`
    // does: the same pairs and the same Sim(3) ATE, and it prints the scale error.
    let Some(python) = frontend::python_with("evo", "evo", "eval: EuRoC ground truth vs evo_ape euroc") else {
        return;
    };
    use dynaflow_datasets::synth::Motion;
    let dir = common::TempDir::new("eval-euroc");
    let mut csv = String::from(
        "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n",
    );
    for k in 0..1000u64 {
        let p = Motion::Handheld.pose(k as f64 * 0.005);
        let (t, q) = (p.translation.vector, p.rotation);
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},{},0,0,0,0,0,0,0,0,0\n",
            1_403_636_579_763_555_584u64 + k * 5_000_000,
            t.x,
            t.y,
            t.z,
            q.w,
            q.i,
            q.j,
            q.k
        ));
    }
    let gt_path = dir.path().join("data.csv");
    std::fs::write(&gt_path, csv).unwrap();
    let offset =
        Isometry3::from_parts(Translation3::new(0.3, -1.0, 0.2), UnitQuaternion::from_euler_angles(0.1, -0.2, 0.7));
    let est: Vec<(f64, Isometry3<f64>)> = (0..100)
        .map(|k| {
            let mut p = Motion::Handheld.pose(k as f64 * 0.05);
            let j = k as f64;
            let noise = Vector3::new((j * 12.9898).sin(), (j * 78.233).sin(), (j * 37.719).sin()) * 1e-3;
            p.translation.vector = p.translation.vector * 0.8 + noise;
            (1_403_636_579_763_555_584u64 as f64 * 1e-9 + k as f64 * 0.05, offset * p)
        })
        .collect();
    let est_path = dir.path().join("est.txt");
    write_tum(&est_path, &est);
    let out = common::bin()
        .args(["eval", "--align", "sim3", "--json", "--gt"])
        .arg(&gt_path)
        .arg("--est")
        .arg(&est_path)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let ours: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let table = common::bin()
        .args(["eval", "--align", "sim3", "--gt"])
        .arg(&gt_path)
        .arg("--est")
        .arg(&est_path)
        .output()
        .unwrap();
    let table = String::from_utf8_lossy(&table.stdout).into_owned();
    let scale = ours["scale"].as_f64().unwrap();
    assert!(table.contains(&format!("(scale error {:.2} %)", (scale - 1.0).abs() * 100.0)), "{table}");
    let job = serde_json::json!([{
        "gt": gt_path, "gt_format": "euroc", "est": est_path, "max_diff": 0.01, "delta": 1, "unit": "frames"
    }]);
    let job_path = dir.path().join("job.json");
    std::fs::write(&job_path, job.to_string()).unwrap();
    let o = Command::new(&python).arg(common::repo().join("tests/peers/evo_eval.py")).arg(&job_path).output().unwrap();
    assert!(o.status.success(), "evo: {}", String::from_utf8_lossy(&o.stderr));
    let evo: Vec<serde_json::Value> = serde_json::from_slice(&o.stdout).unwrap();
    let (mine, theirs) = (ours["ate"]["rmse"].as_f64().unwrap(), evo[0]["ate_sim3"]["rmse"].as_f64().unwrap());
    eprintln!("EuRoC ground truth: our Sim(3) ATE {mine:.9} m (scale {scale:.6}), evo's {theirs:.9} m");
    assert_eq!(ours["matched"].as_u64(), evo[0]["matched"].as_u64());
    assert_eq!(ours["matched"].as_u64(), Some(100));
    assert!((mine - theirs).abs() <= 1e-6 * theirs.max(1e-3), "ours {mine}, evo {theirs}");
    assert!((scale - 1.25).abs() < 0.01, "the estimate is 0.8 times the truth: scale {scale}");
}

#[test]
fn eval_and_infer_refuse_what_evo_and_the_graph_refuse() {
    // No RPE pair, a NaN time window, thresholds outside 0..=1.
    let fixtures = common::repo().join("tests/fixtures/slambook2_trajectories");
    let eval = |extra: &[&str]| {
        let out = common::bin()
            .args(["eval", "--gt"])
            .arg(fixtures.join("groundtruth.txt"))
            .arg("--est")
            .arg(fixtures.join("estimated.txt"))
            .args(extra)
            .output()
            .unwrap();
        (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let (code, err) = eval(&["--rpe-delta", "100000"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("no pair of matched poses is 100000 frames apart"), "{err}");
    let (code, err) = eval(&["--max-diff", "NaN"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--max-diff"), "{err}");
    let img = common::repo().join("tests/fixtures/slambook2_rgbd_pair/rgb/1.png");
    for (flag, value) in [("--score", "2"), ("--score", "NaN"), ("--iou", "NaN"), ("--iou", "1.5")] {
        let out = common::bin().args(["infer", flag, value]).arg(&img).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(err.contains(&format!("{flag} must be in 0..=1")), "{err}");
    }
}

#[test]
fn an_official_style_tum_file_with_repeated_stamps_reads_and_evaluates_as_evo() {
    // Ground truth as the TUM benchmark publishes it (comment lines,
    // 100 Hz stamps with four decimals, some written twice with two different poses, a gap),
    // an estimate with six decimals at 30 Hz; `dynaflow eval` reads both and equals evo.
    let Some(python) = frontend::python_with("evo", "evo", "eval: TUM file with repeated stamps vs evo") else {
        return;
    };
    let dir = common::TempDir::new("eval-dups");
    let dense = ground_truth(1200, 100.0);
    let mut text = String::from(
        "# ground truth trajectory\n# file: 'rgbd_dataset_freiburg3_walking_xyz.bag'\n# timestamp tx ty tz qx qy qz qw\n",
    );
    let mut repeated = 0;
    for (i, (t, p)) in dense.iter().enumerate() {
        if (500..540).contains(&i) {
            continue; // a motion-capture gap
        }
        let (v, q) = (p.translation.vector, p.rotation.coords);
        let row = |t: f64, dx: f64| {
            format!("{:.4} {:.4} {:.4} {:.4} {:.4} {:.4} {:.4} {:.4}\n", t, v.x + dx, v.y, v.z, q.x, q.y, q.z, q.w)
        };
        text.push_str(&row(1_311_868_164.0 + t, 0.0));
        if i % 97 == 0 {
            text.push_str(&row(1_311_868_164.0 + t, 0.002));
            repeated += 1;
        }
    }
    let gt_path = dir.path().join("groundtruth.txt");
    std::fs::write(&gt_path, text).unwrap();
    let est: Vec<(f64, Isometry3<f64>)> =
        estimate(&dense, 1.0, 0.01, 3, 0..0).into_iter().map(|(t, p)| (1_311_868_164.0 + t, p)).collect();
    let est_path = dir.path().join("estimate.txt");
    write_tum(&est_path, &est);
    let out =
        common::bin().args(["eval", "--json", "--gt"]).arg(&gt_path).arg("--est").arg(&est_path).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains(&format!("{repeated} poses repeat the previous pose's timestamp")), "{stderr}");
    let ours: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let job = serde_json::json!([{ "gt": gt_path, "est": est_path, "max_diff": 0.01, "delta": 1, "unit": "frames" }]);
    let job_path = dir.path().join("job.json");
    std::fs::write(&job_path, job.to_string()).unwrap();
    let o = Command::new(&python).arg(common::repo().join("tests/peers/evo_eval.py")).arg(&job_path).output().unwrap();
    assert!(o.status.success(), "evo: {}", String::from_utf8_lossy(&o.stderr));
    let evo: Vec<serde_json::Value> = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(ours["matched"], evo[0]["matched"]);
    for (key, theirs) in [("ate", "ate_se3"), ("rpe_translation", "rpe_t_se3"), ("rpe_rotation_deg", "rpe_r_se3")] {
        let (a, b) = (ours[key]["rmse"].as_f64().unwrap(), evo[0][theirs]["rmse"].as_f64().unwrap());
        assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "{key}: ours {a}, evo {b}");
    }
}

#[test]
fn a_motionless_estimate_under_sim3_is_called_motionless_not_too_few() {
    // `--align sim3` on an estimate that never moves said "50 matched
    // poses are too few to align (3 needed)". Now it says why no scale fits and what to use;
    // SE(3) and no alignment still evaluate it (a constant estimate has a well-defined ATE:
    // the ground truth's spread about the point it is moved onto).
    let dir = common::TempDir::new("eval-motionless");
    let gt = ground_truth(50, 10.0);
    let still: Vec<_> =
        gt.iter().map(|(t, p)| (*t, Isometry3::from_parts(Translation3::new(1.0, 2.0, 3.0), p.rotation))).collect();
    let (g, e) = (dir.path().join("gt.txt"), dir.path().join("est.txt"));
    write_tum(&g, &gt);
    write_tum(&e, &still);
    let eval = |align: &str| {
        let out = common::bin().args(["eval", "--align", align, "--gt"]).arg(&g).arg("--est").arg(&e).output().unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, _, err) = eval("sim3");
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("the estimate does not move: its 50 matched positions"), "{err}");
    assert!(err.contains("`--align se3`") && !err.contains("too few"), "{err}");
    // Under SE(3) the ATE is the ground truth's spread about its centroid.
    let (code, out, err) = eval("se3");
    assert_eq!(code, Some(0), "{err}");
    let centroid = gt.iter().map(|p| p.1.translation.vector).sum::<Vector3<f64>>() / gt.len() as f64;
    let rmse =
        (gt.iter().map(|p| (p.1.translation.vector - centroid).norm_squared()).sum::<f64>() / gt.len() as f64).sqrt();
    let said: f64 =
        out.lines().find(|l| l.starts_with("ATE")).unwrap().split_whitespace().nth(1).unwrap().parse().unwrap();
    assert!((said - rmse).abs() < 1e-5, "ATE {said} vs the spread {rmse}");
}
