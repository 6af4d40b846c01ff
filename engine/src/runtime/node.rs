//! The task that runs one node: joins its inputs frame by frame, calls the operator (inline
//! or on the blocking pool), and forwards outputs to consumers and recorders.

use std::panic::AssertUnwindSafe;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use super::RunOptions;
use super::edge::{EdgeRx, EdgeTx, Envelope, TryRecv};
use super::metrics::{Failure, NodeMetrics, ParameterChange};
use super::monitor::{AppliedSet, EchoTap, LiveSet, lock};
use super::recorders::{Tap, records};
use crate::msg::{Message, PortType};
use crate::op::{Context, Inputs, Instance, OpError, Operator, Outputs as OpOutputs, Params, Source};
use crate::spec::{Join, RecordPolicy, ResolvedNode};

pub(super) struct Outputs {
    pub ports: Vec<(&'static str, PortType, RecordPolicy)>,
    pub senders: Vec<Vec<EdgeTx>>,
    pub tap: Vec<tokio::sync::mpsc::Sender<Tap>>,
}

/// A tunable parameter's new value from frame `frame` on (`run --set-at FRAME:node.param=value`),
/// applied in lockstep order: the node computes frame `frame` with it.
#[derive(Clone, Debug, PartialEq)]
pub struct ScheduledSet {
    /// The first frame that uses the value.
    pub frame: u64,
    /// The node.
    pub node: String,
    /// The parameter (one of the node's operator's [`crate::op::OpSpec::tunable`]).
    pub param: String,
    /// The value, as validation resolved it.
    pub value: serde_json::Value,
}

pub(super) struct NodeTask {
    pub node: ResolvedNode,
    pub ctx: Context,
    pub outputs: Outputs,
    pub inputs: Vec<Option<EdgeRx>>,
    /// Join mode and delay of each input (`None` if unwired).
    pub joins: Vec<Option<(Join, u32)>>,
    pub failures: Arc<Mutex<Vec<Failure>>>,
    pub options: RunOptions,
    /// This node's scheduled parameter changes (`run --set-at`), by frame.
    pub schedule: Vec<ScheduledSet>,
    /// The counters, where the monitor reads them while the node runs.
    pub live: Arc<Mutex<NodeMetrics>>,
    /// Parameter changes sent while running (`dynaflow set`), if the node takes any.
    pub sets: Option<tokio::sync::mpsc::UnboundedReceiver<LiveSet>>,
    /// Ports someone listens to (`dynaflow echo`).
    pub echo: Option<EchoTap>,
}

struct Slot {
    rx: Option<EdgeRx>,
    join: Join,
    /// Lockstep without delay: these inputs decide which frames exist. Delayed feedback
    /// inputs never end on their own (the node feeds them), so they cannot.
    driving: bool,
    head: Option<Envelope>,
    /// Newest message seen (for `latest` joins).
    held: Option<Arc<Message>>,
    /// Highest frame consumed so far.
    frontier: Option<u64>,
}

/// A caught panic as an operator error.
fn caught<R>(r: std::thread::Result<Result<R, OpError>>) -> Result<R, OpError> {
    r.unwrap_or_else(|p| Err(OpError::Failed(format!("panicked: {}", panic_message(&*p)))))
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic payload".to_owned())
}

impl NodeTask {
    fn fail(&self, error: String) {
        tracing::error!(node = %self.node.id, "{error}");
        self.failures
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(Failure { node: self.node.id.to_string(), error });
        self.options.stop.request();
    }

    pub async fn run(mut self, inst: Option<Instance>) -> NodeMetrics {
        match inst {
            Some(Instance::Source(src)) => self.run_source(src).await,
            Some(Instance::Transform(op)) => self.run_transform(Some(op)).await,
            None if self.node.inputs.iter().any(|i| i.edge.is_some()) => self.run_transform(None).await,
            // A disabled source produces no frames.
            None => {}
        }
        let mut metrics = lock(&self.live);
        metrics.report = self.ctx.report.take();
        metrics.clone()
    }

    /// Change `param` to `value` before frame `k`: the operator takes it (or the change is
    /// refused and the run fails, as an operator error would), `params` follows.
    fn change(
        &mut self,
        o: &mut Box<dyn Operator>,
        params: &mut Params,
        k: u64,
        param: String,
        value: serde_json::Value,
    ) -> Result<ParameterChange, String> {
        let (next, old) = params.with(&param, value.clone());
        let taken = caught(std::panic::catch_unwind(AssertUnwindSafe(|| o.set_params(&mut self.ctx, &next))));
        if let Err(e) = taken {
            return Err(format!("setting `{param}` at frame {k}: {e}"));
        }
        let old = old.unwrap_or_default();
        tracing::info!(node = %self.node.id, "frame {k}: `{param}` {old} -> {value}");
        let change = ParameterChange { frame: k, param, old, new: value };
        lock(&self.live).parameter_changes.push(change.clone());
        *params = next;
        Ok(change)
    }

    async fn call_source(
        &mut self,
        src: Box<dyn Source>,
        seq: u64,
    ) -> (Box<dyn Source>, Result<Option<OpOutputs>, OpError>) {
        let (back, r) = self.invoke(src, move |s, ctx| s.next(ctx, seq)).await;
        (back.unwrap_or_else(|| Box::new(Ended)), r)
    }

    /// Call `f` on the operator: inline, or on the blocking pool when the op is CPU-heavy (the
    /// operator and its context travel there and back). Panics become errors; the operator is
    /// `None` only if its blocking task was lost.
    async fn invoke<T, R>(
        &mut self,
        mut obj: T,
        f: impl FnOnce(&mut T, &mut Context) -> Result<R, OpError> + Send + 'static,
    ) -> (Option<T>, Result<R, OpError>)
    where
        T: Send + 'static,
        R: Send + 'static,
    {
        if !self.node.op.cpu_heavy {
            let r = std::panic::catch_unwind(AssertUnwindSafe(|| f(&mut obj, &mut self.ctx)));
            return (Some(obj), caught(r));
        }
        let stand_in = placeholder_ctx(&self.ctx);
        let mut ctx = std::mem::replace(&mut self.ctx, stand_in);
        let joined = tokio::task::spawn_blocking(move || {
            let r = std::panic::catch_unwind(AssertUnwindSafe(|| f(&mut obj, &mut ctx)));
            (obj, ctx, r)
        })
        .await;
        match joined {
            Ok((obj, ctx, r)) => {
                self.ctx = ctx;
                (Some(obj), caught(r))
            }
            Err(e) => (None, Err(OpError::Failed(format!("task failed: {e}")))),
        }
    }

    async fn run_source(&mut self, mut src: Box<dyn Source>) {
        if let Err(e) = src.start(&mut self.ctx) {
            self.fail(format!("start: {e}"));
            return;
        }
        let mut pace: Option<(Instant, f64)> = None;
        let mut seq = 0u64;
        loop {
            if self.options.stop.requested() || self.options.max_frames.is_some_and(|m| seq >= m) {
                break;
            }
            let t0 = Instant::now();
            let (back, result) = self.call_source(src, seq).await;
            src = back;
            let out = match result {
                Ok(Some(out)) => out,
                Ok(None) => break,
                Err(e) => {
                    self.fail(e.to_string());
                    break;
                }
            };
            let busy = t0.elapsed();
            if self.options.realtime
                && let Some(stamp) = out.items.first().map(|(_, m)| m.header.stamp)
            {
                let (wall0, stamp0) = *pace.get_or_insert((Instant::now(), stamp));
                let due = wall0 + Duration::from_secs_f64((stamp - stamp0).max(0.0));
                tokio::select! {
                    _ = tokio::time::sleep_until(due.into()) => {}
                    _ = self.options.stop.wait() => break,
                }
            }
            let born = Instant::now();
            let out_was_empty = out.items.is_empty();
            if let Err(e) = self.emit(seq, out, born).await {
                self.fail(e.to_string());
                break;
            }
            {
                let mut metrics = lock(&self.live);
                // A source frame without any output is a skipped frame (e.g. an unreadable file).
                if out_was_empty {
                    metrics.skipped += 1;
                } else {
                    metrics.frames += 1;
                }
                metrics.busy += busy;
                metrics.latency.record(busy);
                metrics.ends.record(busy);
                metrics.age.record(Duration::ZERO);
                metrics.handled(seq);
            }
            self.options.progress.fetch_max(seq + 1, std::sync::atomic::Ordering::Relaxed);
            seq += 1;
        }
        if let Err(e) = src.stop(&mut self.ctx) {
            self.fail(format!("stop: {e}"));
        }
    }

    async fn run_transform(&mut self, mut op: Option<Box<dyn Operator>>) {
        if let Some(o) = op.as_mut()
            && let Err(e) = o.start(&mut self.ctx)
        {
            self.fail(format!("start: {e}"));
            return;
        }
        let mut slots: Vec<Slot> = std::mem::take(&mut self.inputs)
            .into_iter()
            .zip(&self.joins)
            .map(|(rx, join)| {
                let (join, delay) = join.unwrap_or((Join::Lockstep, 0));
                Slot { rx, join, driving: join == Join::Lockstep && delay == 0, head: None, held: None, frontier: None }
            })
            .collect();
        let deterministic = !self.options.realtime;
        let mut params = self.node.params.clone();
        let mut schedule = std::mem::take(&mut self.schedule).into_iter().peekable();
        // The last frame this node emitted (fired or skipped), and whether it ended because its
        // inputs did (rather than on an error).
        let mut last_frame: Option<u64> = None;
        let mut completed = true;
        loop {
            // 1. Every open lockstep input needs a head: driving ones first, because the node
            // ends when they all have.
            for driving in [true, false] {
                for s in slots.iter_mut().filter(|s| s.join == Join::Lockstep && s.driving == driving) {
                    if s.head.is_none()
                        && let Some(rx) = &s.rx
                    {
                        match rx.recv().await {
                            Some(e) => s.head = Some(e),
                            None => s.rx = None,
                        }
                    }
                }
                if driving && slots.iter().filter(|s| s.driving).all(|s| s.head.is_none()) {
                    break;
                }
            }
            if slots.iter().filter(|s| s.driving).all(|s| s.head.is_none()) {
                break;
            }
            // 2. The frame to fire is the smallest pending one.
            let Some(k) =
                slots.iter().filter(|s| s.join == Join::Lockstep).filter_map(|s| s.head.as_ref().map(|h| h.seq)).min()
            else {
                break;
            };
            // Frames between the last one and k were lost upstream to a dropping queue (every
            // lockstep input has moved past them), so this node will never run them. Say so
            // downstream at once: a consumer in a feedback loop may be waiting on exactly
            // those frames before it can produce the input that decides ours.
            if k > last_frame.map_or(0, |l| l + 1)
                && let Err(e) = self.emit(k - 1, OpOutputs::new(), Instant::now()).await
            {
                self.fail(e.to_string());
                completed = false;
                break;
            }
            // 3. Bring `latest` inputs up to frame k.
            for s in slots.iter_mut().filter(|s| s.join == Join::Latest) {
                advance_latest(s, k, deterministic).await;
            }
            // 4. Assemble.
            let mut born: Option<Instant> = None;
            let ports: Vec<(&'static str, Option<Arc<Message>>)> = slots
                .iter_mut()
                .zip(&self.node.inputs)
                .map(|(s, decl)| {
                    let msg = match s.join {
                        Join::Lockstep => match s.head.take() {
                            Some(h) if h.seq == k => {
                                born = Some(born.map_or(h.born, |b: Instant| b.min(h.born)));
                                s.frontier = Some(k);
                                h.msg
                            }
                            other => {
                                s.head = other;
                                None
                            }
                        },
                        Join::Latest => s.held.clone(),
                    };
                    (decl.name, msg)
                })
                .collect();
            let born = born.unwrap_or_else(Instant::now);
            // 5. Parameters scheduled for this frame (or one this node never ran) change now,
            // between frames, so every run with the same schedule computes the same.
            // Then the changes sent while running (`dynaflow set`), in the order they came: at
            // this frame, which the change records, so `--set-at` replays it exactly.
            let mut live: Vec<LiveSet> = Vec::new();
            while let Some(set) = self.sets.as_mut().and_then(|rx| rx.try_recv().ok()) {
                live.push(set);
            }
            let scheduled = std::iter::from_fn(|| schedule.next_if(|c| c.frame <= k)).map(|c| (c.param, c.value, None));
            let live = live.into_iter().map(|s| (s.param, s.value, Some(s.applied)));
            let stamp = ports.iter().find_map(|(_, m)| m.as_ref().map(|m| m.header.stamp)).unwrap_or(0.0);
            for (param, value, reply) in scheduled.collect::<Vec<_>>().into_iter().chain(live) {
                let Some(mut o) = op.take() else { continue };
                let r = self.change(&mut o, &mut params, k, param, value);
                op = Some(o);
                match &r {
                    // On the recorders' timelines too (a marker in the `.rrd`, a log message in
                    // the MCAP).
                    Ok(change) => {
                        for tap in &self.outputs.tap {
                            let change = change.clone();
                            let _ = tap.send(Tap::Change { node: self.node.id.clone(), change, stamp }).await;
                        }
                    }
                    Err(e) => {
                        self.fail(e.clone());
                        completed = false;
                    }
                }
                if let Some(reply) = reply {
                    let _ = reply.send(r.map(|c| AppliedSet { frame: c.frame, old: c.old, new: c.new }));
                }
                if !completed {
                    break;
                }
            }
            if !completed {
                break;
            }
            let inputs = Inputs::new(k, ports);
            let ready = self.node.inputs.iter().zip(&inputs.ports).all(|(decl, (_, m))| !decl.required || m.is_some());
            let t0 = Instant::now();
            let out = match (&mut op, ready) {
                (Some(_), true) => {
                    let (back, r) = self.call(op.take(), inputs).await;
                    op = back;
                    match r {
                        Ok(out) => out,
                        Err(e) => {
                            self.fail(e.to_string());
                            completed = false;
                            break;
                        }
                    }
                }
                _ => {
                    lock(&self.live).skipped += 1;
                    OpOutputs::new()
                }
            };
            let fired = ready && op.is_some();
            let busy = t0.elapsed();
            if let Err(e) = self.emit(k, out, born).await {
                self.fail(e.to_string());
                completed = false;
                break;
            }
            last_frame = Some(k);
            let mut metrics = lock(&self.live);
            if fired {
                metrics.frames += 1;
                metrics.busy += busy;
                let took = t0.elapsed();
                metrics.latency.record(took);
                metrics.ends.record(took);
                metrics.age.record(born.elapsed());
            }
            metrics.handled(k);
        }
        // Closing our inputs lets producers stop waiting on us. After a clean end, what is
        // left belongs to frames after our last one (a delay's tail) and is not lost.
        for slot in slots {
            if let Some(rx) = slot.rx {
                if completed {
                    rx.complete(last_frame);
                } else {
                    drop(rx);
                }
            }
        }
        if let Some(o) = op.as_mut()
            && let Err(e) = o.stop(&mut self.ctx)
        {
            self.fail(format!("stop: {e}"));
        }
    }

    async fn call(
        &mut self,
        op: Option<Box<dyn Operator>>,
        inputs: Inputs,
    ) -> (Option<Box<dyn Operator>>, Result<OpOutputs, OpError>) {
        match op {
            Some(op) => self.invoke(op, move |o, ctx| o.process(ctx, &inputs)).await,
            None => (None, Ok(OpOutputs::new())),
        }
    }

    /// Send frame `seq`: each output port gets its message or a watermark.
    async fn emit(&self, seq: u64, out: OpOutputs, born: Instant) -> Result<(), OpError> {
        let mut per_port: Vec<Option<Arc<Message>>> = vec![None; self.outputs.ports.len()];
        for (port, mut msg) in out.items {
            let Some(j) = self.outputs.ports.iter().position(|(p, _, _)| *p == port) else {
                return Err(OpError::Contract(format!("emitted on undeclared port `{port}`")));
            };
            let ty = self.outputs.ports.get(j).map_or(PortType::Any, |p| p.1);
            if ty != PortType::Any && msg.body.port_type() != ty {
                return Err(OpError::Contract(format!(
                    "port `{port}` is declared {ty} but got {}",
                    msg.body.port_type()
                )));
            }
            let Some(slot) = per_port.get_mut(j) else { continue };
            if slot.is_some() {
                return Err(OpError::Contract(format!("emitted twice on port `{port}` in frame {seq}")));
            }
            // The runtime owns frame numbering.
            msg.header.seq = seq;
            msg.touch();
            *slot = Some(Arc::new(msg));
        }
        for (j, ((port, _, record), (senders, msg))) in
            self.outputs.ports.iter().zip(self.outputs.senders.iter().zip(per_port)).enumerate()
        {
            if let (Some(m), Some(echo)) = (&msg, &self.echo)
                && echo.watched(j)
            {
                // Nobody listening is the usual case: no receiver, nothing to do.
                let _ = echo.tx.send(super::monitor::Echo {
                    node: self.node.id.to_string(),
                    port: (*port).to_owned(),
                    seq,
                    stamp: m.header.stamp,
                    at_s: echo.started.elapsed().as_secs_f64(),
                    summary: m.summary(),
                });
            }
            if let Some(m) = &msg
                && records(*record, seq)
            {
                for tap in &self.outputs.tap {
                    // A closed recorder queue only happens at teardown; nothing to record then.
                    let _ = tap.send(Tap::Message { node: self.node.id.clone(), port, msg: m.clone() }).await;
                }
            }
            for tx in senders {
                tx.send(Envelope { seq, msg: msg.clone(), born }).await;
            }
        }
        Ok(())
    }
}

async fn advance_latest(s: &mut Slot, k: u64, deterministic: bool) {
    loop {
        if s.frontier.is_some_and(|f| f >= k) {
            return;
        }
        if s.head.is_none() {
            let Some(rx) = &s.rx else { return };
            if deterministic {
                match rx.recv().await {
                    Some(e) => s.head = Some(e),
                    None => {
                        s.rx = None;
                        return;
                    }
                }
            } else {
                match rx.try_recv() {
                    TryRecv::Item(e) => s.head = Some(e),
                    TryRecv::Empty => return,
                    TryRecv::Closed => {
                        s.rx = None;
                        return;
                    }
                }
            }
        }
        match s.head.take() {
            Some(h) if h.seq <= k => {
                s.frontier = Some(h.seq);
                if let Some(m) = h.msg {
                    s.held = Some(m);
                }
            }
            other => {
                s.head = other;
                return;
            }
        }
    }
}

/// Stand-in while the real context travels to the blocking pool with the operator.
fn placeholder_ctx(ctx: &Context) -> Context {
    use rand_core::SeedableRng;
    Context {
        node: ctx.node.clone(),
        seed: ctx.seed,
        rng: rand_chacha::ChaCha8Rng::seed_from_u64(0),
        out_dir: None,
        stem: ctx.stem.clone(),
        realtime: ctx.realtime,
        report: None,
    }
}

/// A source that has ended (used when its task was lost).
struct Ended;

impl Source for Ended {
    fn next(&mut self, _ctx: &mut Context, _seq: u64) -> Result<Option<OpOutputs>, OpError> {
        Ok(None)
    }
}
