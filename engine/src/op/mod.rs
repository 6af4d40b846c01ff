//! The operator contract: what an operator declares (ports, parameters) and what it implements.
//!
//! Split in three: `spec` holds the static declarations the validator and `dynaflow ops` read,
//! `params` the resolved parameter values handed to constructors, and `registry` the lookup
//! table from op name to declaration. The traits below are what an operator author implements.

mod declare;
mod params;
mod registry;
mod spec;

use std::path::PathBuf;
use std::sync::Arc;

use rand_chacha::ChaCha8Rng;

pub(crate) use declare::comma_items;
pub use declare::{In, Out, Param, ParamMap, Seeded, doc_line, ranged};
pub use params::Params;
pub use registry::Registry;
pub use spec::{
    DeclareFn, DeclareRequest, Default, InputRole, Instance, MapStore, OpKind, OpSpec, ParamSpec, ParamType, PortSpec,
    concat_params,
};

use crate::msg::{Body, Header, Message};

/// What an operator can fail with. The runtime adds the node id when it reports it.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OpError {
    /// A parameter could not be turned into the operator's config.
    #[error("parameter `{key}`: {message}")]
    Config {
        /// The offending key.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// Input data is unusable (wrong size, corrupt, …).
    #[error("bad input: {0}")]
    Input(String),
    /// A library refused this operator's input (a file, a model, a map, a frame): its typed
    /// error kept whole (displayed as itself, its `source()` chain intact, downcastable).
    #[error(transparent)]
    Library(Box<dyn std::error::Error + Send + Sync + 'static>),
    /// The operator emitted on a port it did not declare, or with the wrong type.
    #[error("operator bug: {0}")]
    Contract(String),
    /// Anything else.
    #[error("{0}")]
    Failed(String),
}

impl OpError {
    /// A library's error, kept as it is: `.map_err(OpError::library)`.
    pub fn library(e: impl std::error::Error + Send + Sync + 'static) -> Self {
        Self::Library(Box::new(e))
    }
}

/// Per-node state the runtime hands to every call.
#[derive(Debug)]
pub struct Context {
    /// The node id.
    pub node: Arc<str>,
    /// Seed of this node's RNG (graph seed mixed with the node id).
    pub seed: u64,
    /// This node's deterministic RNG. Use only this for randomness.
    pub rng: ChaCha8Rng,
    /// The run's output directory, if any.
    pub out_dir: Option<PathBuf>,
    /// The run's file stem, `<graph>` or `<graph>-<variant>`: an operator's own files are
    /// `<out_dir>/<stem>.<node>.<what>` ([`Context::output_file`]).
    pub stem: Arc<str>,
    /// Whether the run is paced at sensor rate.
    pub realtime: bool,
    /// What the operator has to add to its node's entry in the run summary (e.g. a
    /// tracker's ATE against ground truth), set by the time `stop` returns.
    pub report: Option<serde_json::Value>,
}

impl Context {
    /// Where this node writes its file `what` (`trajectory.txt`, `ot`, ...), if the run has an
    /// output folder: `<out_dir>/<stem>.<node>.<what>` ([`crate::files::RunFiles`]).
    pub fn output_file(&self, what: &str) -> Option<PathBuf> {
        let dir = self.out_dir.as_ref()?;
        Some(crate::files::RunFiles { dir: dir.clone(), stem: self.stem.to_string() }.node_file(&self.node, what))
    }
}

/// The inputs of one frame, in declaration order; `None` where an input is absent this frame.
#[derive(Debug, Clone)]
pub struct Inputs {
    /// The frame sequence number.
    pub seq: u64,
    pub(crate) ports: Vec<(&'static str, Option<Arc<Message>>)>,
}

impl Inputs {
    /// A frame's inputs (mainly for tests of operators without the runtime).
    pub fn new(seq: u64, ports: Vec<(&'static str, Option<Arc<Message>>)>) -> Self {
        Self { seq, ports }
    }
    /// The message on `port`, if present this frame; a port the node does not declare is an
    /// operator bug ([`OpError::Contract`]), never "absent". Operators read through their
    /// [`In`] handles.
    pub fn declared(&self, port: &str) -> Result<Option<&Arc<Message>>, OpError> {
        match self.ports.iter().find(|(p, _)| *p == port) {
            Some((_, m)) => Ok(m.as_ref()),
            None => Err(OpError::Contract(format!(
                "read of input `{port}`, which the operator does not declare (it declares {})",
                self.ports.iter().map(|(p, _)| format!("`{p}`")).collect::<Vec<_>>().join(", ")
            ))),
        }
    }
    /// A header for outputs derived from these inputs: that of the first present input.
    pub fn header(&self) -> Option<&Header> {
        self.ports.iter().find_map(|(_, m)| m.as_ref().map(|m| &m.header))
    }
}

/// What one call produced; ports left out are "nothing for this frame".
#[derive(Debug, Default)]
pub struct Outputs {
    pub(crate) items: Vec<(&'static str, Message)>,
}

impl Outputs {
    /// No outputs.
    pub fn new() -> Self {
        Self::default()
    }
    /// Emit `body` on `port` with `header`.
    pub fn push(&mut self, port: &'static str, header: Header, body: Body) {
        self.items.push((port, Message::new(header, body)));
    }
    /// Builder form of [`Outputs::push`].
    #[must_use]
    pub fn with(mut self, port: &'static str, header: Header, body: Body) -> Self {
        self.push(port, header, body);
        self
    }
    /// The emitted messages.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, &Message)> {
        self.items.iter().map(|(p, m)| (*p, m))
    }
}

/// A node with inputs. Called once per frame whose required inputs are all present.
///
/// CPU-heavy operators declare it in their [`OpSpec`]; the runtime then calls them on the
/// blocking pool so they never stall the async executor.
pub trait Operator: Send + 'static {
    /// Called once before the first frame.
    fn start(&mut self, _ctx: &mut Context) -> Result<(), OpError> {
        Ok(())
    }
    /// Process one frame.
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError>;
    /// Called once after the last frame (also on shutdown after an error elsewhere).
    fn stop(&mut self, _ctx: &mut Context) -> Result<(), OpError> {
        Ok(())
    }
    /// Take new values of the parameters the operator declares tunable ([`OpSpec::tunable`]):
    /// `params` are the node's parameters with the changed ones replaced, each validated as
    /// `--set` is. Called between two frames; the next frame computes with them.
    fn set_params(&mut self, _ctx: &mut Context, _params: &Params) -> Result<(), OpError> {
        Err(OpError::Failed("this operator takes no parameter while running".into()))
    }
}

/// A node without inputs that produces frames `0, 1, 2, …`.
pub trait Source: Send + 'static {
    /// Called once before the first frame.
    fn start(&mut self, _ctx: &mut Context) -> Result<(), OpError> {
        Ok(())
    }
    /// Produce frame `seq`, or `None` at the end of the sequence. Every emitted header
    /// must carry `seq`; its `stamp` paces `--realtime` runs.
    fn next(&mut self, ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError>;
    /// Called once after the last frame.
    fn stop(&mut self, _ctx: &mut Context) -> Result<(), OpError> {
        Ok(())
    }
    /// Number of frames this source will produce, if known (for progress display).
    fn len_hint(&self) -> Option<u64> {
        None
    }
}
