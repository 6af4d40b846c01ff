//! Per-frame utility operators.

use dynaflow_engine::msg::{Scalars, SegmentationMask};
use dynaflow_engine::op::{Context, In, InputRole, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Out, Outputs};
use std::collections::BTreeSet;

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
