//! The engine's [`Wire`] over zenoh: one zenoh session per machine of a graph, peer to peer
//! over TCP (unauthenticated: loopback or a trusted network) or over TLS with mutual
//! authentication and access control by certificate name ([`Tls`]).
//!
//! Configuration that fails loudly rather than guessing: each machine *listens* on its own
//! `machines:` endpoint and *connects* to every other machine's endpoint; multicast and gossip
//! scouting are off, so nothing is discovered that the graph file does not name. At start-up
//! each machine declares a liveliness token `dynaflow/<graph>/machine/<name>/<digest>` (the
//! graph digest of [`ResolvedGraph::digest`]) once its subscriptions are in place, and waits
//! for every other machine's token: one that does not come within the timeout is named with
//! its endpoint; one whose digest differs runs another graph (other file, variant, `--set` or
//! `--seed`) and is refused. During the run a machine whose token disappears before its
//! streams ended is an error on the machines that read from it (and a machine that reads our
//! streams gone is an error for us), so a run never waits forever on a dead peer. After the
//! run each machine declares `.../done/<name>` and waits (bounded) until every peer is done or
//! gone before closing its session, so the last frames it published are delivered.
//!
//! Streams are `dynaflow/<graph>/<digest>/data/<node>/<port>`, published with
//! `CongestionControl::Block` (a full receiver slows the sender: lockstep runs lose nothing)
//! into a bounded FIFO on the receiving side.

#![warn(missing_docs)]

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use dynaflow_engine::runtime::remote::{Wire, WireRx, WireTx};
use dynaflow_engine::runtime::{Monitor, Snapshot};
use dynaflow_engine::spec::ResolvedGraph;
use futures::FutureExt;
use futures::future::BoxFuture;
use zenoh::qos::CongestionControl;

/// How long a machine waits for its peers at start-up and at the end, by default.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(20);
/// Frames a subscription holds before the sender waits.
const QUEUE: usize = 64;

/// A machine's TLS identity: the folder given with `dynaflow run --tls DIR`.
///
/// Every machine of the graph holds a certificate signed by one certificate authority (the
/// graph's), whose common name is the machine's name in `machines:` and whose subject
/// alternative names are the hosts of its endpoint. Connections are mutually authenticated
/// (each side checks the other's certificate against the authority, and the connecting side
/// checks the host name), and zenoh's access control admits only the peers whose certificate
/// names one of the graph's other machines: a process with no certificate, one from another
/// authority or one issued to another name cannot join the run nor inject a frame.
#[derive(Clone, Debug)]
pub struct Tls {
    /// The folder.
    pub dir: std::path::PathBuf,
}

impl Tls {
    /// What the folder holds.
    pub const LAYOUT: &str =
        "a folder with `ca.pem` (the authority's certificate) and this machine's `<machine>.pem` and `<machine>.key`";

    /// The zenoh configuration of machine `machine` whose peers are `others`.
    fn zenoh_config(&self, machine: &str, others: &[&str]) -> Result<Vec<(&'static str, String)>, String> {
        let file = |name: String| -> Result<String, String> {
            let path = self.dir.join(&name);
            if !path.is_file() {
                return Err(format!("`--tls {}`: no {} ({})", self.dir.display(), path.display(), Self::LAYOUT));
            }
            let path = std::path::absolute(&path).unwrap_or(path);
            serde_json::to_string(&path.display().to_string()).map_err(|e| e.to_string())
        };
        let (ca, cert, key) =
            (file("ca.pem".into())?, file(format!("{machine}.pem"))?, file(format!("{machine}.key"))?);
        let names = serde_json::to_string(others).map_err(|e| e.to_string())?;
        // Every message kind zenoh's access control knows, on dynaflow's key space only.
        let acl = format!(
            r#"{{
                enabled: true,
                default_permission: "deny",
                rules: [{{
                    id: "graph",
                    messages: ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                               "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"],
                    flows: ["egress", "ingress"],
                    permission: "allow",
                    key_exprs: ["dynaflow/**"],
                }}],
                subjects: [{{ id: "machines", cert_common_names: {names} }}],
                policies: [{{ rules: ["graph"], subjects: ["machines"] }}],
            }}"#
        );
        Ok(vec![
            ("transport/link/tls/root_ca_certificate", ca),
            ("transport/link/tls/listen_certificate", cert.clone()),
            ("transport/link/tls/listen_private_key", key.clone()),
            ("transport/link/tls/connect_certificate", cert),
            ("transport/link/tls/connect_private_key", key),
            ("transport/link/tls/enable_mtls", "true".into()),
            ("transport/link/tls/verify_name_on_connect", "true".into()),
            ("access_control", acl),
        ])
    }
}

/// What the liveliness tokens say of one peer.
#[derive(Clone, Debug, Default)]
struct Peer {
    /// The graph digest of its token, once seen.
    digest: Option<String>,
    /// Its token was seen and has gone.
    gone: bool,
    /// It declared that its run is over.
    done: bool,
}

type Peers = Arc<Mutex<HashMap<String, Peer>>>;

/// Why [`ZenohWire::wait_for`] gave up.
enum Waited {
    /// This machine did not get there in time.
    Timeout(String),
    /// The predicate refused a machine (the message says which and why).
    Refused(String),
}

/// One machine's zenoh session for a graph.
pub struct ZenohWire {
    session: zenoh::Session,
    /// `dynaflow/<graph>`.
    ns: String,
    digest: String,
    machine: String,
    /// The other machines and their endpoints.
    others: Vec<(String, String)>,
    peers: Peers,
    changed: Arc<tokio::sync::Notify>,
    timeout: Duration,
    tokens: Mutex<Vec<zenoh::liveliness::LivelinessToken>>,
    _watch: zenoh::pubsub::Subscriber<()>,
}

fn lock(p: &Peers) -> std::sync::MutexGuard<'_, HashMap<String, Peer>> {
    p.lock().unwrap_or_else(PoisonError::into_inner)
}

impl ZenohWire {
    /// Open `machine`'s session for `graph` (listening on its endpoint, connecting to the
    /// others'), waiting at most `timeout` for peers later on.
    pub async fn open(
        graph: &ResolvedGraph,
        machine: &str,
        timeout: Duration,
        tls: Option<&Tls>,
    ) -> Result<Self, String> {
        let Some((_, endpoint)) = graph.machines.iter().find(|(m, _)| &**m == machine) else {
            let names: Vec<&str> = graph.machines.iter().map(|(m, _)| &**m).collect();
            return Err(format!("the graph has no machine `{machine}` (its machines: {})", names.join(", ")));
        };
        let others: Vec<(String, String)> =
            graph.machines.iter().filter(|(m, _)| &**m != machine).map(|(m, e)| (m.to_string(), e.clone())).collect();
        let mut config = zenoh::Config::default();
        let json = |v: &[&str]| format!("[{}]", v.iter().map(|e| format!("\"{e}\"")).collect::<Vec<_>>().join(","));
        let connect: Vec<&str> = others.iter().map(|(_, e)| e.as_str()).collect();
        for (key, value) in [
            ("mode", "\"peer\"".to_owned()),
            ("listen/endpoints", json(&[endpoint])),
            ("connect/endpoints", json(&connect)),
            ("scouting/multicast/enabled", "false".to_owned()),
            ("scouting/gossip/enabled", "false".to_owned()),
        ] {
            config.insert_json5(key, &value).map_err(|e| format!("zenoh configuration `{key}`: {e}"))?;
        }
        let over_tls = endpoint.starts_with("tls/");
        match (over_tls, tls) {
            (true, None) => {
                return Err(format!(
                    "the graph's endpoints are `tls/`: give this machine's certificates with `--tls DIR` ({})",
                    Tls::LAYOUT
                ));
            }
            (false, Some(_)) => {
                return Err(
                    "`--tls`: the graph's endpoints are `tcp/`; write them `tls/HOST:PORT` to run over TLS".into()
                );
            }
            (true, Some(tls)) => {
                let others: Vec<&str> = others.iter().map(|(m, _)| m.as_str()).collect();
                for (key, value) in tls.zenoh_config(machine, &others)? {
                    config.insert_json5(key, &value).map_err(|e| format!("zenoh configuration `{key}`: {e}"))?;
                }
            }
            (false, None) => {}
        }
        let session = zenoh::open(config)
            .await
            .map_err(|e| format!("machine `{machine}` cannot open its zenoh session on `{endpoint}`: {e}"))?;
        let ns = format!("dynaflow/{}", graph.name);
        let peers: Peers = Arc::default();
        let changed = Arc::new(tokio::sync::Notify::new());
        let (p, c, prefix) = (peers.clone(), changed.clone(), format!("{ns}/"));
        let watch = session
            .liveliness()
            .declare_subscriber(format!("{ns}/**"))
            .history(true)
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let Some(rest) = key.strip_prefix(&prefix) else { return };
                let parts: Vec<&str> = rest.split('/').collect();
                let put = sample.kind() == zenoh::sample::SampleKind::Put;
                let mut peers = lock(&p);
                match parts.as_slice() {
                    ["machine", name, digest] => {
                        let e = peers.entry((*name).to_owned()).or_default();
                        if put {
                            e.digest = Some((*digest).to_owned());
                        } else {
                            e.gone = true;
                        }
                    }
                    ["done", name] if put => peers.entry((*name).to_owned()).or_default().done = true,
                    _ => {}
                }
                drop(peers);
                c.notify_waiters();
            })
            .await
            .map_err(|e| format!("zenoh liveliness subscription: {e}"))?;
        Ok(Self {
            session,
            ns,
            digest: format!("{:016x}", graph.digest()),
            machine: machine.to_owned(),
            others,
            peers,
            changed,
            timeout,
            tokens: Mutex::new(Vec::new()),
            _watch: watch,
        })
    }

    fn endpoint_of(&self, machine: &str) -> &str {
        self.others.iter().find(|(m, _)| m == machine).map_or("?", |(_, e)| e.as_str())
    }

    async fn token(&self, key: String) -> Result<(), String> {
        let t = self.session.liveliness().declare_token(key).await.map_err(|e| format!("zenoh liveliness: {e}"))?;
        self.tokens.lock().unwrap_or_else(PoisonError::into_inner).push(t);
        Ok(())
    }

    /// Wait until `ok(machine, peer)` holds for every other machine, or `deadline`: an error
    /// names the first machine for which it does not ([`Waited::Timeout`]), or carries the
    /// predicate's own refusal ([`Waited::Refused`]).
    async fn wait_for(
        &self,
        deadline: Instant,
        ok: impl Fn(&str, &Peer) -> Result<bool, String>,
    ) -> Result<(), Waited> {
        loop {
            let notified = self.changed.notified();
            let pending = {
                let peers = lock(&self.peers);
                let mut pending = None;
                for (m, _) in &self.others {
                    let p = peers.get(m).cloned().unwrap_or_default();
                    if !ok(m, &p).map_err(Waited::Refused)? {
                        pending = Some(m.clone());
                        break;
                    }
                }
                pending
            };
            let Some(missing) = pending else { return Ok(()) };
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(Waited::Timeout(missing));
            }
            let _ = tokio::time::timeout(left.min(Duration::from_millis(200)), notified).await;
        }
    }

    /// Share this machine's live view (`dynaflow top`) with the others and keep theirs: every
    /// `period` its snapshot goes to `<graph>/top/<machine>` as JSON, and the others' are
    /// handed to `monitor` as they come. The task ends after sending the final snapshot once
    /// the run has ended; await it before [`ZenohWire::finish`], so the others get it.
    pub async fn share_status(
        &self,
        monitor: Monitor,
        period: Duration,
    ) -> Result<tokio::task::JoinHandle<()>, String> {
        let prefix = format!("{}/top/", self.ns);
        let own = format!("{prefix}{}", self.machine);
        let (m, me, p) = (monitor.clone(), self.machine.clone(), prefix.clone());
        let subscriber = self
            .session
            .declare_subscriber(format!("{prefix}*"))
            .callback(move |sample| {
                let from = sample.key_expr().as_str().strip_prefix(&p).unwrap_or_default();
                if from == me {
                    return;
                }
                match serde_json::from_slice::<Snapshot>(&sample.payload().to_bytes()) {
                    Ok(snapshot) if snapshot.machine.as_deref() == Some(from) => m.set_peer(snapshot),
                    Ok(_) => tracing::warn!("a status on `{from}`'s key names another machine; ignored"),
                    Err(e) => tracing::warn!("machine `{from}` sent a status that does not read: {e}"),
                }
            })
            .await
            .map_err(|e| format!("zenoh status subscription: {e}"))?;
        let session = self.session.clone();
        Ok(tokio::spawn(async move {
            // The subscription lives as long as the sharing does.
            let _subscriber = subscriber;
            loop {
                let ended = tokio::select! {
                    _ = monitor.ended() => true,
                    () = tokio::time::sleep(period) => false,
                };
                if let Some(json) = monitor.snapshot().and_then(|s| serde_json::to_vec(&s).ok())
                    && let Err(e) = session.put(&own, json).await
                {
                    tracing::debug!("status not shared: {e}");
                }
                if ended {
                    return;
                }
            }
        }))
    }

    /// After the run: say so, and wait (at most the timeout) until every peer has said so or
    /// is gone, so what this machine published last reaches them; then close the session.
    pub async fn finish(&self) {
        let _ = self.token(format!("{}/done/{}", self.ns, self.machine)).await;
        let deadline = Instant::now() + self.timeout;
        if let Err(Waited::Timeout(m)) =
            self.wait_for(deadline, |_, p| Ok(p.done || p.gone || p.digest.is_none())).await
        {
            tracing::warn!("machine `{m}` did not finish within {:.0} s; closing anyway", self.timeout.as_secs_f64());
        }
        let _ = self.session.close().await;
    }
}

struct Tx {
    publisher: zenoh::pubsub::Publisher<'static>,
    to: Vec<String>,
    peers: Peers,
    key: String,
    endpoints: Vec<String>,
}

struct Rx {
    subscriber: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    from: String,
    endpoint: String,
    peers: Peers,
    changed: Arc<tokio::sync::Notify>,
}

impl Wire for ZenohWire {
    fn publisher<'a>(&'a self, key: &'a str, to: &'a [Arc<str>]) -> BoxFuture<'a, Result<Box<dyn WireTx>, String>> {
        async move {
            let full = format!("{}/{}/data/{key}", self.ns, self.digest);
            let publisher = self
                .session
                .declare_publisher(full.clone())
                .congestion_control(CongestionControl::Block)
                .await
                .map_err(|e| format!("zenoh publisher `{full}`: {e}"))?;
            // The readers declared their subscriptions before their tokens; wait until the
            // routing has them, so no frame is published into the void.
            let deadline = Instant::now() + self.timeout;
            loop {
                let matching = publisher.matching_status().await.map_err(|e| format!("zenoh matching: {e}"))?;
                if matching.matching() {
                    break;
                }
                if Instant::now() >= deadline {
                    let names: Vec<&str> = to.iter().map(|m| &**m).collect();
                    return Err(format!(
                        "no subscriber for stream `{key}` on machine(s) {} after {:.0} s",
                        names.join(", "),
                        self.timeout.as_secs_f64()
                    ));
                }
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
            Ok(Box::new(Tx {
                publisher,
                to: to.iter().map(|m| m.to_string()).collect(),
                peers: self.peers.clone(),
                key: key.to_owned(),
                endpoints: to.iter().map(|m| self.endpoint_of(m).to_owned()).collect(),
            }) as Box<dyn WireTx>)
        }
        .boxed()
    }

    fn subscriber<'a>(&'a self, key: &'a str, from: &'a str) -> BoxFuture<'a, Result<Box<dyn WireRx>, String>> {
        async move {
            let full = format!("{}/{}/data/{key}", self.ns, self.digest);
            let subscriber = self
                .session
                .declare_subscriber(full.clone())
                .with(zenoh::handlers::FifoChannel::new(QUEUE))
                .await
                .map_err(|e| format!("zenoh subscriber `{full}`: {e}"))?;
            Ok(Box::new(Rx {
                subscriber,
                from: from.to_owned(),
                endpoint: self.endpoint_of(from).to_owned(),
                peers: self.peers.clone(),
                changed: self.changed.clone(),
            }) as Box<dyn WireRx>)
        }
        .boxed()
    }

    fn ready(&self) -> BoxFuture<'_, Result<(), String>> {
        async move {
            self.token(format!("{}/machine/{}/{}", self.ns, self.machine, self.digest)).await?;
            let deadline = Instant::now() + self.timeout;
            let here = &self.digest;
            let checked = self
                .wait_for(deadline, |m, p| match &p.digest {
                    Some(d) if d != here => Err(format!(
                        "machine `{m}` ({}) runs a different graph (digest {d} there, {here} here): start every machine with the same graph file, variant, --set and --seed",
                        self.endpoint_of(m)
                    )),
                    Some(_) => Ok(true),
                    None => Ok(false),
                })
                .await;
            match checked {
                Ok(()) => Ok(()),
                Err(Waited::Refused(why)) => Err(why),
                Err(Waited::Timeout(m)) => {
                    let endpoint = self.endpoint_of(&m);
                    // Over TLS a peer whose certificate does not hold is refused by the
                    // handshake or the access control, and looks to this side like no peer.
                    let tls = if endpoint.starts_with("tls/") {
                        format!(
                            "; over TLS a peer is refused unless its certificate is signed by this graph's `ca.pem` and issued to `{m}` (the warnings above name a failed handshake)"
                        )
                    } else {
                        String::new()
                    };
                    Err(format!(
                        "machine `{m}` ({endpoint}) did not join within {:.0} s: start `dynaflow run GRAPH --machine {m}` there, and check that its endpoint is reachable from here{tls}",
                        self.timeout.as_secs_f64(),
                    ))
                }
            }
        }
        .boxed()
    }
}

impl WireTx for Tx {
    fn send(&self, frame: Vec<u8>) -> BoxFuture<'_, Result<(), String>> {
        async move {
            {
                let peers = lock(&self.peers);
                if let Some((m, e)) =
                    self.to.iter().zip(&self.endpoints).find(|(m, _)| peers.get(*m).is_some_and(|p| p.gone))
                {
                    return Err(format!("machine `{m}` ({e}), which reads `{}`, is gone", self.key));
                }
            }
            self.publisher.put(frame).await.map_err(|e| format!("zenoh put: {e}"))
        }
        .boxed()
    }
}

impl WireRx for Rx {
    fn recv(&mut self) -> BoxFuture<'_, Result<Vec<u8>, String>> {
        async move {
            loop {
                let notified = self.changed.notified();
                // What already arrived comes first: the end mark may be queued behind a peer
                // that has since left normally.
                if let Ok(Some(sample)) = self.subscriber.try_recv() {
                    return Ok(sample.payload().to_bytes().into_owned());
                }
                if lock(&self.peers).get(&self.from).is_some_and(|p| p.gone) {
                    return Err(format!("machine `{}` ({}) is gone before the stream ended", self.from, self.endpoint));
                }
                tokio::select! {
                    s = self.subscriber.recv_async() => {
                        return s.map(|s| s.payload().to_bytes().into_owned()).map_err(|e| format!("zenoh: {e}"));
                    }
                    () = notified => {}
                }
            }
        }
        .boxed()
    }
}
