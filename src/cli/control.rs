//! A run's control endpoint: a Unix-domain socket `<out>/<stem>.sock` (`<stem>.<machine>.sock`
//! for one machine's share of a split run) where `dynaflow top`, `set`, `echo` and `hz` attach.
//! Off the data path: it reads the run's [`Monitor`] and hands parameter changes to it.
//!
//! # Who may attach
//! The socket is made readable and writable by its owner only (mode 0600), and every
//! connection's peer credentials are checked: a process of another user is refused even where
//! the file mode would not stop it (root). The socket is removed when the run ends; one left
//! by a killed run (nobody answers on it) is removed by the next run in the folder, while one
//! that answers means another run writes there, which is refused.
//!
//! # Protocol
//! One JSON request per connection, one line; answers are JSON lines:
//! - `{"op":"snapshot"}` -> `{"ok":true,"snapshot":{..}|null,"peers":[..]}` (`null` while the
//!   operators are being built; `peers`: the other machines' latest snapshots in a split run,
//!   shared over zenoh).
//! - `{"op":"follow","interval_s":1.0}` -> a snapshot line every interval, the last one when
//!   the run has ended (its counts are the summary's).
//! - `{"op":"set","assignment":"node.param=value"}` -> once the node has taken it,
//!   `{"ok":true,"node":..,"param":..,"frame":k,"old":..,"new":..}`, else `{"ok":false,"error":..}`.
//! - `{"op":"echo","port":"node.port"}` -> `{"echo":{..}}` per message, `{"missed":n}` when
//!   the listener fell behind, `{"end":true}` when the run is over.

use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use dynaflow_engine::runtime::Monitor;
use serde_json::json;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader};
use tokio::net::{UnixListener, UnixStream};

/// Checks `node.param=value` as `--set` does and says what it resolves to: node, parameter,
/// value (the error names the command and the parameter's declaration).
pub(crate) type Validate = dyn Fn(&str) -> Result<(String, String, serde_json::Value), String> + Send + Sync;

/// The longest path a Unix-domain socket address holds (`sun_path`, with its terminating NUL).
const SUN_PATH_MAX: usize = 107;

/// How long a closing run waits for its watchers to take their final snapshot.
const FINAL_FLUSH: Duration = Duration::from_secs(1);

/// A listening endpoint; [`Endpoint::close`] ends it and removes the socket.
pub(crate) struct Endpoint {
    path: PathBuf,
    ino: u64,
    accept: tokio::task::JoinHandle<()>,
    connections: Arc<tokio::sync::Mutex<tokio::task::JoinSet<()>>>,
}

/// Open the endpoint at `path` (inside the runtime). `Ok(None)` where a socket cannot be made
/// there for a reason that should not stop the run (a path too long for a socket address), said
/// as a warning; `Err` where another run answers on it.
pub(crate) fn open(path: &Path, monitor: Monitor, validate: Arc<Validate>) -> Result<Option<Endpoint>, String> {
    if path.as_os_str().len() > SUN_PATH_MAX {
        tracing::warn!(
            "no control endpoint: {} is longer than a socket address holds ({SUN_PATH_MAX} bytes); `dynaflow top` cannot attach (run with a shorter --out)",
            path.display()
        );
        return Ok(None);
    }
    clear_stale(path)?;
    let listener =
        UnixListener::bind(path).map_err(|e| format!("cannot open the control socket {}: {e}", path.display()))?;
    // Only the owner may connect (peer credentials are checked too, for whoever the mode lets
    // through).
    let meta = std::fs::metadata(path)
        .and_then(|m| std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600)).map(|()| m))
        .map_err(|e| format!("cannot restrict the control socket {}: {e}", path.display()))?;
    let (owner, ino) = (meta.uid(), meta.ino());
    let connections: Arc<tokio::sync::Mutex<tokio::task::JoinSet<()>>> = Arc::default();
    let conns = connections.clone();
    let accept = tokio::spawn(async move {
        loop {
            let Ok((stream, _)) = listener.accept().await else { continue };
            let (monitor, validate) = (monitor.clone(), validate.clone());
            conns.lock().await.spawn(async move {
                if let Err(e) = serve(stream, owner, monitor, &*validate).await {
                    tracing::debug!("control connection: {e}");
                }
            });
        }
    });
    Ok(Some(Endpoint { path: path.to_path_buf(), ino, accept, connections }))
}

/// A socket a killed run left (nobody answers) is removed, as is a plain file or a link; one
/// that answers belongs to a live run.
fn clear_stale(path: &Path) -> Result<(), String> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_socket() => {
            if std::os::unix::net::UnixStream::connect(path).is_ok() {
                return Err(format!(
                    "another run is writing to this folder: its control socket {} answers (give this run another --out, or wait for it)",
                    path.display()
                ));
            }
            std::fs::remove_file(path)
        }
        Ok(m) if m.is_dir() => return Err(format!("{} is a directory, where the run's control socket goes", path.display())),
        Ok(_) => std::fs::remove_file(path),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e),
    }
    .map_err(|e| format!("cannot replace {}: {e}", path.display()))
}

impl Endpoint {
    /// The run has ended (the monitor says so): let the watchers take their final snapshot,
    /// then stop listening and remove the socket (if it is still ours).
    pub(crate) async fn close(self) {
        self.accept.abort();
        let mut conns = self.connections.lock().await;
        let _ = tokio::time::timeout(FINAL_FLUSH, async { while conns.join_next().await.is_some() {} }).await;
        conns.abort_all();
        if std::fs::symlink_metadata(&self.path).is_ok_and(|m| m.ino() == self.ino) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

async fn serve(stream: UnixStream, owner: u32, monitor: Monitor, validate: &Validate) -> std::io::Result<()> {
    let (read, mut write) = stream.into_split();
    let peer = write.as_ref().peer_cred()?.uid();
    // The request line is read (at most 64 KiB) before anything is answered, a refusal included:
    // answering and closing first could break the client's pipe while it still sends, and it would
    // report that instead of the refusal.
    let mut line = String::new();
    BufReader::new(read.take(64 * 1024)).read_line(&mut line).await?;
    if peer != owner {
        tracing::warn!("control socket: refused a process of user {peer} (the run belongs to user {owner})");
        return send(&mut write, &json!({"ok": false, "error": "refused: this run belongs to another user"})).await;
    }
    let request: serde_json::Value = match serde_json::from_str(line.trim()) {
        Ok(v) => v,
        Err(e) => return send(&mut write, &json!({"ok": false, "error": format!("not a JSON request: {e}")})).await,
    };
    match request["op"].as_str().unwrap_or("") {
        "snapshot" => {
            send(&mut write, &json!({"ok": true, "snapshot": monitor.snapshot(), "peers": monitor.peers()})).await
        }
        "follow" => {
            let interval = Duration::from_secs_f64(request["interval_s"].as_f64().unwrap_or(1.0).clamp(0.05, 60.0));
            loop {
                let ended = tokio::select! {
                    _ = monitor.ended() => true,
                    () = tokio::time::sleep(interval) => false,
                };
                send(&mut write, &json!({"ok": true, "snapshot": monitor.snapshot(), "peers": monitor.peers()}))
                    .await?;
                if ended {
                    return Ok(());
                }
            }
        }
        "set" => {
            let text = request["assignment"].as_str().unwrap_or("");
            let answer = match set(&monitor, validate, text).await {
                Ok(v) => v,
                Err(e) => json!({"ok": false, "error": e}),
            };
            send(&mut write, &answer).await
        }
        "echo" => echo(&mut write, &monitor, request["port"].as_str().unwrap_or("")).await,
        other => {
            let error = format!("unknown request `{other}` (snapshot, follow, set, echo)");
            send(&mut write, &json!({"ok": false, "error": error})).await
        }
    }
}

async fn send(write: &mut tokio::net::unix::OwnedWriteHalf, v: &serde_json::Value) -> std::io::Result<()> {
    let mut line = v.to_string();
    line.push('\n');
    write.write_all(line.as_bytes()).await
}

/// Validate (as `--set`), hand to the node, wait until it has taken the change.
async fn set(monitor: &Monitor, validate: &Validate, text: &str) -> Result<serde_json::Value, String> {
    let (node, param, value) = validate(text)?;
    // A change sent while the operators are still being built waits for them.
    while !monitor.attached() {
        tokio::select! {
            s = monitor.ended() => return Err(format!("the run ended ({s:?}) before its nodes started")),
            () = tokio::time::sleep(Duration::from_millis(20)) => {}
        }
    }
    let reply = monitor.set(&node, &param, value);
    let applied = tokio::select! {
        r = reply => r.map_err(|_| format!("node `{node}` finished its frames before it took the change"))?,
        s = monitor.ended() => return Err(format!("the run ended ({s:?}) before `{node}` took the change")),
    }?;
    Ok(
        json!({"ok": true, "node": node, "param": param, "frame": applied.frame, "old": applied.old, "new": applied.new}),
    )
}

async fn echo(write: &mut tokio::net::unix::OwnedWriteHalf, monitor: &Monitor, port: &str) -> std::io::Result<()> {
    let Some((node, port)) = port.split_once('.') else {
        return send(write, &json!({"ok": false, "error": format!("`{port}`: expected `node.port`")})).await;
    };
    while !monitor.attached() {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut listener = match monitor.echo(node, port) {
        Ok(l) => l,
        Err(e) => return send(write, &json!({"ok": false, "error": e})).await,
    };
    loop {
        let next = tokio::select! {
            n = listener.next() => n,
            _ = monitor.ended() => Ok(None),
        };
        match next {
            Ok(Some(e)) => send(write, &json!({"echo": e})).await?,
            Ok(None) => return send(write, &json!({"end": true})).await,
            Err(missed) => send(write, &json!({"missed": missed})).await?,
        }
    }
}
