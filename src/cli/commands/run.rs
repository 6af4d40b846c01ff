//! `dynaflow run`.

use std::io::IsTerminal;
use std::sync::atomic::Ordering;
use std::time::Duration;

use crate::summary::Summary;
use dynaflow_engine::files::RunFiles;
use dynaflow_engine::runtime::{self, RunOptions, RunStatus};
use dynaflow_engine::sink::{DigestSink, Sink};
use dynaflow_engine::spec::{Override, ResolvedGraph};
use dynaflow_engine::{LoadRequest, SourceOverride};
use dynaflow_recordings::mcap::DEFAULT_FLUSH_INTERVAL;
use dynaflow_recordings::{EncodeCache, ImageCodec, LiveSink, McapSink, MessageLog, Ros2Sink, RrdSink};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, RunArgs};

/// A run that could not start, as a located diagnostic where an operator refused one of its
/// parameters: at the parameter in the file (or its node, for a default), naming the `--set`
/// flag that gave the value if one did.
fn build_error(loaded: &dynaflow_engine::Loaded, req: &LoadRequest, e: &runtime::RunError) -> String {
    use dynaflow_engine::diag::Diagnostic;
    use dynaflow_engine::op::OpError;
    let runtime::RunError::Build { node, source: OpError::Config { key, message } } = e else {
        return format!("error: {e}");
    };
    let spec = loaded.spec.as_ref().and_then(|s| s.nodes.iter().find(|n| &n.id == node));
    let span = spec.map(|n| n.params.iter().find(|(k, _)| &k.text == key).map_or(n.id_span, |(k, _)| k.span));
    // The flag that gave the value: a `--set`, or `--save-map`/`--load-map`/`--localise`.
    let map_flags =
        loaded.spec.as_ref().and_then(|s| req.map.overrides(s, &crate::registry()).ok()).unwrap_or_default();
    let set = req.overrides.iter().chain(&map_flags).rev().find(|o| &o.node == node && &o.param == key);
    let from = set.map_or_else(String::new, |o| format!("`{}`: ", o.text));
    let d = Diagnostic::error("param-value", span, format!("{from}node `{node}`: param `{key}`: {message}"));
    loaded.source.plain(&d)
}

/// `dynaflow run`: load the graph, check where this process's share runs, open the
/// recorders, run, print the results, write the summary; the exit status says how it ended.
pub fn run(args: &RunArgs) -> u8 {
    let req = match load_request(args) {
        Ok(r) => r,
        Err(e) => return bad_input(&e),
    };
    let Some(mut loaded) = super::load_and_report(&args.graph, &req) else {
        return EXIT_BAD_INPUT;
    };
    // The graph runs; the rest of the load stays for locating a build error.
    let Some(graph) = loaded.graph.take() else {
        return EXIT_BAD_INPUT;
    };
    // Changes while running are checked against the text this run loaded, not the file as it
    // may have been edited since.
    let text = GraphText {
        name: loaded.source.name.clone(),
        text: loaded.source.text.clone(),
        base: args.graph.parent().map(std::path::Path::to_path_buf),
        nodes: graph.nodes.iter().map(|n| (n.id.to_string(), n.op)).collect(),
    };
    let schedule = match schedule(args, &text, &req) {
        Ok(s) => s,
        Err(e) => return bad_input(&e),
    };
    if let Err(e) = std::fs::create_dir_all(&args.out) {
        return bad_input(&format!("cannot create output folder {}: {e}", args.out.display()));
    }
    let mut files = RunFiles::new(&args.out, &graph.name, graph.variant.as_deref());
    if let Err(e) = this_machine(&graph, args, &mut files) {
        return bad_input(&e);
    }
    let (sinks, digest) = match recorders(args, &files) {
        Ok(r) => r,
        Err(e) => return bad_input(&e),
    };
    let control = Control { socket: files.run_file("sock"), graph: text, req: req.clone() };
    let report = match execute(&graph, args, sinks, schedule, control) {
        Ok(r) => r,
        Err(Failed::Start(e)) => {
            eprintln!("error: {e}");
            return EXIT_FAILED;
        }
        Err(Failed::Run(e)) => {
            eprintln!("{}", build_error(&loaded, &req, &e));
            return EXIT_BAD_INPUT;
        }
    };
    say!("{}", report.table());
    let oracle = report.oracle.as_ref().map(|uses| {
        say!(
            "(oracle) this run decides with ground truth ({}): its results are a bound, not a system's",
            uses.join("; ")
        );
    });
    let mut summary = Summary::of(report);
    print_trajectory_errors(&summary, if oracle.is_some() { " (oracle)" } else { "" });
    if args.digest {
        summary.digests = Some(digest.snapshot());
    }
    recording_costs(&summary.run.recorders);
    let path = files.summary();
    match summary.write(&path) {
        Ok(()) => tracing::info!("wrote {}", path.display()),
        Err(e) => {
            eprintln!("error: cannot write {}: {e}", path.display());
            return EXIT_FAILED;
        }
    }
    let report = &summary.run;
    for f in &report.failures {
        eprintln!("error: node `{}` failed: {}", f.node, f.error);
    }
    match report.status {
        RunStatus::Completed => EXIT_OK,
        RunStatus::Interrupted => EXIT_INTERRUPTED,
        RunStatus::Failed => EXIT_FAILED,
    }
}

fn bad_input(e: &str) -> u8 {
    eprintln!("error: {e}");
    EXIT_BAD_INPUT
}

/// `--set-at FRAME:node.param=value`, each checked before the run starts as [`assignment`]
/// checks a change.
fn schedule(args: &RunArgs, graph: &GraphText, req: &LoadRequest) -> Result<Vec<runtime::ScheduledSet>, String> {
    let mut out = Vec::new();
    for raw in &args.set_at {
        let flag = format!("--set-at {raw}");
        let (frame, rest) =
            raw.split_once(':').ok_or_else(|| format!("`{flag}`: expected `FRAME:node.param=value`"))?;
        let frame: u64 =
            frame.trim().parse().map_err(|_| format!("`{flag}`: `{frame}` is not a frame number (0, 1, ...)"))?;
        let (node, param, value) = assignment(&flag, rest, graph, req)?;
        out.push(runtime::ScheduledSet { frame, node, param, value });
    }
    Ok(out)
}

/// A change of a parameter while running, `node.param=value`, as `flag` gave it (`--set-at ...`
/// or `dynaflow set ...`): the node exists, its operator declares the parameter tunable, and
/// the value passes the same validation as `--set` (the graph is loaded with it as an
/// override, so an error names the flag and the parameter's declaration). The node, the
/// parameter and the value as validation resolved it.
pub(crate) fn assignment(
    flag: &str,
    text: &str,
    graph_file: &GraphText,
    req: &LoadRequest,
) -> Result<(String, String, serde_json::Value), String> {
    let mut o = Override::parse(text).map_err(|e| e.replace(&format!("--set {text}"), flag))?;
    o.text = flag.to_owned();
    let registry = crate::registry();
    // The run's own graph says which nodes there are and what they run.
    let Some((_, op)) = graph_file.nodes.iter().find(|(id, _)| *id == o.node) else {
        let names: Vec<&str> = graph_file.nodes.iter().map(|(id, _)| id.as_str()).collect();
        return Err(format!("`{flag}`: the graph has no node `{}` (its nodes: {})", o.node, names.join(", ")));
    };
    if op.param(&o.param).is_none() {
        let names: Vec<&str> = op.params.iter().map(|p| p.name).collect();
        return Err(format!(
            "`{flag}`: `{}` (op `{}`) has no parameter `{}` (its parameters: {})",
            o.node,
            op.name,
            o.param,
            names.join(", ")
        ));
    }
    if !op.tunable.contains(&o.param.as_str()) {
        let tunable = if op.tunable.is_empty() {
            "none of its parameters".to_owned()
        } else {
            op.tunable.iter().map(|t| format!("`{t}`")).collect::<Vec<_>>().join(", ")
        };
        return Err(format!(
            "`{flag}`: `{}.{}` cannot change while running: op `{}` declares {tunable} tunable (`dynaflow ops {}`)",
            o.node, o.param, op.name, op.name
        ));
    }
    let mut with = req.clone();
    with.overrides.push(o.clone());
    let loaded =
        dynaflow_engine::load_str(&graph_file.name, &graph_file.text, graph_file.base.clone(), &registry, &with);
    match loaded
        .graph
        .as_ref()
        .and_then(|g| g.nodes.iter().find(|n| *n.id == o.node))
        .and_then(|n| n.params.get(&o.param).cloned())
    {
        Some(value) => Ok((o.node, o.param, value)),
        None => {
            let problems: Vec<String> = loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect();
            Err(format!("`{flag}`: the value is refused:\n{}", problems.join("\n")))
        }
    }
}

/// What the flags ask of the graph's load: `--set`, `--input`, `--variant`, `--seed` and the
/// map flags.
fn load_request(args: &RunArgs) -> Result<LoadRequest, String> {
    let overrides = args.set.iter().map(|s| Override::parse(s).map_err(|e| e.to_string())).collect::<Result<_, _>>()?;
    let source = match &args.input {
        None if args.topics.is_some() => {
            return Err("`--topics` names the topics of a bag given to `--input`; there is no `--input`".into());
        }
        None => None,
        // Relative to the working directory, as typed (graph params resolve against the graph
        // file's folder, so the source gets an absolute path).
        Some(dir) => {
            let layout = dynaflow_operators::decode::detect_layout(
                &std::path::absolute(dir).unwrap_or_else(|_| dir.clone()),
                args.intrinsics.as_deref(),
                args.topics.as_deref(),
            )
            .map_err(|e| e.to_string())?;
            Some(SourceOverride {
                op: layout.op.to_owned(),
                params: layout.params.into_iter().map(|(k, v)| (k.to_owned(), v)).collect(),
                origin: format!("--input {}", dir.display()),
            })
        }
    };
    let map = dynaflow_engine::MapRequest {
        save: args.save_map.clone(),
        load: args.load_map.clone(),
        localise: args.localise,
    };
    Ok(LoadRequest {
        variant: crate::cli::joined_variants(&args.variant),
        overrides,
        seed: args.seed,
        all_variants: false,
        source,
        map,
    })
}

/// With `--machine NAME`: the machine exists, the link settings are sane, and this machine's
/// files are `<stem>.<machine>.*`.
fn this_machine(graph: &ResolvedGraph, args: &RunArgs, files: &mut RunFiles) -> Result<(), String> {
    let Some(m) = &args.machine else {
        if graph.machines.len() > 1 {
            tracing::info!(
                "the graph places its nodes on {} machines; all of them run in this process (`--machine NAME` runs one machine's share)",
                graph.machines.len()
            );
        }
        return Ok(());
    };
    if graph.machines.is_empty() {
        return Err(format!(
            "`--machine {m}`: the graph has no `machines:`, so it runs in one process (leave out --machine)"
        ));
    }
    if !graph.machines.iter().any(|(n, _)| &**n == m) {
        let names: Vec<&str> = graph.machines.iter().map(|(n, _)| &**n).collect();
        return Err(format!("`--machine {m}`: the graph has no such machine (its machines: {})", names.join(", ")));
    }
    if !(args.peer_timeout.is_finite() && args.peer_timeout > 0.0) {
        return Err(format!("`--peer-timeout {}`: give a positive number of seconds", args.peer_timeout));
    }
    if args.require_tls
        && let Some((name, endpoint)) = graph.machines.iter().find(|(_, e)| !e.starts_with("tls/"))
    {
        return Err(format!(
            "`--require-tls`: machine `{name}` listens on `{endpoint}`, plain TCP that anyone who reaches the port can join; write the endpoints `tls/HOST:PORT` and give `--tls DIR`"
        ));
    }
    files.stem = format!("{}.{m}", files.stem);
    Ok(())
}

/// The recorders `--record` names (each once), the live stream, and the digest sink (a sink
/// only with `--digest`; its snapshot goes into the summary).
fn recorders(args: &RunArgs, files: &RunFiles) -> Result<(Vec<Box<dyn Sink>>, DigestSink), String> {
    // Each recorder once: two sinks on one file would interleave into a corrupt file.
    let mut names: Vec<&str> = Vec::new();
    for r in args.record.iter().map(|r| r.trim()) {
        if names.contains(&r) {
            return Err(format!(
                "`--record {}` names `{r}` twice; each recorder writes one file",
                args.record.join(",")
            ));
        }
        names.push(r);
    }
    if names.contains(&"none") && names.len() > 1 {
        return Err("`--record none` cannot be combined with other recorders".into());
    }
    let codec = ImageCodec::from_name(&args.image_format).unwrap_or(ImageCodec::Jpeg(90));
    let live_url = live_stream(args);
    let image_recorders =
        names.iter().filter(|r| matches!(**r, "rrd" | "mcap" | "ros2")).count() + usize::from(live_url.is_some());
    let cache = EncodeCache::new(image_recorders);
    let mut sinks: Vec<Box<dyn Sink>> = Vec::new();
    for r in names {
        match r {
            "jsonl" => sinks.push(Box::new(MessageLog::new(files.run_file("messages.jsonl")))),
            "rrd" => {
                sinks.push(Box::new(RrdSink::new(files.run_file("rrd")).with_codec(codec).with_cache(cache.clone())))
            }
            "mcap" => sinks.push(Box::new(
                McapSink::new(files.run_file("mcap"))
                    .with_codec(codec)
                    .with_cache(cache.clone())
                    .with_chunking(args.mcap_chunk_kib.saturating_mul(1024), DEFAULT_FLUSH_INTERVAL),
            )),
            "ros2" => {
                sinks.push(Box::new(Ros2Sink::new(files.run_file("ros2")).with_codec(codec).with_cache(cache.clone())))
            }
            "none" | "" => {}
            other => return Err(format!("unknown recorder `{other}` (available: rrd, mcap, ros2, jsonl, none)")),
        }
    }
    if let Some(url) = live_url {
        sinks.push(Box::new(LiveSink::new(url).with_codec(codec).with_cache(cache.clone())));
    }
    let digest = DigestSink::default();
    if args.digest {
        sinks.push(Box::new(digest.clone()));
    }
    Ok((sinks, digest))
}

/// Why [`execute`] has no report.
enum Failed {
    /// The async runtime did not start.
    Start(String),
    /// The graph did not build or the machines did not join.
    Run(runtime::RunError),
}

/// The graph text a run loaded (its name and folder, for diagnostics and relative paths), and
/// its resolved nodes' operators.
#[derive(Clone)]
pub(crate) struct GraphText {
    name: String,
    text: std::sync::Arc<str>,
    base: Option<std::path::PathBuf>,
    nodes: Vec<(String, dynaflow_engine::op::OpSpec)>,
}

/// Where the run's control endpoint listens, and what checks a change sent to it.
struct Control {
    socket: std::path::PathBuf,
    graph: GraphText,
    req: LoadRequest,
}

impl Control {
    /// Open the endpoint (inside the runtime); changes are checked as `--set-at` checks them.
    fn open(self, monitor: &runtime::Monitor) -> Result<Option<crate::cli::control::Endpoint>, String> {
        let (graph, req) = (self.graph, self.req);
        let validate: std::sync::Arc<crate::cli::control::Validate> =
            std::sync::Arc::new(move |text: &str| assignment(&format!("dynaflow set {text}"), text, &graph, &req));
        crate::cli::control::open(&self.socket, monitor.clone(), validate)
    }
}

/// Runs the graph on a tokio runtime: signals stop it (a second aborts), a progress bar on a
/// terminal, this machine joined to the others with `--machine`, the control endpoint open.
fn execute(
    graph: &ResolvedGraph,
    args: &RunArgs,
    sinks: Vec<Box<dyn Sink>>,
    schedule: Vec<runtime::ScheduledSet>,
    control: Control,
) -> Result<runtime::RunReport, Failed> {
    let options = RunOptions {
        realtime: args.realtime,
        max_frames: args.frames,
        out_dir: Some(args.out.clone()),
        schedule,
        ..RunOptions::default()
    };
    let monitor = options.monitor.clone();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| Failed::Start(format!("cannot start the async runtime: {e}")))?;
    let show_progress = !args.no_progress && std::io::stderr().is_terminal();
    let result = rt.block_on(async {
        // A second signal aborts at once: the CLI owns the exit code (130, as a shell reports
        // a SIGINT).
        if crate::cli::handles_signals() {
            runtime::stop_on_signals(options.stop.clone(), || std::process::exit(i32::from(EXIT_INTERRUPTED)));
        }
        let endpoint = control.open(&monitor).map_err(runtime::RunError::Remote)?;
        let progress = show_progress.then(|| spawn_progress(&options));
        let mut options = options.clone();
        let wire = match join_machines(graph, args, &monitor).await {
            Ok(w) => w,
            Err(e) => {
                monitor.finish(RunStatus::Failed);
                if let Some(endpoint) = endpoint {
                    endpoint.close().await;
                }
                return Err(runtime::RunError::Remote(e));
            }
        };
        options.placement = wire.as_ref().map(|(p, _)| p.clone());
        let result = runtime::run(graph, options, sinks).await;
        if result.is_err() {
            monitor.finish(RunStatus::Failed);
        }
        if let Some(endpoint) = endpoint {
            endpoint.close().await;
        }
        if let Some((_, finish)) = wire {
            finish.await;
        }
        if let Some((bar, task)) = progress {
            task.abort();
            bar.finish_and_clear();
        }
        result
    });
    // An operator cancelled after a stop may still be inside a blocking call; do not wait
    // for it, the recordings are closed already.
    rt.shutdown_timeout(Duration::from_millis(500));
    result.map_err(Failed::Run)
}

/// Each tracker's ATE, the first in graph order the reference the others are compared with
/// (as a baseline is); a tracker with no trajectory says why.
fn print_trajectory_errors(summary: &Summary, oracle: &str) {
    let mut reference: Option<(&str, f64)> = None;
    for n in &summary.run.nodes {
        let tracker = summary.tracker(&n.node);
        if let Some(why) = tracker.as_ref().and_then(|t| t.not_initialised_because.as_deref()) {
            say!("`{}` has no trajectory: {why}", n.node);
        }
        let Some(ate) = summary.trackers.get(&n.node) else { continue };
        let versus = match reference {
            Some((name, r)) if r > 0.0 => format!(" ({:+.1} % vs `{name}`)", 100.0 * (ate.rmse / r - 1.0)),
            _ => String::new(),
        };
        // Lost frames have no pose (the trajectory leaves them out): say how many.
        let lost = tracker.as_ref().map_or(0, |t| t.frames.lost);
        let lost = if lost > 0 { format!(", {lost} lost frames left out") } else { String::new() };
        say!(
            "ATE of `{}`{oracle} ({} poses{lost}, {} aligned): rmse {:.4} m, mean {:.4} m, median {:.4} m, std {:.4} m{versus}",
            n.node,
            ate.pairs,
            ate.align,
            ate.rmse,
            ate.mean,
            ate.median,
            ate.std
        );
        reference.get_or_insert((&n.node, ate.rmse));
    }
}

/// What joins this process to the other machines of a split run: the placement the runtime
/// uses and what to await once the run is over (the session's orderly end).
type Joined = (runtime::remote::Placement, std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>>);

/// How often a machine of a split run shares its live view with the others (`dynaflow top`).
#[cfg(feature = "zenoh")]
const STATUS_PERIOD: Duration = Duration::from_secs(1);

/// `--machine NAME`: open this machine's zenoh session (`None` without `--machine`), sharing
/// the live view with the other machines (each one's `top` shows them all).
#[cfg(feature = "zenoh")]
async fn join_machines(
    graph: &ResolvedGraph,
    args: &RunArgs,
    monitor: &runtime::Monitor,
) -> Result<Option<Joined>, String> {
    let Some(m) = &args.machine else { return Ok(None) };
    let timeout = Duration::from_secs_f64(args.peer_timeout);
    let tls = args.tls.as_ref().map(|dir| dynaflow_net::Tls { dir: dir.clone() });
    let wire = std::sync::Arc::new(dynaflow_net::ZenohWire::open(graph, m, timeout, tls.as_ref()).await?);
    let status = wire.share_status(monitor.clone(), STATUS_PERIOD).await?;
    let placement = runtime::remote::Placement { machine: m.as_str().into(), wire: wire.clone() };
    Ok(Some((
        placement,
        Box::pin(async move {
            // The final snapshot goes out before the session closes.
            let _ = tokio::time::timeout(timeout, status).await;
            wire.finish().await;
        }),
    )))
}

/// Without the `zenoh` feature `--machine` is refused, saying how to get it.
#[cfg(not(feature = "zenoh"))]
async fn join_machines(
    _graph: &dynaflow_engine::spec::ResolvedGraph,
    args: &RunArgs,
    _monitor: &runtime::Monitor,
) -> Result<Option<Joined>, String> {
    match &args.machine {
        None => Ok(None),
        Some(m) => Err(format!(
            "`--machine {m}`: this dynaflow is built without graphs across machines; build it with `cargo build --release --features zenoh`"
        )),
    }
}

fn spawn_progress(options: &RunOptions) -> (indicatif::ProgressBar, tokio::task::JoinHandle<()>) {
    let bar = indicatif::ProgressBar::with_draw_target(None, indicatif::ProgressDrawTarget::stderr());
    let style = indicatif::ProgressStyle::with_template("{spinner} {pos}/{len} frames [{elapsed_precise}] {per_sec}")
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style);
    let (progress, total, b) = (options.progress.clone(), options.total_frames.clone(), bar.clone());
    let task = tokio::spawn(async move {
        loop {
            let t = total.load(Ordering::Relaxed);
            if t > 0 {
                b.set_length(t);
            }
            b.set_position(progress.load(Ordering::Relaxed));
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
    (bar, task)
}

/// Print what each recording cost per frame and its largest ports, so a user sees what
/// recording takes.
fn recording_costs(recorders: &std::collections::BTreeMap<String, dynaflow_engine::sink::SinkReport>) {
    let kib = |b: f64| b / 1024.0;
    for (name, r) in recorders {
        let dropped: u64 = r.ports.values().map(|p| p.dropped).sum();
        let (Some(file), Some(per_frame)) = (r.file_bytes, r.bytes_per_frame) else {
            let messages: u64 = r.ports.values().map(|p| p.messages).sum();
            if name == "digest" {
                say!("digested {messages} messages of {} ports (the summary's `digests`)", r.ports.len());
            } else {
                say!("streamed {name}: {messages} messages, {dropped} dropped (per port in the summary)");
            }
            continue;
        };
        let mut line = format!("recorded {name}: {:.1} MiB, {:.0} KiB/frame", file as f64 / 1048576.0, kib(per_frame));
        let mut ports: Vec<(&String, f64)> =
            r.ports.iter().filter(|(_, p)| p.bytes > 0).map(|(n, p)| (n, p.bytes_per_frame.unwrap_or(0.0))).collect();
        ports.sort_by(|a, b| b.1.total_cmp(&a.1));
        let top: Vec<String> = ports.iter().take(4).map(|(p, b)| format!("{p} {:.0}", kib(*b))).collect();
        if !top.is_empty() {
            line += &format!("; largest ports before compression (KiB/frame): {}", top.join(", "));
        }
        if dropped > 0 {
            line += &format!("; {dropped} messages dropped (per port in the summary)");
        }
        say!("{line}");
    }
}

/// The viewer URL to stream to (`--connect`, `--spawn`), once it answers; a viewer that cannot
/// be reached or started is a warning, and the run goes on with its files only.
fn live_stream(args: &RunArgs) -> Option<String> {
    if args.spawn {
        // `spawn_viewer` returns once the viewer listens.
        return dynaflow_recordings::live::spawn_viewer()
            .inspect(|url| tracing::info!("streaming to the rerun viewer at {url}"))
            .inspect_err(|e| eprintln!("warning: {e}\n  the run goes on without the live stream"))
            .ok();
    }
    let url = args.connect.clone()?;
    match dynaflow_recordings::live::probe(&url) {
        Ok(()) => {
            tracing::info!("streaming to the rerun viewer at {url}");
            Some(url)
        }
        Err(e) => {
            eprintln!(
                "warning: no rerun viewer at {url} ({e}); the run goes on without the live stream.\n  start one with `rerun` (pip install rerun-sdk==0.36.3), or use `--spawn`"
            );
            None
        }
    }
}
