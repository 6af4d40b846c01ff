//! `dynaflow eval --gt GT --est EST`.

use std::io::Write;
use std::path::PathBuf;

use dynaflow_datasets::tum::read_trajectory;
use dynaflow_slam::eval::{Align, RpeDelta, Stats, evaluate_with};

use crate::cli::{EXIT_BAD_INPUT, EXIT_OK};

/// `dynaflow eval` arguments.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Ground-truth trajectory: TUM format (`stamp tx ty tz qx qy qz qw`, T_world_camera), or
    /// a EuRoC `state_groundtruth_estimate0/data.csv` (the body's pose, read as evo's `euroc`
    /// format reads it).
    #[arg(long)]
    pub gt: PathBuf,
    /// Estimated trajectory, TUM format.
    #[arg(long)]
    pub est: PathBuf,
    /// Alignment of the estimate before the ATE: `se3` (evo `-a`), `sim3` (evo `-as`, for
    /// monocular scale), `none`.
    #[arg(long, default_value = "se3", value_parser = ["se3", "sim3", "none"])]
    pub align: String,
    /// Largest time difference of associated poses, seconds (evo's `--t_max_diff`).
    #[arg(long, default_value_t = 0.01)]
    pub max_diff: f64,
    /// RPE step (evo's `--delta`): frames, or metres of travelled path with `--rpe-unit m`.
    #[arg(long, default_value_t = 1.0)]
    pub rpe_delta: f64,
    /// Unit of `--rpe-delta` (evo's `--delta_unit f|m`).
    #[arg(long, default_value = "frames", value_parser = ["frames", "m"])]
    pub rpe_unit: String,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also write a plot (PNG): top view of both trajectories and the ATE over time.
    #[arg(long, value_name = "OUT.png")]
    pub plot: Option<PathBuf>,
}

fn row(name: &str, unit: &str, s: &Stats) -> String {
    format!(
        "{name:<16} {:>10.6} {:>10.6} {:>10.6} {:>10.6} {:>10.6} {:>10.6}  {unit}",
        s.rmse, s.mean, s.median, s.std, s.min, s.max
    )
}

/// Whether `path` is a EuRoC ground-truth CSV: its first data line (not blank, not a `#`
/// comment, which may hold commas in either format) has commas (a TUM file separates with
/// spaces).
fn is_euroc_csv(path: &std::path::Path) -> bool {
    use std::io::BufRead;
    std::fs::File::open(path)
        .ok()
        .and_then(|f| {
            std::io::BufReader::new(f).lines().map_while(Result::ok).find(|l| {
                let l = l.trim();
                !l.is_empty() && !l.starts_with('#')
            })
        })
        .is_some_and(|l| l.contains(','))
}

/// A ground-truth trajectory: a EuRoC ground-truth CSV (the body's poses) or a TUM file, told
/// apart by [`is_euroc_csv`]; the error names the file.
pub fn read_ground_truth(path: &std::path::Path) -> Result<Vec<(f64, nalgebra::Isometry3<f64>)>, String> {
    if is_euroc_csv(path) {
        dynaflow_datasets::euroc::read_ground_truth_csv(path)
            .map(|g| g.into_iter().map(|g| (g.stamp, g.world_from_body)).collect())
            .map_err(|e| e.to_string())
    } else {
        read_trajectory(path).map_err(|e| e.to_string())
    }
}

/// Exit 0 with the report, 2 on unreadable or incomparable input.
pub fn eval(args: &EvalArgs) -> u8 {
    let read = |p: &PathBuf| read_trajectory(p).map_err(|e| eprintln!("error: {e}"));
    let read_gt = |p: &PathBuf| read_ground_truth(p).map_err(|e| eprintln!("error: {e}"));
    let (Ok(gt), Ok(est)) = (read_gt(&args.gt), read(&args.est)) else { return EXIT_BAD_INPUT };
    let align = match args.align.as_str() {
        "sim3" => Align::Sim3,
        "none" => Align::None,
        _ => Align::Se3,
    };
    let rpe = if args.rpe_unit == "m" {
        if args.rpe_delta.is_nan() || args.rpe_delta.is_infinite() || args.rpe_delta <= 0.0 {
            eprintln!("error: --rpe-delta in metres must be a positive number");
            return EXIT_BAD_INPUT;
        }
        RpeDelta::Meters(args.rpe_delta)
    } else {
        if args.rpe_delta.is_nan() || args.rpe_delta < 1.0 || args.rpe_delta.fract() != 0.0 || args.rpe_delta >= 1e9 {
            eprintln!("error: --rpe-delta in frames must be a whole number >= 1");
            return EXIT_BAD_INPUT;
        }
        RpeDelta::Frames(args.rpe_delta as usize)
    };
    if !(args.max_diff.is_finite() && args.max_diff >= 0.0) {
        eprintln!("error: --max-diff must be a number of seconds >= 0, got {}", args.max_diff);
        return EXIT_BAD_INPUT;
    }
    let delta = if args.rpe_unit == "m" { format!("{} m", args.rpe_delta) } else { format!("{}", args.rpe_delta) };
    let result = match evaluate_with(&gt, &est, args.max_diff, align, rpe) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {} vs {}: {e}", args.est.display(), args.gt.display());
            return EXIT_BAD_INPUT;
        }
    };
    if result.rpe_translation.count == 0 {
        // evo refuses too: an RPE over no pair is not 0.
        let unit = if args.rpe_unit == "m" { "" } else { " frames" };
        eprintln!(
            "error: {} vs {}: no pair of matched poses is {delta}{unit} apart ({} matched): no RPE; use a smaller --rpe-delta",
            args.est.display(),
            args.gt.display(),
            result.matched
        );
        return EXIT_BAD_INPUT;
    }
    if let Some(path) = &args.plot {
        if let Err(e) =
            dynaflow_engine::files::refuse_overwriting_inputs("--plot", path, [args.gt.as_path(), args.est.as_path()])
        {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
        let title = format!("{} vs {}", args.est.display(), args.gt.display());
        if let Err(e) = crate::cli::plot::evaluation(&result, &title, path) {
            // The path is the user's input: a folder that does not exist, one not writable.
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    }
    // Written with errors ignored: a closed pipe (`| head`) is not a failure of the evaluation.
    let mut out = std::io::stdout().lock();
    if args.json {
        let _ = writeln!(out, "{}", serde_json::to_string_pretty(&result).unwrap_or_default());
        return EXIT_OK;
    }
    let scale_error = if align == Align::Sim3 {
        format!(" (scale error {:.2} %)", (result.scale - 1.0).abs() * 100.0)
    } else {
        String::new()
    };
    let _ = writeln!(
        out,
        "{} of {} estimated poses matched {} ground-truth poses (max diff {} s); alignment {:?}, scale {:.6}{scale_error}",
        result.matched, result.poses[1], result.poses[0], args.max_diff, align, result.scale
    );
    let _ = writeln!(
        out,
        "{:<16} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "", "rmse", "mean", "median", "std", "min", "max"
    );
    let _ = writeln!(out, "{}", row("ATE", "m", &result.ate));
    let _ = writeln!(out, "{}", row(&format!("RPE trans ({delta})"), "m", &result.rpe_translation));
    let _ = writeln!(out, "{}", row(&format!("RPE rot ({delta})"), "deg", &result.rpe_rotation_deg));
    EXIT_OK
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_tum_file_with_a_comma_in_its_comment_is_not_euroc() {
        let dir = std::env::temp_dir().join(format!("dynaflow-eval-sniff-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (tum, csv) = (dir.join("gt.txt"), dir.join("data.csv"));
        // The header dynaflow's own ground-truth files carry, and EuRoC's.
        std::fs::write(
            &tum,
            "# timestamp tx ty tz qx qy qz qw (world_from_cam, dynaflow groundtruth)\n1.0 0 0 0 0 0 0 1\n",
        )
        .unwrap();
        std::fs::write(&csv, "#timestamp, p_RS_R_x [m]\n1000,0,0,0,1,0,0,0,0,0,0,0,0,0,0,0,0\n").unwrap();
        assert!(!super::is_euroc_csv(&tum));
        assert!(super::is_euroc_csv(&csv));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
