//! `combine_labels`: two label sets as one.

use super::*;

// --- combine_labels ------------------------------------------------------------------------

param_enum! {
    /// How two label sets combine.
    enum CombineMode { Or = "or", And = "and" }
}

params! {
    struct CombineConfig {
        /// how the two decisions combine
        mode: CombineMode = CombineMode::Or,
    }
}

const LABELS_A: In<PointLabels> = In::required("a", "first rule's labels");
const LABELS_B: In<PointLabels> = In::required("b", "second rule's labels");

/// The `combine_labels` operator (its doc: `dynaflow ops combine_labels`).
pub const COMBINE_LABELS: OpSpec =
    OpSpec::transform("combine_labels", "culling", doc_line(include_str!("docs/combine_labels.md")), |p: &Params| {
        Ok(Instance::Transform(Box::new(CombineOp(CombineConfig::from_params(p)?))))
    })
    .inputs(&[In::<Tracks>::required("tracks", "the tracks both label sets index").spec, LABELS_A.spec, LABELS_B.spec])
    .outputs(&[LABELS.spec, STATIC.spec, Out::<Scalars>::new("counts", "`dynamic`, `static`, `total`").spec])
    .params(CombineConfig::PARAMS);

struct CombineOp(CombineConfig);

impl Operator for CombineOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let ((_, a), (_, b)) = (LABELS_A.require(inputs)?, LABELS_B.require(inputs)?);
        let find = |l: &PointLabels, i: usize| {
            l.labels.iter().find(|x| x.index as usize == i).map(|x| Decision {
                dynamic: x.dynamic,
                reason: x.reason,
                score: x.score,
            })
        };
        let how = match self.0.mode {
            CombineMode::And => rules::Combine::And,
            CombineMode::Or => rules::Combine::Or,
        };
        let decisions: Vec<Decision> =
            (0..t.tracks.len()).map(|i| rules::combine(find(a, i), find(b, i), how)).collect();
        Ok(labelled(msg, t, &decisions, &[]))
    }
}
