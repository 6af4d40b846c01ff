//! Per-frame utility operators.

use dynaflow_engine::msg::{Scalars, SegmentationMask};
use dynaflow_engine::op::{
    Context, In, InputRole, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Out, Outputs, Params,
};
use dynaflow_engine::params;
use std::collections::BTreeSet;

use dynaflow_engine::testing::{ANY_IN, SAME_OUT, forward};

// --- passthrough -----------------------------------------------------------------------

pub(super) const PASSTHROUGH: OpSpec = OpSpec {
    name: "passthrough",
    family: "util",
    doc: "Forwards its input unchanged. Used to measure engine overhead per hop.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: &[],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |_| Ok(Instance::Transform(Box::new(Passthrough))),
};

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

pub(super) const GATE: OpSpec = OpSpec {
    name: "gate",
    family: "util",
    doc: "Forwards frames whose number `k` satisfies `k % every == offset`; other frames carry nothing (a watermark). Models a key-frame gate.",
    kind: OpKind::Transform,
    inputs: ANY_IN,
    outputs: SAME_OUT,
    params: GateConfig::PARAMS,
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(Gate(GateConfig::from_params(p)?)))),
};

struct Gate(GateConfig);

impl Operator for Gate {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        if inputs.seq % self.0.every == self.0.offset % self.0.every { forward(inputs) } else { Ok(Outputs::new()) }
    }
}

// --- mask_stats ------------------------------------------------------------------------

pub(super) const MASK_STATS: OpSpec = OpSpec {
    name: "mask_stats",
    family: "util",
    doc: "Statistics of a segmentation mask: the fraction of pixels of a non-background class (`dynamic_fraction`) and the number of distinct instances (`instances`). Shows how dynamic each frame of a sequence is.",
    kind: OpKind::Transform,
    inputs: &[MASK.spec],
    outputs: &[STATS.spec],
    params: &[],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |_| Ok(Instance::Transform(Box::new(MaskStats))),
};

const MASK: In<SegmentationMask> =
    In::required("mask", "class (and instance) mask; class 0 is background/static").with_role(InputRole::Statistics);
const STATS: Out<Scalars> = Out::new("stats", "`dynamic_fraction`, `instances`");

struct MaskStats;

impl Operator for MaskStats {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, m) = MASK.require(inputs)?;
        let dynamic = m.classes.iter().filter(|&&c| c != 0).count();
        let fraction = if m.classes.is_empty() { 0.0 } else { dynamic as f64 / m.classes.len() as f64 };
        let instances =
            m.instances.as_ref().map_or(0, |i| i.iter().filter(|&&v| v != 0).collect::<BTreeSet<_>>().len());
        let values = vec![("dynamic_fraction".into(), fraction), ("instances".into(), instances as f64)];
        Ok(Outputs::new().send(&STATS, msg.header.clone(), Scalars { values }))
    }
}
