//! The `dynaflow` command line: argument parsing, wiring and exit codes only; the work happens
//! in the `dynaflow-engine`, `dynaflow-operators` and `dynaflow-recordings` crates. In the
//! library so that the binary (`src/main.rs`) and the Python package (`dynaflow.run`) run the
//! same code: [`main_with`].

/// `println!` that ignores a closed standard output (`dynaflow ops | head`): the command's work
/// is done either way, and a panic there would be noise.
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($t)*);
    }};
}

pub(crate) mod commands;
mod control;
mod plot;

pub use commands::eval::read_ground_truth;

use std::path::PathBuf;

use clap::{Parser, Subcommand, ValueEnum};

/// Whether `run` takes SIGINT/SIGTERM (the first stops the run gracefully, a second exits with
/// [`EXIT_INTERRUPTED`]); off when the host process keeps its own (the Python package).
static HANDLE_SIGNALS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Leave SIGINT and SIGTERM to the host process: a host that embeds the command line (Python,
/// whose Ctrl-C raises `KeyboardInterrupt`) calls this before [`main_with`].
pub fn leave_signals_to_the_host() {
    HANDLE_SIGNALS.store(false, std::sync::atomic::Ordering::Relaxed);
}

pub(crate) fn handles_signals() -> bool {
    HANDLE_SIGNALS.load(std::sync::atomic::Ordering::Relaxed)
}

/// Exit status: success.
pub const EXIT_OK: u8 = 0;
/// Exit status: the run failed (operator error, panic, recording failure).
pub const EXIT_FAILED: u8 = 1;
/// Exit status: interrupted by SIGINT/SIGTERM (recordings closed, summary written), as shells expect.
pub const EXIT_INTERRUPTED: u8 = 130;
/// Exit status: bad input (invalid graph, missing file, bad flag).
pub const EXIT_BAD_INPUT: u8 = 2;

#[derive(Debug, Parser)]
#[command(
    name = "dynaflow",
    version,
    about = "Dataflow engine for dynamic-scene visual SLAM",
    propagate_version = true
)]
struct Cli {
    /// More log output (-v debug, -vv trace). RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    /// Only warnings and errors.
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a graph: prints per-node timings and writes `<out>/<name>.summary.json` and recordings.
    Run(RunArgs),
    /// Watch a running graph: per node frames, rate, latency, busy share, queues, drops and
    /// lag, busiest first (`--json` for scripts).
    Top(commands::top::TopArgs),
    /// Change a parameter of a running graph from the node's next frame (recorded, so
    /// `run --set-at` replays it).
    Set(commands::top::SetArgs),
    /// Print a running graph's messages on one port, summarised (sizes, counts, a pose).
    Echo(commands::top::EchoArgs),
    /// Print the rate of one port of a running graph.
    Hz(commands::top::EchoArgs),
    /// Check graph files (and all their variants) without running them.
    Validate {
        /// Graph files.
        #[arg(required = true)]
        graphs: Vec<PathBuf>,
        /// Print diagnostics as JSON.
        #[arg(long)]
        json: bool,
    },
    /// List operators with their ports and parameters.
    Ops {
        /// Output format.
        #[arg(long, value_enum, default_value_t = OpsFormat::Text)]
        format: OpsFormat,
        /// Shorthand for `--format json`.
        #[arg(long, conflicts_with = "format")]
        json: bool,
        /// Shorthand for `--format markdown`.
        #[arg(long, conflicts_with_all = ["format", "json"])]
        markdown: bool,
    },
    /// Run graphs x variants x sequences and tabulate ATE, RPE and time per frame, as papers do.
    Bench(commands::bench::BenchArgs),
    /// Compare two recorded runs (MCAP): per topic, counts, first differing frame, deltas, ATE.
    Diff(commands::diff::DiffArgs),
    /// Join the recordings of a run split over machines into one `.rrd` or MCAP file.
    Merge(commands::merge::MergeArgs),
    /// Recorded runs (an ablation) side by side in one rerun recording: images with their
    /// labels, trajectories against ground truth, per-frame error and dynamic counts.
    Compare(commands::compare::CompareArgs),
    /// Evaluate a trajectory against ground truth (TUM files): ATE and RPE, as evo computes them.
    Eval(commands::eval::EvalArgs),
    /// Run an ONNX detector on images: detections per image as JSON lines.
    Infer(commands::infer::InferArgs),
    /// Run an ONNX segmenter on images: per image a class-id PNG and a JSON of class pixel counts.
    Segment(commands::segment::SegmentArgs),
    /// List a ROS 1 or ROS 2 bag: topics, types, counts, rates, and the topics a run would use.
    Inspect(commands::inspect::InspectArgs),
    /// Summarise an OctoMap file (.ot, .bt) as JSON; `--plot` draws it from above.
    Octree(commands::octree::OctreeArgs),
    /// Generate a semi-synthetic dynamic RGB-D sequence in the TUM layout, with ground truth.
    Synth(commands::synth::SynthArgs),
    /// Bag-of-words vocabularies for ORB descriptors (place recognition).
    #[command(subcommand)]
    Vocab(commands::vocab::VocabCommand),
    /// Open a `.rrd` recording in the rerun viewer (if installed).
    View {
        /// Recording file.
        file: PathBuf,
    },
    /// Draw a graph as Mermaid or Graphviz dot.
    Graph {
        /// Graph file.
        graph: PathBuf,
        /// Output format.
        #[arg(long, value_enum, default_value_t = GraphFormat::Mermaid)]
        format: GraphFormat,
        /// Apply a variant first (repeat, or join with `+`, to apply several in order).
        #[arg(long)]
        variant: Vec<String>,
    },
}

/// `dynaflow run` arguments.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Graph file.
    pub graph: PathBuf,
    /// Output folder for the summary and recordings.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Apply a named variant of the graph; repeated (or joined with `+`: `mono+no_loop`),
    /// several apply in order, and two that set the same thing are an error.
    #[arg(long)]
    pub variant: Vec<String>,
    /// Override a parameter: `node.param=value` (repeatable).
    #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
    pub set: Vec<String>,
    /// Change a parameter while running, from a frame on: `FRAME:node.param=value`
    /// (repeatable; only the parameters an operator declares tunable, `dynaflow ops OP`;
    /// validated as `--set`; recorded in the summary's `parameter_changes`, so a run can be
    /// replayed exactly).
    #[arg(long = "set-at", value_name = "FRAME:NODE.PARAM=VALUE")]
    pub set_at: Vec<String>,
    /// Run on a recorded sequence instead of the graph's own source: a TUM RGB-D folder, a KITTI
    /// odometry sequence, a EuRoC MAV folder, a folder of images, or a ROS 1 / ROS 2 bag
    /// (detected from the files).
    #[arg(long)]
    pub input: Option<PathBuf>,
    /// The topics of a bag given to `--input`, where it has several candidates for a role:
    /// `rgb=/camera/color/image_raw,depth=...,camera_info=...,gt=...` (`gt=tf:PARENT:CHILD`;
    /// `dynaflow inspect BAG` shows the candidates).
    #[arg(long)]
    pub topics: Option<String>,
    /// Camera of `--input`: `fr1`, `fr2`, `fr3`, `fx,fy,cx,cy[,k1,k2,p1,p2,k3]` or a fisheye
    /// `kb:fx,fy,cx,cy,k1,k2,k3,k4` (TUM folders named `rgbd_dataset_freiburgN_*` need none).
    #[arg(long)]
    pub intrinsics: Option<String>,
    /// Override the graph seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Pace sources at sensor rate; `latest` joins take what has arrived.
    #[arg(long)]
    pub realtime: bool,
    /// Stop after this many frames (at least 1).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub frames: Option<u64>,
    /// Recorders (comma-separated): `rrd` (rerun), `mcap` (Foxglove schemas), `ros2` (a rosbag2 bag
    /// ROS tools replay: `<stem>.ros2/`), `jsonl` (message log); `none` records nothing.
    #[arg(long, default_value = "rrd,mcap", value_delimiter = ',')]
    pub record: Vec<String>,
    /// How colour images are stored in recordings: `jpeg` (quality 90), lossless `png`, or
    /// lossless `raw` pixels (fast to write, 8.5x the bytes of JPEG; docs/benchmarks.md).
    #[arg(long, default_value = "jpeg", value_parser = ["jpeg", "png", "raw"])]
    pub image_format: String,
    /// Stream every recorded port to a running rerun viewer or server as the graph runs
    /// (default: rerun's local viewer, `rerun+http://127.0.0.1:9876/proxy`); files are written
    /// as before. A slow or vanished viewer never stalls the run: what it cannot take is
    /// dropped from the stream and counted in the summary.
    #[arg(long, value_name = "URL", num_args = 0..=1, default_missing_value = dynaflow_recordings::live::DEFAULT_URL)]
    pub connect: Option<String>,
    /// Start a local rerun viewer (or use the one already running) and stream to it, as
    /// `--connect`; with `--realtime` this is the "watch it live" mode.
    #[arg(long, conflicts_with = "connect")]
    pub spawn: bool,
    /// MCAP chunk size bound in KiB (a killed run loses at most one chunk, or one second).
    #[arg(long, default_value_t = dynaflow_recordings::mcap::DEFAULT_CHUNK_SIZE / 1024)]
    pub mcap_chunk_kib: u64,
    /// Add per-port content digests to the summary (for comparing runs).
    #[arg(long)]
    pub digest: bool,
    /// Save the whole map at the end (key frames, keypoints, points and the vocabulary's id):
    /// the `save_map` param of the graph's `pnp_track` node.
    #[arg(long, value_name = "FILE")]
    pub save_map: Option<PathBuf>,
    /// Start in a saved map (made with the same vocabulary): the first frames relocalise in it.
    #[arg(long, value_name = "FILE")]
    pub load_map: Option<PathBuf>,
    /// With `--load-map`: ORB-SLAM2's localisation mode (no new key frames, mapping off).
    #[arg(long, requires = "load_map")]
    pub localise: bool,
    /// No progress bar.
    #[arg(long)]
    pub no_progress: bool,
    /// Run this machine's share of a graph with `machines:` (its nodes, with edges to the
    /// others over zenoh; needs the `zenoh` build feature). Without it the whole graph runs
    /// here.
    #[arg(long, value_name = "NAME")]
    pub machine: Option<String>,
    /// With `--machine`: how long to wait for the other machines at the start and at the end.
    #[arg(long, value_name = "SECONDS", default_value_t = 20.0, requires = "machine")]
    pub peer_timeout: f64,
    /// With `--machine` and `tls/` endpoints: this machine's TLS identity, a folder with
    /// `ca.pem` (the authority that signed every machine's certificate), `<machine>.pem` (its
    /// certificate: common name the machine's name, subject alternative names its endpoint's
    /// host) and `<machine>.key`. Peers are mutually authenticated and only the graph's other
    /// machines are admitted (docs/distributed.md).
    #[arg(long, value_name = "DIR", requires = "machine")]
    pub tls: Option<PathBuf>,
    /// With `--machine`: refuse to run over plain TCP (unauthenticated) endpoints.
    #[arg(long, requires = "machine")]
    pub require_tls: bool,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum OpsFormat {
    Text,
    Json,
    Markdown,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum GraphFormat {
    Mermaid,
    Dot,
}

/// Colour only on a terminal, and never when `NO_COLOR` is set to anything (no-color.org).
fn colour_on_stderr() -> bool {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
}

fn init_logging(verbose: u8, quiet: bool) {
    let default = match (quiet, verbose) {
        (true, _) => "warn",
        (false, 0) => "info",
        (false, 1) => "debug",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(colour_on_stderr())
        .with_target(false)
        .without_time()
        // A second command in one process (the Python package) keeps the first one's logger.
        .try_init()
        .ok();
}

/// Run the command line `args` (the first is the program name, as `std::env::args_os`);
/// the exit status.
pub fn main_with<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { EXIT_BAD_INPUT } else { EXIT_OK };
            let _ = e.print();
            return code;
        }
    };
    init_logging(cli.verbose, cli.quiet);
    match cli.command {
        Command::Run(args) => commands::run::run(&args),
        Command::Top(args) => commands::top::top(&args),
        Command::Set(args) => commands::top::set(&args),
        Command::Echo(args) => commands::top::echo(&args),
        Command::Hz(args) => commands::top::hz(&args),
        Command::Validate { graphs, json } => commands::validate::validate(&graphs, json),
        Command::Ops { format, json, markdown } => {
            let format = if json {
                OpsFormat::Json
            } else if markdown {
                OpsFormat::Markdown
            } else {
                format
            };
            commands::ops::ops(&match format {
                OpsFormat::Text => commands::ops::Format::Text,
                OpsFormat::Json => commands::ops::Format::Json,
                OpsFormat::Markdown => commands::ops::Format::Markdown,
            })
        }
        Command::Diff(args) => commands::diff::diff(&args),
        Command::Merge(args) => commands::merge::merge(&args),
        Command::Compare(args) => commands::compare::compare(&args),
        Command::Eval(args) => commands::eval::eval(&args),
        Command::Synth(args) => commands::synth::synth(&args),
        Command::Vocab(c) => commands::vocab::vocab(&c),
        Command::Infer(args) => commands::infer::infer(&args),
        Command::Segment(args) => commands::segment::segment(&args),
        Command::Bench(args) => commands::bench::bench(&args),
        Command::Octree(args) => commands::octree::octree(&args),
        Command::Inspect(args) => commands::inspect::inspect(&args),
        Command::View { file } => commands::view::view(&file),
        Command::Graph { graph, format, variant } => {
            commands::graph::graph(&graph, matches!(format, GraphFormat::Dot), joined_variants(&variant))
        }
    }
}

/// `--variant a --variant b` as one composed variant name, `a+b` (`None` for none).
pub(crate) fn joined_variants(variants: &[String]) -> Option<String> {
    (!variants.is_empty()).then(|| variants.join("+"))
}
