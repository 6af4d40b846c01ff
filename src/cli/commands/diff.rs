//! `dynaflow diff A B`.

use std::path::PathBuf;

use dynaflow_recordings::diff::{self, Tolerance};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow diff` arguments.
#[derive(Debug, clap::Args)]
pub struct DiffArgs {
    /// Recording of run A (`.mcap`).
    pub a: PathBuf,
    /// Recording of run B (`.mcap`).
    pub b: PathBuf,
    /// Tolerance `PATTERN=VALUE` or `PATTERN:METRIC=VALUE` (glob over topics, repeatable),
    /// e.g. `--tol '/track/pose:translation_m=0.01'`. A topic with a tolerance is compared
    /// numerically instead of bit-exactly.
    #[arg(long = "tol", value_name = "PATTERN=VALUE")]
    pub tol: Vec<String>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Write an overlay `.rrd` with both runs under `/a`, `/b` and per-frame `/diff` scalars.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Exit 0 when the runs agree within tolerance, 1 when they differ, 2 on bad input.
pub fn diff(args: &DiffArgs) -> u8 {
    let mut tols = Vec::new();
    for t in &args.tol {
        match t.parse::<Tolerance>() {
            Ok(t) => tols.push(t),
            Err(e) => {
                eprintln!("error: {e}");
                return EXIT_BAD_INPUT;
            }
        }
    }
    if let Some(out) = &args.out {
        let out_ok = dynaflow_engine::files::require_extension("--out", out, "rrd").and_then(|()| {
            dynaflow_engine::files::refuse_overwriting_inputs("--out", out, [args.a.as_path(), args.b.as_path()])
        });
        if let Err(e) = out_ok {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    }
    let (a, b) = match (diff::read_mcap(&args.a), diff::read_mcap(&args.b)) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    let report = diff::diff(&a, &b, &tols);
    if args.json {
        say!("{}", serde_json::to_string_pretty(&report).unwrap_or_default());
    } else {
        print!("{}", report.table());
    }
    if let Some(out) = &args.out {
        if let Err(e) = diff::write_overlay(&a, &b, out) {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
        eprintln!("wrote {} (open with `dynaflow view {}`)", out.display(), out.display());
    }
    if report.same { EXIT_OK } else { EXIT_FAILED }
}
