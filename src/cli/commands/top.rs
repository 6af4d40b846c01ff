//! `dynaflow top`, `set`, `echo` and `hz`: clients of a running graph's control endpoint
//! (`src/cli/control.rs` has the protocol). A run is named by its output folder (every
//! control socket in it) or by a socket; `top` takes several, one per machine of a split run.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use dynaflow_engine::runtime::{LiveState, Snapshot};
use serde_json::json;

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow top` arguments.
#[derive(Debug, clap::Args)]
pub struct TopArgs {
    /// The run's output folder (`--out`), or a control socket (`<out>/<stem>.sock`); several,
    /// for the machines of a split run (each writes `<stem>.<machine>.sock` in its folder).
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Print one snapshot as JSON (`{"runs": [...]}`, one per control socket) and exit.
    #[arg(long)]
    pub json: bool,
    /// With `--json`: a snapshot per line every `--interval` until the run ends; the last
    /// one's counts are the run's summary's.
    #[arg(long, requires = "json")]
    pub follow: bool,
    /// Seconds between refreshes.
    #[arg(long, default_value_t = 1.0)]
    pub interval: f64,
    /// Wait this many seconds for the run's control socket to appear.
    #[arg(long, default_value_t = 0.0)]
    pub wait: f64,
}

/// `dynaflow set` arguments.
#[derive(Debug, clap::Args)]
pub struct SetArgs {
    /// The run's output folder (`--out`), or its control socket.
    pub run: PathBuf,
    /// `node.param=value`: a parameter the node's operator declares tunable (`dynaflow ops`),
    /// validated as `--set`; it applies from the node's next frame, and the frame is recorded.
    pub assignment: String,
    /// Wait this many seconds for the run's control socket to appear.
    #[arg(long, default_value_t = 0.0)]
    pub wait: f64,
}

/// `dynaflow echo` and `hz` arguments.
#[derive(Debug, clap::Args)]
pub struct EchoArgs {
    /// The run's output folder (`--out`), or its control socket.
    pub run: PathBuf,
    /// `node.port`: an output port of a node.
    pub port: String,
    /// Stop after this many messages.
    #[arg(short = 'n', long)]
    pub count: Option<u64>,
    /// Wait this many seconds for the run's control socket to appear.
    #[arg(long, default_value_t = 0.0)]
    pub wait: f64,
}

/// The control sockets `run` names: the socket itself, or every `*.sock` in the folder
/// (waiting up to `wait` seconds for one to appear).
fn sockets(run: &Path, wait: f64) -> Result<Vec<PathBuf>, String> {
    let deadline = Instant::now() + Duration::from_secs_f64(wait.clamp(0.0, 3600.0));
    loop {
        let found: Vec<PathBuf> = if run.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(run)
                .map_err(|e| format!("cannot read {}: {e}", run.display()))?
                .filter_map(Result::ok)
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "sock"))
                .collect();
            v.sort();
            v
        } else if run.exists() {
            vec![run.to_path_buf()]
        } else {
            Vec::new()
        };
        if !found.is_empty() {
            return Ok(found);
        }
        if Instant::now() >= deadline {
            return Err(format!(
                "no run to attach to in {}: no control socket (a run writes `<out>/<stem>.sock` while it runs; `--wait SECONDS` waits for one)",
                run.display()
            ));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The one socket of a run (`set`, `echo`): several are an error naming them.
fn one_socket(run: &Path, wait: f64) -> Result<PathBuf, String> {
    let mut all = sockets(run, wait)?;
    if all.len() > 1 {
        let names: Vec<String> = all.iter().map(|p| p.display().to_string()).collect();
        return Err(format!("{} holds several runs' control sockets; name one: {}", run.display(), names.join(", ")));
    }
    all.pop().ok_or_else(|| format!("no control socket in {}", run.display()))
}

/// Send one request; the answer's lines.
fn request(socket: &Path, req: &serde_json::Value) -> Result<std::io::Lines<BufReader<UnixStream>>, String> {
    let mut stream = UnixStream::connect(socket).map_err(|e| match e.kind() {
        std::io::ErrorKind::ConnectionRefused | std::io::ErrorKind::NotFound => {
            format!("{}: the run is no longer there ({e})", socket.display())
        }
        std::io::ErrorKind::PermissionDenied => {
            format!("{}: refused ({e}): the run belongs to another user", socket.display())
        }
        _ => format!("cannot connect to {}: {e}", socket.display()),
    })?;
    if let Err(e) = stream.write_all(format!("{req}\n").as_bytes()) {
        // A run that refuses the connection may have answered already: its answer says why.
        let mut lines = BufReader::new(stream).lines();
        return match answer(&mut lines, socket) {
            Err(refusal) => Err(refusal),
            Ok(_) => Err(format!("cannot send to {}: {e}", socket.display())),
        };
    }
    Ok(BufReader::new(stream).lines())
}

/// The next answer line as JSON (`None` when the run closed the connection).
fn answer(
    lines: &mut std::io::Lines<BufReader<UnixStream>>,
    socket: &Path,
) -> Result<Option<serde_json::Value>, String> {
    match lines.next() {
        None => Ok(None),
        Some(Err(e)) => Err(format!("{}: {e}", socket.display())),
        Some(Ok(l)) => {
            let v: serde_json::Value =
                serde_json::from_str(&l).map_err(|e| format!("{}: not an answer ({e}): {l}", socket.display()))?;
            if v["ok"] == json!(false) {
                return Err(v["error"].as_str().unwrap_or("refused").to_owned());
            }
            Ok(Some(v))
        }
    }
}

fn snapshot_of(v: &serde_json::Value) -> Option<Snapshot> {
    serde_json::from_value(v["snapshot"].clone()).ok()
}

/// The other machines' snapshots an answer carries (a split run shares them over zenoh).
fn peers_of(v: &serde_json::Value) -> Vec<Snapshot> {
    serde_json::from_value(v["peers"].clone()).unwrap_or_default()
}

/// One snapshot of a socket (`None` while its operators are being built), and the other
/// machines' latest that its run holds.
fn snapshot(socket: &Path) -> Result<(Option<Snapshot>, Vec<Snapshot>), String> {
    let mut lines = request(socket, &json!({"op": "snapshot"}))?;
    let v = answer(&mut lines, socket)?.unwrap_or_default();
    Ok((snapshot_of(&v), peers_of(&v)))
}

/// The other machines' snapshots not among `own`, one per machine.
fn others(own: &[Option<Snapshot>], peers: Vec<Snapshot>) -> Vec<Snapshot> {
    let mut seen: Vec<Option<String>> = own.iter().flatten().map(|s| s.machine.clone()).collect();
    let mut out = Vec::new();
    for p in peers {
        if !seen.contains(&p.machine) {
            seen.push(p.machine.clone());
            out.push(p);
        }
    }
    out
}

fn fail(e: &str) -> u8 {
    eprintln!("error: {e}");
    EXIT_BAD_INPUT
}

/// `dynaflow top`.
pub fn top(args: &TopArgs) -> u8 {
    let mut socks = Vec::new();
    for run in &args.runs {
        match sockets(run, args.wait) {
            Ok(s) => socks.extend(s),
            Err(e) => return fail(&e),
        }
    }
    let interval = Duration::from_secs_f64(args.interval.clamp(0.05, 3600.0));
    if args.json && args.follow {
        return follow(&socks, interval);
    }
    if args.json {
        let (mut own, mut peers) = (Vec::new(), Vec::new());
        for s in &socks {
            match snapshot(s) {
                Ok((snap, p)) => {
                    own.push(snap);
                    peers.extend(p);
                }
                Err(e) => return fail(&e),
            }
        }
        // This process's runs, then the machines only known through them (over zenoh).
        let peers = others(&own, peers);
        say!(
            "{}",
            json!({ "runs": own.iter().map(|s| json!(s)).chain(peers.iter().map(|s| json!(s))).collect::<Vec<_>>() })
        );
        return EXIT_OK;
    }
    watch(&socks, interval)
}

/// `--json --follow`: every socket's snapshot lines, as they come, until each run has ended;
/// following one socket of a split run, the other machines' latest (shared over zenoh) too.
fn follow(socks: &[PathBuf], interval: Duration) -> u8 {
    let with_peers = socks.len() == 1;
    let threads: Vec<_> = socks
        .iter()
        .cloned()
        .map(|s| {
            std::thread::Builder::new().name("dynaflow-top".into()).spawn(move || -> Result<(), String> {
                let mut lines = request(&s, &json!({"op": "follow", "interval_s": interval.as_secs_f64()}))?;
                while let Some(v) = answer(&mut lines, &s)? {
                    say!("{}", v["snapshot"]);
                    for p in peers_of(&v).iter().filter(|_| with_peers) {
                        say!("{}", json!(p));
                    }
                }
                Ok(())
            })
        })
        .collect();
    let mut code = EXIT_OK;
    for t in threads {
        let joined = t.map_err(|e| format!("cannot start a watcher thread: {e}")).and_then(|t| {
            t.join().map_err(|_| "a watcher thread panicked".to_owned()).and_then(std::convert::identity)
        });
        if let Err(e) = joined {
            eprintln!("error: {e}");
            code = EXIT_FAILED;
        }
    }
    code
}

/// Seconds of looks the terminal view's rate ("Hz now") is taken over.
const RATE_WINDOW_S: f64 = 5.0;

/// The terminal view: redrawn every interval until every run has ended (or Ctrl-C).
fn watch(socks: &[PathBuf], interval: Duration) -> u8 {
    // Per socket, the looks of the last RATE_WINDOW_S seconds, oldest first.
    let mut looks: Vec<std::collections::VecDeque<Snapshot>> = vec![Default::default(); socks.len()];
    let mut peers = std::collections::BTreeMap::new();
    loop {
        let mut all_over = true;
        for (i, s) in socks.iter().enumerate() {
            // An error: the run ended between two looks; its last view stays.
            let Ok((snap, shared)) = snapshot(s) else { continue };
            peers.extend(shared.into_iter().map(|p| (p.machine.clone(), p)));
            let Some(snap) = snap else {
                all_over = false;
                continue;
            };
            all_over &= snap.state != LiveState::Running;
            if let Some(window) = looks.get_mut(i) {
                while window.front().is_some_and(|f| f.elapsed_s < snap.elapsed_s - RATE_WINDOW_S) {
                    window.pop_front();
                }
                window.push_back(snap);
            }
        }
        let own: Vec<Option<Snapshot>> = looks.iter().map(|w| w.back().cloned()).collect();
        let shared = others(&own, peers.values().cloned().collect());
        let screen = render(socks, &looks, &shared);
        // Home and clear, then the table: a terminal shows the latest; a pipe gets one per look.
        let mut out = std::io::stdout().lock();
        let _ = write!(out, "\x1b[H\x1b[2J{screen}");
        let _ = out.flush();
        if all_over {
            return EXIT_OK;
        }
        std::thread::sleep(interval);
    }
}

/// One screen: per run (machine), a header and its nodes, busiest first; then the machines of
/// a split run only known through the others (shared over zenoh).
fn render(socks: &[PathBuf], looks: &[std::collections::VecDeque<Snapshot>], shared: &[Snapshot]) -> String {
    let mut s = String::new();
    for (i, sock) in socks.iter().enumerate() {
        let Some(snap) = looks.get(i).and_then(|w| w.back()) else {
            s.push_str(&format!("{}: starting\n\n", sock.display()));
            continue;
        };
        let prev = looks.get(i).and_then(|w| w.front()).filter(|p| p.elapsed_s < snap.elapsed_s);
        s.push_str(&block(snap, prev, ""));
    }
    for snap in shared {
        s.push_str(&block(snap, None, " (shared over zenoh)"));
    }
    s
}

/// One machine's view: a header and its nodes, busiest first; the rate over the looks since
/// `prev` where there is one.
fn block(snap: &Snapshot, prev: Option<&Snapshot>, note: &str) -> String {
    let mut s = String::new();
    {
        let machine = snap.machine.as_deref().map_or(String::new(), |m| format!(" on `{m}`"));
        let total = snap.total_frames.map_or(String::new(), |t| format!("/{t}"));
        let rss = snap.rss_bytes.map_or(String::new(), |b| format!(", {:.0} MiB resident", b as f64 / 1048576.0));
        let variant = snap.variant.as_deref().map_or(String::new(), |v| format!(" ({v})"));
        s.push_str(&format!(
            "{}{variant}{machine}{note}: {:?}, frame {}{total}, {:.1} s{rss}\n",
            snap.graph, snap.state, snap.frames, snap.elapsed_s
        ));
        s.push_str(&format!(
            "{:<16} {:<14} {:>7} {:>7} {:>8} {:>9} {:>9} {:>6} {:>6} {:>7} {:>5}\n",
            "node", "op", "frames", "skipped", "Hz", "p50 ms", "p95 ms", "busy%", "queue", "dropped", "lag"
        ));
        let mut nodes: Vec<_> = snap.nodes.iter().collect();
        nodes.sort_by(|a, b| b.busy_pct.total_cmp(&a.busy_pct).then(b.lag_frames.cmp(&a.lag_frames)));
        for n in nodes {
            // The rate now, over the window's looks; the run's rate until there are two.
            let now =
                prev.and_then(|p| p.nodes.iter().find(|q| q.node == n.node).map(|q| (p, q))).and_then(|(p, q)| {
                    let dt = snap.elapsed_s - p.elapsed_s;
                    (dt > 0.0).then(|| ((n.frames + n.skipped).saturating_sub(q.frames + q.skipped)) as f64 / dt)
                });
            s.push_str(&format!(
                "{:<16} {:<14} {:>7} {:>7} {:>8.1} {:>9.3} {:>9.3} {:>6.1} {:>6} {:>7} {:>5}\n",
                n.node,
                n.op,
                n.frames,
                n.skipped,
                now.unwrap_or(n.rate_hz),
                n.latency.p50_ms,
                n.latency.p95_ms,
                n.busy_pct,
                n.queue,
                n.dropped,
                n.lag_frames
            ));
        }
        s.push('\n');
    }
    s
}

/// `dynaflow set`.
pub fn set(args: &SetArgs) -> u8 {
    let socket = match one_socket(&args.run, args.wait) {
        Ok(s) => s,
        Err(e) => return fail(&e),
    };
    let got = request(&socket, &json!({"op": "set", "assignment": args.assignment}))
        .and_then(|mut lines| answer(&mut lines, &socket));
    match got {
        Ok(Some(v)) => {
            say!(
                "{}.{}: {} -> {} from frame {}",
                v["node"].as_str().unwrap_or("?"),
                v["param"].as_str().unwrap_or("?"),
                v["old"],
                v["new"],
                v["frame"]
            );
            EXIT_OK
        }
        Ok(None) => fail("the run closed the connection before answering"),
        Err(e) => fail(&e),
    }
}

/// Each message of `node.port` as the run emits it: the `echo` answer lines, until the run
/// ends or `count` have come; messages the listener fell behind on are said.
fn listen(args: &EchoArgs, mut each: impl FnMut(&serde_json::Value)) -> u8 {
    let socket = match one_socket(&args.run, args.wait) {
        Ok(s) => s,
        Err(e) => return fail(&e),
    };
    let mut lines = match request(&socket, &json!({"op": "echo", "port": args.port})) {
        Ok(l) => l,
        Err(e) => return fail(&e),
    };
    let mut seen = 0u64;
    loop {
        match answer(&mut lines, &socket) {
            Ok(Some(v)) if v.get("echo").is_some() => {
                each(&v["echo"]);
                seen += 1;
                if args.count.is_some_and(|c| seen >= c) {
                    return EXIT_OK;
                }
            }
            Ok(Some(v)) if v.get("missed").is_some() => {
                eprintln!("warning: {} messages of `{}` not shown (this terminal fell behind)", v["missed"], args.port);
            }
            Ok(_) => return EXIT_OK,
            Err(e) => return fail(&e),
        }
    }
}

/// `dynaflow echo`.
pub fn echo(args: &EchoArgs) -> u8 {
    listen(args, |e| {
        say!("frame {:>6}  stamp {:.4}  {}", e["seq"], e["stamp"].as_f64().unwrap_or(f64::NAN), e["summary"]);
    })
}

/// `dynaflow hz`: the port's rate each second (run time between emissions), and at the end
/// over everything heard.
pub fn hz(args: &EchoArgs) -> u8 {
    let mut times: Vec<f64> = Vec::new();
    let mut shown = Instant::now();
    let code = listen(args, |e| {
        times.push(e["at_s"].as_f64().unwrap_or(0.0));
        if shown.elapsed() >= Duration::from_secs(1) && times.len() >= 2 {
            shown = Instant::now();
            let recent: Vec<f64> = times.iter().rev().take(1 + 200).rev().copied().collect();
            say!("{}", rate_line(&args.port, &recent));
        }
    });
    if times.len() >= 2 {
        say!("{} (whole run heard)", rate_line(&args.port, &times));
    }
    code
}

/// `port: R Hz over N messages (intervals min .. max ms)` for emission times `t` (seconds).
fn rate_line(port: &str, t: &[f64]) -> String {
    let gaps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let span = t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0);
    let rate = if span > 0.0 { gaps.len() as f64 / span } else { 0.0 };
    let min = gaps.iter().copied().fold(f64::INFINITY, f64::min);
    let max = gaps.iter().copied().fold(0.0, f64::max);
    format!("{port}: {rate:.2} Hz over {} messages (intervals {:.1} .. {:.1} ms)", t.len(), min * 1e3, max * 1e3)
}
