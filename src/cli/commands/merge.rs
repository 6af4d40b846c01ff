//! `dynaflow merge FILE... --out OUT`: the recordings of a run split over machines (each
//! machine's `<stem>.<machine>.rrd` / `.mcap`) joined into one file of the whole run.

use std::path::PathBuf;

use dynaflow_recordings::merge::{Input, merge_mcap, merge_rrd};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow merge` arguments.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// One recording per machine, all `.rrd` or all `.mcap` (`dynaflow run --machine M` writes
    /// `<stem>.M.rrd` and `<stem>.M.mcap`).
    #[arg(required = true, num_args = 2..)]
    pub files: Vec<PathBuf>,
    /// The merged file (same extension).
    #[arg(long)]
    pub out: PathBuf,
    /// Machine names in the order of the files (default: each file's `<stem>.<machine>` part).
    #[arg(long, value_delimiter = ',')]
    pub names: Vec<String>,
}

/// Exit 0 merged, 1 the merge failed while writing, 2 bad input.
pub fn merge(args: &MergeArgs) -> u8 {
    let ext = |p: &PathBuf| p.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    let kind = ext(&args.out);
    if kind != "rrd" && kind != "mcap" {
        eprintln!("error: --out {}: give a `.rrd` or `.mcap` file", args.out.display());
        return EXIT_BAD_INPUT;
    }
    if let Some(f) = args.files.iter().find(|f| ext(f) != kind) {
        eprintln!("error: {} is not a `.{kind}` file like --out: merge each kind on its own", f.display());
        return EXIT_BAD_INPUT;
    }
    if !args.names.is_empty() && args.names.len() != args.files.len() {
        eprintln!("error: --names gives {} names for {} files", args.names.len(), args.files.len());
        return EXIT_BAD_INPUT;
    }
    if let Some(f) = args.files.iter().find(|f| !f.is_file()) {
        eprintln!("error: no such recording: {}", f.display());
        return EXIT_BAD_INPUT;
    }
    // Before anything is written: the error path below removes a half-written `--out`.
    if let Err(e) =
        dynaflow_engine::files::refuse_overwriting_inputs("--out", &args.out, args.files.iter().map(PathBuf::as_path))
    {
        eprintln!("error: {e}");
        return EXIT_BAD_INPUT;
    }
    let inputs: Vec<Input> = args
        .files
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let mut input = Input::from_path(f);
            if let Some(n) = args.names.get(i) {
                input.machine.clone_from(n);
            }
            input
        })
        .collect();
    let merged = if kind == "rrd" { merge_rrd(&inputs, &args.out) } else { merge_mcap(&inputs, &args.out) };
    match merged {
        Ok(n) => {
            let machines: Vec<&str> = inputs.iter().map(|i| i.machine.as_str()).collect();
            println!("merged {n} messages of machines {} into {}", machines.join(", "), args.out.display());
            EXIT_OK
        }
        Err(e) => {
            eprintln!("error: {e}");
            let _ = std::fs::remove_file(&args.out);
            // What the inputs are (another run, unreadable) is bad input; a write error is not.
            if e.starts_with("writing") || e.starts_with("cannot create") { EXIT_FAILED } else { EXIT_BAD_INPUT }
        }
    }
}
