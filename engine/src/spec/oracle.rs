//! Ground truth followed through a graph: which decisions read it.
//!
//! Ground truth starts at the output ports operators declare as such (a generator's exact
//! poses and masks, a dataset's motion capture) and flows through every node it reaches, by
//! each input's [`InputRole`]: a `decision` or `statistics` input carries it on to all of the
//! node's outputs, an `evaluation` input (the tracker's `gt_pose`, used for the summary's
//! ATE) stops it. A node that receives ground truth on a `decision` input decides with it:
//! the graph (or the variant) is then an oracle and must say `oracle: true`, so every result
//! it produces is marked as an oracle's wherever users see it.

use super::GraphSpec;
use crate::op::{InputRole, OpSpec};
use crate::yaml::Span;

/// A decision that reads ground truth.
#[derive(Clone, Debug)]
pub(super) struct GroundTruthUse {
    /// The deciding node and its input, `node/port`.
    pub input: String,
    /// The producer wired into it, `node.port`.
    pub from: String,
    /// The ground-truth port it derives from, `node.port`.
    pub origin: String,
    /// Where the input is written.
    pub span: Span,
}

impl GroundTruthUse {
    /// `cull/mask <- boxes.detections (from camera.gt_mask)`.
    pub fn describe(&self) -> String {
        if self.from == self.origin {
            format!("{} <- {}", self.input, self.from)
        } else {
            format!("{} <- {} (from {})", self.input, self.from, self.origin)
        }
    }
}

/// One wired input: producer (node, output), consumer (node, input), where it is written.
pub(super) type Wire = ((usize, usize), (usize, usize), Span);

/// What the analysis found: every enabled node input that receives ground truth for a
/// decision (in edge order), and per node and output whether it carries ground truth.
pub(super) struct Analysis {
    pub uses: Vec<GroundTruthUse>,
    pub carries: Vec<Vec<bool>>,
}

/// Follow ground truth from the ports that emit it (`dynamic`: per node, the outputs its
/// parameters make ground truth) through the wires.
pub(super) fn analyse(spec: &GraphSpec, ops: &[Option<&OpSpec>], dynamic: &[Vec<&str>], wires: &[Wire]) -> Analysis {
    let enabled = |i: usize| spec.nodes.get(i).is_some_and(|n| !n.disabled) && ops.get(i).is_some_and(Option::is_some);
    let label = |i: usize, port: &str| format!("{}.{port}", spec.nodes.get(i).map_or("?", |n| n.id.as_str()));
    // Per node: the ground-truth origin its outputs carry (one origin per output port).
    let mut origin: Vec<Vec<Option<String>>> = ops
        .iter()
        .enumerate()
        .map(|(i, op)| {
            op.map_or_else(Vec::new, |op| {
                let gt =
                    |p: &crate::op::PortSpec| p.ground_truth || dynamic.get(i).is_some_and(|d| d.contains(&p.name));
                op.outputs.iter().map(|p| (gt(p) && enabled(i)).then(|| label(i, p.name))).collect()
            })
        })
        .collect();
    let role = |node: usize, port: usize| {
        ops.get(node).copied().flatten().and_then(|op| op.inputs.get(port)).map_or(InputRole::Decision, |p| p.role)
    };
    // Propagate to a fixed point (feedback edges make the graph cyclic).
    let mut changed = true;
    while changed {
        changed = false;
        for &((from, out), (to, input), _) in wires {
            if !enabled(from) || !enabled(to) || role(to, input) == InputRole::Evaluation {
                continue;
            }
            let Some(o) = origin.get(from).and_then(|p| p.get(out)).cloned().flatten() else { continue };
            for slot in origin.get_mut(to).into_iter().flatten() {
                if slot.is_none() {
                    *slot = Some(o.clone());
                    changed = true;
                }
            }
        }
    }
    let uses = wires
        .iter()
        .filter(|&&((from, _), (to, input), _)| enabled(from) && enabled(to) && role(to, input) == InputRole::Decision)
        .filter_map(|&((from, out), (to, input), span)| {
            let o = origin.get(from)?.get(out)?.clone()?;
            let op_from = ops.get(from).copied().flatten()?;
            let op_to = ops.get(to).copied().flatten()?;
            Some(GroundTruthUse {
                input: format!("{}/{}", spec.nodes.get(to)?.id, op_to.inputs.get(input)?.name),
                from: label(from, op_from.outputs.get(out)?.name),
                origin: o,
                span,
            })
        })
        .collect();
    let carries = origin.iter().map(|o| o.iter().map(Option::is_some).collect()).collect();
    Analysis { uses, carries }
}
