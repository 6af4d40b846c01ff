//! `dynaflow bench GRAPH... [--inputs DIR...] [--variants all|a,b,a+b] [--jobs N] [--out DIR]`:
//! every graph x variant x sequence as its own `dynaflow run` process (spread over `--jobs`),
//! then the papers' tables (markdown and CSV: ATE, RPE, time per frame, improvement over
//! `orb_baseline`) and plots (trajectories against ground truth, ATE per variant, time per
//! node). A failed run is a row marked failed with its error.

use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};

use crate::summary::{NodeReport, Summary};
use dynaflow_engine::LoadRequest;
use dynaflow_engine::files::RunFiles;
use dynaflow_slam::eval::{Align, evaluate};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK};

mod results;

use results::{Row, compare_variants, read_row, report};

/// `dynaflow bench` arguments.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Graph files.
    #[arg(required_unless_present = "collect")]
    pub graphs: Vec<PathBuf>,
    /// Sequences to run each graph on (TUM RGB-D, KITTI or image folders, as `run --input`);
    /// none: each graph's own source (the embedded synthetic scene).
    #[arg(long, num_args = 1..)]
    pub inputs: Vec<PathBuf>,
    /// Intrinsics for `--inputs` (as `run --intrinsics`).
    #[arg(long)]
    pub intrinsics: Option<String>,
    /// Variants: `all` (the graph as written, then each variant), or a comma-separated list
    /// where `base` names the graph as written and `a+b` applies variants `a` then `b`.
    #[arg(long, default_value = "all")]
    pub variants: String,
    /// Runs at a time (each its own process).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub jobs: u64,
    /// Output folder: `bench.md`, `bench.csv`, plots, and one folder per run.
    #[arg(long, default_value = "bench")]
    pub out: PathBuf,
    /// Frames per run (default: each graph's own).
    #[arg(long)]
    pub frames: Option<u64>,
    /// Override a parameter in every run: `node.param=value` (repeatable).
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// No progress bar.
    #[arg(long)]
    pub no_progress: bool,
    /// Print the bench's cells (graph x variant x sequence), one per line with its index, and
    /// run nothing: what a cluster scheduler's array job spreads with `--cell`.
    #[arg(long, conflicts_with_all = ["cell", "collect"])]
    pub list: bool,
    /// Run only cell I (0-based, as `--list` numbers them) into `--out`; no tables. Exit 0
    /// when it completed, 1 when it failed (its `cell.json` says so).
    #[arg(long, value_name = "I", conflicts_with = "collect")]
    pub cell: Option<usize>,
    /// Merge the cells run with `--cell` (each folder a `--out` of them, or one shared
    /// `--out`) into the usual tables and plots in `--out`; no graph arguments needed.
    #[arg(long, value_name = "DIR", num_args = 1..)]
    pub collect: Vec<PathBuf>,
    /// Record each run's MCAP and write, per graph and sequence, `compare-<graph>-<sequence>.rrd`:
    /// its variants side by side (`dynaflow compare`).
    #[arg(long, conflicts_with_all = ["list", "collect"])]
    pub compare: bool,
}

/// One run to do.
#[derive(Clone, Debug)]
struct Job {
    graph: PathBuf,
    name: String,
    variant: Option<String>,
    input: Option<PathBuf>,
    /// The sequence's name in tables and folders, unique among the bench's inputs.
    sequence: String,
    dir: PathBuf,
}

impl Job {
    fn variant_name(&self) -> &str {
        self.variant.as_deref().unwrap_or("base")
    }
    fn sequence(&self) -> String {
        self.sequence.clone()
    }
}

/// A name per input, unique among them: the folder's name (`walking_xyz`), or where two share
/// it (every KITTI sequence folder is `00`, `01`, ... under its own data set) as many of its
/// parents as tell them apart, joined by `-` (`kitti_a-sequences-00`); an input given twice
/// gets its position (`00#2`).
fn sequence_names(inputs: &[PathBuf]) -> Vec<String> {
    let parts = |p: &PathBuf| -> Vec<String> {
        let abs = std::path::absolute(p).unwrap_or_else(|_| p.clone());
        abs.components()
            .filter_map(|c| match c {
                std::path::Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
                _ => None,
            })
            .collect()
    };
    let all: Vec<Vec<String>> = inputs.iter().map(parts).collect();
    let name = |i: usize, depth: usize| -> String {
        let p = &all[i];
        p[p.len().saturating_sub(depth)..].join("-")
    };
    let longest = all.iter().map(Vec::len).max().unwrap_or(1).max(1);
    let mut names: Vec<String> = Vec::with_capacity(inputs.len());
    for i in 0..inputs.len() {
        let mut depth = 1;
        while depth < longest
            && (0..inputs.len()).any(|j| j != i && all[j] != all[i] && name(j, depth) == name(i, depth))
        {
            depth += 1;
        }
        names.push(name(i, depth));
    }
    let mut out: Vec<String> = Vec::with_capacity(names.len());
    for (i, n) in names.iter().enumerate() {
        let repeats = names[..i].iter().filter(|m| *m == n).count();
        out.push(if repeats == 0 { n.clone() } else { format!("{n}#{}", repeats + 1) });
    }
    out
}

fn jobs(args: &BenchArgs) -> Result<Vec<Job>, String> {
    let registry = crate::registry();
    let mut out = Vec::new();
    let inputs: Vec<(Option<PathBuf>, String)> = if args.inputs.is_empty() {
        vec![(None, "synthetic".to_owned())]
    } else {
        args.inputs.iter().cloned().map(Some).zip(sequence_names(&args.inputs)).collect()
    };
    for g in &args.graphs {
        let loaded = dynaflow_engine::load(g, &registry, &LoadRequest::default())
            .map_err(|e| format!("cannot read graph file {}: {e}", g.display()))?;
        if loaded.has_errors() {
            super::print_diagnostics(&loaded);
            return Err(format!("{} does not validate", g.display()));
        }
        let spec = loaded.spec.ok_or_else(|| format!("{}: no graph", g.display()))?;
        let all: Vec<Option<String>> =
            std::iter::once(None).chain(spec.variants.iter().map(|v| Some(v.name.clone()))).collect();
        let wanted: Vec<Option<String>> = if args.variants == "all" {
            all
        } else {
            let mut w = Vec::new();
            for v in args.variants.split(',').map(str::trim).filter(|v| !v.is_empty()) {
                if v == "base" {
                    w.push(None);
                } else if dynaflow_engine::spec::variant_parts(&spec, v).is_some() {
                    w.push(Some(v.to_string()));
                } else if args.graphs.len() == 1 {
                    return Err(format!("{} has no variant `{v}`", g.display()));
                }
            }
            w
        };
        for (input, sequence) in &inputs {
            for v in &wanted {
                let job = Job {
                    graph: g.clone(),
                    name: spec.name.clone(),
                    variant: v.clone(),
                    input: input.clone(),
                    sequence: sequence.clone(),
                    dir: PathBuf::new(),
                };
                let dir = args.out.join("runs").join(format!("{}-{}-{}", job.name, job.variant_name(), job.sequence()));
                out.push(Job { dir, ..job });
            }
        }
    }
    Ok(out)
}

/// What a cell's folder keeps of its job (`cell.json`), for `--collect`.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct CellRecord {
    /// The bench's plan (a digest of every cell's graph, variant, sequence and the run
    /// options): cells of different benches are not merged.
    plan: String,
    cell: usize,
    cells: usize,
    graph: PathBuf,
    name: String,
    variant: Option<String>,
    input: Option<PathBuf>,
    /// The sequence's name in the tables.
    #[serde(default)]
    sequence: String,
    /// The `dynaflow run` process exited 0.
    exit_ok: bool,
}

const CELL_FILE: &str = "cell.json";

/// A digest of the plan: the cells in order and the options every run gets.
fn plan_id(jobs: &[Job], args: &BenchArgs) -> String {
    let mut d = dynaflow_engine::msg::Digest::new();
    for j in jobs {
        d.str(&j.graph.display().to_string());
        d.str(j.variant_name());
        d.str(&j.input.as_ref().map(|p| p.display().to_string()).unwrap_or_default());
    }
    d.str(&format!("{:?}|{:?}|{:?}", args.frames, args.set, args.intrinsics));
    format!("{:016x}", d.finish())
}

/// The bench's running `dynaflow run` children and the signals it has had. Each child runs in
/// a process group of its own, so a terminal's Ctrl-C reaches the bench alone, which passes
/// one SIGINT to each child: the child finishes its in-flight frames and writes its summary and
/// recordings (its row reads "run interrupted"), no new run starts, and the tables of what
/// finished are written. A second signal kills the children at once.
#[derive(Debug, Default)]
struct Interrupt {
    signals: std::sync::atomic::AtomicU32,
    running: Mutex<Vec<u32>>,
}

impl Interrupt {
    fn stopped(&self) -> bool {
        self.signals.load(std::sync::atomic::Ordering::SeqCst) > 0
    }

    /// Pass the signal for the `n`-th interrupt (1: SIGINT, then SIGKILL) to one child.
    fn forward(pid: u32, n: u32) {
        let sig = if n <= 1 { "INT" } else { "KILL" };
        // The `kill` utility: std has no signal but SIGKILL, and the bench needs no unsafe code.
        let _ = Command::new("kill").args(["-s", sig, &pid.to_string()]).stderr(std::process::Stdio::null()).status();
    }

    /// Listen for SIGINT and SIGTERM on a thread of its own for the rest of the process.
    fn watch(self: &Arc<Self>) {
        let state = self.clone();
        let spawned = std::thread::Builder::new().name("bench-signals".into()).spawn(move || {
            let Ok(rt) = tokio::runtime::Builder::new_current_thread().enable_all().build() else { return };
            rt.block_on(async move {
                #[cfg(unix)]
                {
                    use tokio::signal::unix::{SignalKind, signal};
                    let (Ok(mut int), Ok(mut term)) = (signal(SignalKind::interrupt()), signal(SignalKind::terminate()))
                    else {
                        return;
                    };
                    loop {
                        tokio::select! {
                            _ = int.recv() => {}
                            _ = term.recv() => {}
                        }
                        let n = state.signals.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
                        let running = state.running.lock().unwrap_or_else(std::sync::PoisonError::into_inner).clone();
                        if n == 1 {
                            eprintln!(
                                "interrupted: {} runs finish their in-flight frames, no new run starts, then the tables of what finished are written (signal again to kill the runs)",
                                running.len()
                            );
                        } else {
                            eprintln!("killing {} runs", running.len());
                        }
                        for pid in running {
                            Self::forward(pid, n);
                        }
                    }
                }
            });
        });
        if let Err(e) = spawned {
            tracing::warn!("cannot watch for signals ({e}): Ctrl-C will end the bench without its tables");
        }
    }
}

/// Run a job's `dynaflow run` process, keep its stderr and `cell.json`, and read its row.
fn run_one(exe: &Path, job: &Job, args: &BenchArgs, cell: (usize, usize, &str), interrupt: &Interrupt) -> Row {
    if interrupt.stopped() {
        return Row { error: "not run: the bench was interrupted".into(), interrupted: true, ..Row::default() };
    }
    let ok = execute(exe, job, args, interrupt);
    let record = CellRecord {
        plan: cell.2.to_owned(),
        cell: cell.0,
        cells: cell.1,
        graph: job.graph.clone(),
        name: job.name.clone(),
        variant: job.variant.clone(),
        input: job.input.clone(),
        sequence: job.sequence.clone(),
        exit_ok: ok.as_ref().is_ok_and(|ok| *ok),
    };
    if let Ok(text) = serde_json::to_string_pretty(&record) {
        let _ = std::fs::write(job.dir.join(CELL_FILE), text);
    }
    match ok {
        Ok(ok) => read_row(job, ok),
        Err(error) => Row { error, ..Row::default() },
    }
}

/// Run the job; `Ok(exit status was 0)`, `Err` when the process could not start.
fn execute(exe: &Path, job: &Job, args: &BenchArgs, interrupt: &Interrupt) -> Result<bool, String> {
    let _ = std::fs::remove_dir_all(&job.dir);
    let _ = std::fs::create_dir_all(&job.dir);
    let mut cmd = Command::new(exe);
    let record = if args.compare { "mcap" } else { "none" };
    cmd.arg("run").arg(&job.graph).args(["--no-progress", "--record", record, "--out"]).arg(&job.dir);
    if let Some(v) = &job.variant {
        cmd.args(["--variant", v]);
    }
    if let Some(i) = &job.input {
        cmd.arg("--input").arg(i);
        if let Some(k) = &args.intrinsics {
            cmd.args(["--intrinsics", k]);
        }
    }
    if let Some(f) = args.frames {
        cmd.args(["--frames", &f.to_string()]);
    }
    for s in &args.set {
        cmd.args(["--set", s]);
    }
    #[cfg(unix)]
    std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
    cmd.stdin(std::process::Stdio::null()).stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped());
    let child = cmd.spawn().map_err(|e| format!("cannot start {}: {e}", exe.display()))?;
    let pid = child.id();
    interrupt.running.lock().unwrap_or_else(std::sync::PoisonError::into_inner).push(pid);
    // A signal between the check in `run_one` and the registration above still reaches it.
    let signals = interrupt.signals.load(std::sync::atomic::Ordering::SeqCst);
    if signals > 0 {
        Interrupt::forward(pid, signals);
    }
    let out = child.wait_with_output();
    interrupt.running.lock().unwrap_or_else(std::sync::PoisonError::into_inner).retain(|p| *p != pid);
    let out = out.map_err(|e| format!("waiting for {}: {e}", exe.display()))?;
    let _ = std::fs::write(job.dir.join("stderr.txt"), &out.stderr);
    Ok(out.status.success())
}

/// Exit 0 when every run completed, 1 when some failed (the table says which), 2 on bad input.
pub fn bench(args: &BenchArgs) -> u8 {
    if !args.collect.is_empty() {
        return match collect(&args.collect) {
            Ok((jobs, rows)) => report(&jobs, &rows, &args.out),
            Err(e) => {
                eprintln!("error: {e}");
                EXIT_BAD_INPUT
            }
        };
    }
    let jobs = match jobs(args) {
        Ok(j) => j,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    if jobs.is_empty() {
        eprintln!("error: nothing to run (no matching variant)");
        return EXIT_BAD_INPUT;
    }
    let plan = plan_id(&jobs, args);
    if args.list {
        println!("# {} cells, plan {plan}: dynaflow bench ... --cell I runs cell I", jobs.len());
        println!("cell\tgraph\tvariant\tsequence\tfolder");
        for (i, j) in jobs.iter().enumerate() {
            println!("{i}\t{}\t{}\t{}\t{}", j.name, j.variant_name(), j.sequence(), j.dir.display());
        }
        return EXIT_OK;
    }
    if let Err(e) = std::fs::create_dir_all(args.out.join("runs")) {
        eprintln!("error: cannot create {}: {e}", args.out.display());
        return EXIT_BAD_INPUT;
    }
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: cannot find this program: {e}");
            return EXIT_FAILED;
        }
    };
    let interrupt = Arc::new(Interrupt::default());
    interrupt.watch();
    if let Some(i) = args.cell {
        let Some(job) = jobs.get(i) else {
            eprintln!(
                "error: no cell {i}: this bench has {} (0..={}; `--list` prints them)",
                jobs.len(),
                jobs.len() - 1
            );
            return EXIT_BAD_INPUT;
        };
        let row = run_one(&exe, job, args, (i, jobs.len(), &plan), &interrupt);
        let status = if row.ok { "ok".to_owned() } else { format!("failed: {}", row.error) };
        println!(
            "cell {i} of {}: {} {} {}: {status} ({})",
            jobs.len(),
            job.name,
            job.variant_name(),
            job.sequence(),
            job.dir.display()
        );
        return if row.ok { EXIT_OK } else { EXIT_FAILED };
    }
    let bar = if args.no_progress || !std::io::stderr().is_terminal() {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(jobs.len() as u64)
    };
    if let Ok(style) = indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} runs [{elapsed_precise}] {msg}") {
        bar.set_style(style);
    }
    let next = Arc::new(Mutex::new(0usize));
    let rows: Arc<Mutex<Vec<Option<Row>>>> = Arc::new(Mutex::new(vec![None; jobs.len()]));
    std::thread::scope(|s| {
        for _ in 0..args.jobs.min(jobs.len() as u64) {
            s.spawn(|| {
                loop {
                    let i = {
                        let mut n = next.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
                        let i = *n;
                        *n += 1;
                        i
                    };
                    let Some(job) = jobs.get(i) else { break };
                    bar.set_message(format!("{} {} {}", job.name, job.variant_name(), job.sequence()));
                    let row = run_one(&exe, job, args, (i, jobs.len(), &plan), &interrupt);
                    if !row.ok && bar.is_hidden() {
                        eprintln!("failed: {} {} {}: {}", job.name, job.variant_name(), job.sequence(), row.error);
                    }
                    rows.lock().unwrap_or_else(std::sync::PoisonError::into_inner)[i] = Some(row);
                    bar.inc(1);
                }
            });
        }
    });
    bar.finish_and_clear();
    let rows: Vec<Row> = rows
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .iter()
        .map(|r| r.clone().unwrap_or_default())
        .collect();
    let status = report(&jobs, &rows, &args.out);
    if args.compare {
        compare_variants(&jobs, &rows, &args.out);
    }
    if interrupt.stopped() { EXIT_INTERRUPTED } else { status }
}

/// The cells under `dirs` (each a `--out` of `--cell` runs): their jobs and rows in cell
/// order. Cells of two different plans are refused; a cell of the plan that no folder holds is
/// a failed row naming it (never left out).
fn collect(dirs: &[PathBuf]) -> Result<(Vec<Job>, Vec<Row>), String> {
    let mut found: BTreeMap<usize, (CellRecord, PathBuf)> = BTreeMap::new();
    let mut plan: Option<(String, usize, PathBuf)> = None;
    for dir in dirs {
        let runs = dir.join("runs");
        let entries = std::fs::read_dir(&runs).map_err(|e| format!("cannot read {}: {e}", runs.display()))?;
        let mut paths: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
        paths.sort();
        for path in paths {
            let file = path.join(CELL_FILE);
            if !file.exists() {
                continue;
            }
            let text = std::fs::read_to_string(&file).map_err(|e| format!("cannot read {}: {e}", file.display()))?;
            let rec: CellRecord =
                serde_json::from_str(&text).map_err(|e| format!("{}: not a bench cell record: {e}", file.display()))?;
            match &plan {
                None => plan = Some((rec.plan.clone(), rec.cells, file.clone())),
                Some((p, n, first)) if *p != rec.plan || *n != rec.cells => {
                    return Err(format!(
                        "{} belongs to another bench (plan {}, {} cells) than {} (plan {p}, {n} cells): collect the cells of one bench",
                        file.display(),
                        rec.plan,
                        rec.cells,
                        first.display()
                    ));
                }
                Some(_) => {}
            }
            if let Some((_, other)) = found.get(&rec.cell) {
                return Err(format!("cell {} is in both {} and {}", rec.cell, other.display(), path.display()));
            }
            found.insert(rec.cell, (rec, path));
        }
    }
    let Some((plan, cells, _)) = plan else {
        return Err(format!(
            "no bench cells (runs/*/{CELL_FILE}) under {}",
            dirs.iter().map(|d| d.display().to_string()).collect::<Vec<_>>().join(", ")
        ));
    };
    let mut jobs = Vec::new();
    let mut rows = Vec::new();
    for i in 0..cells {
        match found.remove(&i) {
            Some((rec, dir)) => {
                let sequence = if rec.sequence.is_empty() {
                    rec.input
                        .as_ref()
                        .and_then(|p| p.file_name())
                        .map_or_else(|| "synthetic".into(), |n| n.to_string_lossy().into_owned())
                } else {
                    rec.sequence
                };
                let job =
                    Job { graph: rec.graph, name: rec.name, variant: rec.variant, input: rec.input, sequence, dir };
                rows.push(read_row(&job, rec.exit_ok));
                jobs.push(job);
            }
            None => {
                let dir = PathBuf::from(format!("(cell {i})"));
                jobs.push(Job {
                    graph: PathBuf::new(),
                    name: format!("cell {i}"),
                    variant: None,
                    input: None,
                    sequence: String::new(),
                    dir,
                });
                rows.push(Row {
                    error: format!("cell {i} of {cells} (plan {plan}) is in none of the collected folders"),
                    ..Row::default()
                });
            }
        }
    }
    Ok((jobs, rows))
}
