//! The flow operators every graph may use whatever it carries: `passthrough` (one hop, to
//! measure engine overhead) and `gate` (every k-th frame, the rest as watermarks; the
//! key-frame gate of docs/graph-spec.md). They are content-agnostic, so they live with the
//! engine; `register` adds them to a registry (dynaflow's and [`crate::testing::registry`]).

use crate::msg::Body;
use crate::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params, PortSpec, Registry};
use crate::params;

/// Add `passthrough` and `gate` to `r`.
pub fn register(r: &mut Registry) {
    r.register(PASSTHROUGH);
    r.register(GATE);
}

const INPUT: In<Body> = In::required("input", "any message");
const OUTPUT: Out<Body> = Out::like("output", "input", "the input message, unchanged");
/// The one input of a forwarding operator: `input`, any message.
pub const ANY_IN: &[PortSpec] = &[INPUT.spec];
/// The one output of a forwarding operator: `output`, the input's type.
pub const SAME_OUT: &[PortSpec] = &[OUTPUT.spec];

/// Forward `input` to `output` unchanged (the forwarding operators' frame).
pub fn forward(inputs: &Inputs) -> Result<Outputs, OpError> {
    let (msg, body) = INPUT.require(inputs)?;
    Ok(Outputs::new().send(&OUTPUT, msg.header.clone(), body.clone()))
}

// --- passthrough -----------------------------------------------------------------------

/// `passthrough`: forwards its input unchanged.
pub const PASSTHROUGH: OpSpec = OpSpec::transform(
    "passthrough",
    "util",
    "Forwards its input unchanged. Used to measure engine overhead per hop.",
    |_| Ok(Instance::Transform(Box::new(Passthrough))),
)
.inputs(ANY_IN)
.outputs(SAME_OUT);

struct Passthrough;

impl Operator for Passthrough {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        forward(inputs)
    }
}

// --- gate ------------------------------------------------------------------------------

params! {
    struct GateConfig {
        /// period in frames
        every: u64 [1, 1_000_000] = 5,
        /// phase in frames
        offset: u64 [0, 1_000_000] = 0,
    }
}

const GATE_DOC: &str = "Forwards frames whose number `k` satisfies `k % every == offset`; other frames carry nothing (a watermark). Models a key-frame gate.";

/// `gate`: every `every`-th frame from `offset`, the rest as watermarks.
pub const GATE: OpSpec = OpSpec::transform("gate", "util", GATE_DOC, |p: &Params| {
    Ok(Instance::Transform(Box::new(Gate(GateConfig::from_params(p)?))))
})
.inputs(ANY_IN)
.outputs(SAME_OUT)
.params(GateConfig::PARAMS);

struct Gate(GateConfig);

impl Operator for Gate {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        if inputs.seq % self.0.every == self.0.offset % self.0.every { forward(inputs) } else { Ok(Outputs::new()) }
    }
}
