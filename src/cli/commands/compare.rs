//! `dynaflow compare RUN.mcap... [--names a,b,c] --out compare.rrd`: recorded runs (an
//! ablation's variants) in one rerun recording laid out side by side.

use std::path::PathBuf;

use dynaflow_recordings::diff::compare::{read_run, write_compare};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow compare` arguments.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The runs' MCAP recordings; the first is the reference the others part from.
    #[arg(required = true, num_args = 2..)]
    pub runs: Vec<PathBuf>,
    /// Names of the runs, comma-separated, in order (default: each file's stem).
    #[arg(long, value_delimiter = ',')]
    pub names: Vec<String>,
    /// The comparison recording.
    #[arg(long, default_value = "compare.rrd")]
    pub out: PathBuf,
    /// Print the per-run summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Exit 0 written, 1 writing failed, 2 bad input (a run unreadable, runs that do not compare).
pub fn compare(args: &CompareArgs) -> u8 {
    if !args.names.is_empty() && args.names.len() != args.runs.len() {
        eprintln!("error: --names gives {} names for {} runs", args.names.len(), args.runs.len());
        return EXIT_BAD_INPUT;
    }
    let out_ok = dynaflow_engine::files::require_extension("--out", &args.out, "rrd").and_then(|()| {
        dynaflow_engine::files::refuse_overwriting_inputs("--out", &args.out, args.runs.iter().map(PathBuf::as_path))
    });
    if let Err(e) = out_ok {
        eprintln!("error: {e}");
        return EXIT_BAD_INPUT;
    }
    let mut runs = Vec::new();
    for (i, path) in args.runs.iter().enumerate() {
        let name = args.names.get(i).cloned().unwrap_or_else(|| {
            path.file_stem().map_or_else(|| format!("run{i}"), |s| s.to_string_lossy().into_owned())
        });
        match read_run(&name, path) {
            Ok(r) => runs.push(r),
            Err(e) => {
                eprintln!("error: {e}");
                return EXIT_BAD_INPUT;
            }
        }
    }
    match write_compare(&runs, &args.out) {
        Ok(summaries) => {
            if args.json {
                println!("{}", serde_json::to_string_pretty(&summaries).unwrap_or_default());
            } else {
                println!("| run | ATE rmse (cm) | frames | dynamic points / frame | parts from the first |");
                println!("|---|---|---|---|---|");
                for s in &summaries {
                    let ate = s.ate_rmse_m.map_or_else(|| "-".into(), |a| format!("{:.2}", 100.0 * a));
                    let dynamic = s.dynamic_mean.map_or_else(|| "-".into(), |d| format!("{d:.1}"));
                    let parts = s.parts_at.as_ref().map_or_else(|| "-".into(), |(f, t)| format!("frame {f} ({t})"));
                    let oracle = if s.oracle { " (oracle)" } else { "" };
                    println!("| {}{oracle} | {ate} | {} | {dynamic} | {parts} |", s.name, s.frames);
                }
                println!("wrote {}", args.out.display());
            }
            EXIT_OK
        }
        Err(e @ dynaflow_recordings::Error::BadInput { .. }) => {
            eprintln!("error: {e}");
            EXIT_BAD_INPUT
        }
        Err(e) => {
            eprintln!("error: {e}");
            let msg = e.to_string();
            if msg.contains("give") || msg.contains("named") || msg.contains("run name") {
                EXIT_BAD_INPUT
            } else {
                EXIT_FAILED
            }
        }
    }
}
