//! Per-frame utility operators.

use crate::inference::{ClassName, class_list};
use dynaflow_culling::Confusion;
use dynaflow_engine::msg::{PointLabels, Scalars, SegmentationMask};
use dynaflow_engine::op::{Context, In, InputRole, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::params;
use std::collections::BTreeSet;

// --- mask_stats ------------------------------------------------------------------------

const MASK_STATS_DOC: &str = "Statistics of a segmentation mask: the fraction of pixels of a non-background class (`dynamic_fraction`) and the number of distinct instances (`instances`). Shows how dynamic each frame of a sequence is.";

pub(super) const MASK_STATS: OpSpec =
    OpSpec::transform("mask_stats", "util", MASK_STATS_DOC, |_| Ok(Instance::Transform(Box::new(MaskStats))))
        .inputs(&[MASK.spec])
        .outputs(&[STATS.spec]);

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

// --- mask_iou --------------------------------------------------------------------------

params! {
    struct IouConfig {
        /// classes of `mask` that count as foreground (matched by name); every non-zero class of `truth` does
        classes: Vec<ClassName> = class_list(&["person"]),
    }
}

const MASK_IOU_DOC: &str = "Agreement of a mask with a reference mask (the generator's `gt_mask`): per frame the intersection over union, precision and recall of the `classes` pixels against the reference's non-zero pixels; the node report gives the run's pooled values (summed intersections over summed unions) and the per-frame mean. An evaluation: it reads ground truth, so its outputs are marked so.";

pub(super) const MASK_IOU: OpSpec = OpSpec::transform("mask_iou", "util", MASK_IOU_DOC, |p: &Params| {
    Ok(Instance::Transform(Box::new(MaskIou {
        config: IouConfig::from_params(p)?,
        sums: [0; 4],
        frames: 0,
        iou_sum: 0.0,
    })))
})
.inputs(&[IOU_MASK.spec, TRUTH.spec])
.outputs(&[IOU.spec])
.params(IouConfig::PARAMS);

const IOU_MASK: In<SegmentationMask> =
    In::required("mask", "the mask to score (a segmenter's, `box_to_mask`'s)").with_role(InputRole::Statistics);
const TRUTH: In<SegmentationMask> =
    In::required("truth", "the reference mask, same size (non-zero = foreground)").with_role(InputRole::Statistics);
const IOU: Out<Scalars> = Out::new(
    "iou",
    "`iou`, `precision`, `recall` (1 where nothing is to be found and nothing is), `mask_pixels`, `truth_pixels`",
);

struct MaskIou {
    config: IouConfig,
    /// Intersection, union, mask and truth pixels over the run.
    sums: [u64; 4],
    frames: u64,
    iou_sum: f64,
}

impl Operator for MaskIou {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, m) = IOU_MASK.require(inputs)?;
        let (_, t) = TRUTH.require(inputs)?;
        if (m.width, m.height) != (t.width, t.height) {
            return Err(OpError::Input(format!(
                "mask is {}x{} but truth is {}x{}",
                m.width, m.height, t.width, t.height
            )));
        }
        let fg: Vec<bool> =
            m.class_names.iter().map(|n| self.config.classes.iter().any(|c| c.as_str() == &**n)).collect();
        let [mut inter, mut union, mut mp, mut tp] = [0u64; 4];
        for (&c, &g) in m.classes.iter().zip(&t.classes) {
            let a = fg.get(usize::from(c)).copied().unwrap_or(false);
            let b = g != 0;
            inter += u64::from(a && b);
            union += u64::from(a || b);
            mp += u64::from(a);
            tp += u64::from(b);
        }
        let ratio = |n: u64, d: u64| if d == 0 { 1.0 } else { n as f64 / d as f64 };
        let iou = ratio(inter, union);
        for (s, v) in self.sums.iter_mut().zip([inter, union, mp, tp]) {
            *s += v;
        }
        self.frames += 1;
        self.iou_sum += iou;
        let values = vec![
            ("iou".into(), iou),
            ("precision".into(), ratio(inter, mp)),
            ("recall".into(), ratio(inter, tp)),
            ("mask_pixels".into(), mp as f64),
            ("truth_pixels".into(), tp as f64),
        ];
        Ok(Outputs::new().send(&IOU, msg.header.clone(), Scalars { values }))
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let [inter, union, mp, tp] = self.sums;
        let ratio = |n: u64, d: u64| if d == 0 { 1.0 } else { n as f64 / d as f64 };
        let report = crate::report::MaskAccuracyReport {
            frames: self.frames,
            iou: ratio(inter, union),
            precision: ratio(inter, mp),
            recall: ratio(inter, tp),
            mean_frame_iou: if self.frames == 0 { 0.0 } else { self.iou_sum / self.frames as f64 },
        };
        ctx.report = Some(crate::report::NodeReport::from(report).to_json());
        Ok(())
    }
}

// --- label_accuracy --------------------------------------------------------------------

const LABEL_ACCURACY_DOC: &str = "Precision and recall of a culling rule's labels against a reference mask (the generator's `gt_mask`): a label is truly dynamic where the reference is non-zero at its point. Per frame `precision`, `recall` (1 where nothing is to be found, or nothing was labelled), `tp`, `fp`, `fn`, `points`, `outside` (labels at points the reference does not cover: not scored, counted); the node report pools the run (`dynaflow bench` puts it next to the ATE). An evaluation: it reads ground truth, decides nothing; frames without a reference give nothing.";

pub(super) const LABEL_ACCURACY: OpSpec = OpSpec::transform("label_accuracy", "util", LABEL_ACCURACY_DOC, |_| {
    Ok(Instance::Transform(Box::new(LabelAccuracy::default())))
})
.inputs(&[ACC_LABELS.spec, ACC_TRUTH.spec])
.outputs(&[ACCURACY.spec]);

const ACC_LABELS: In<PointLabels> =
    In::required("labels", "a rule's labels, each at its point").with_role(InputRole::Statistics);
const ACC_TRUTH: In<SegmentationMask> =
    In::wired("truth", "the reference mask (non-zero = dynamic); a frame without (real TUM data): nothing is scored")
        .with_role(InputRole::Statistics);
const ACCURACY: Out<Scalars> = Out::new("accuracy", "`precision`, `recall`, `tp`, `fp`, `fn`, `points`, `outside`");

#[derive(Default)]
struct LabelAccuracy {
    run: Confusion,
    frames: u64,
    /// Labels at points the reference does not cover (not scored).
    outside: u64,
}

impl Operator for LabelAccuracy {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, labels) = ACC_LABELS.require(inputs)?;
        let Some(truth) = ACC_TRUTH.get(inputs)? else { return Ok(Outputs::new()) };
        let (w, h) = (truth.width as usize, truth.height as usize);
        let mut c = Confusion::default();
        let mut outside = 0u64;
        for l in &labels.labels {
            let (x, y) = (l.at[0].round(), l.at[1].round());
            // A point the reference does not cover (LK keeps tracks whose window still touches
            // the image; a reference of another size) cannot be scored: counted, not guessed.
            if !(x >= 0.0 && y >= 0.0 && (x as usize) < w && (y as usize) < h) {
                outside += 1;
                continue;
            }
            let dynamic = truth.classes.get(y as usize * w + x as usize).is_some_and(|&k| k != 0);
            c.add(l.dynamic, dynamic);
        }
        self.run.merge(&c);
        self.outside += outside;
        self.frames += 1;
        let values = vec![
            ("precision".into(), c.precision()),
            ("recall".into(), c.recall()),
            ("tp".into(), c.tp as f64),
            ("fp".into(), c.fp as f64),
            ("fn".into(), c.fn_ as f64),
            ("points".into(), labels.labels.len() as f64),
            ("outside".into(), outside as f64),
        ];
        Ok(Outputs::new().send(&ACCURACY, msg.header.clone(), Scalars { values }))
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let c = self.run;
        let report = crate::report::LabelAccuracyReport {
            frames: self.frames,
            precision: c.precision(),
            recall: c.recall(),
            f1: c.f1(),
            tp: c.tp,
            fp: c.fp,
            fn_: c.fn_,
            tn: c.tn,
            outside: self.outside,
        };
        ctx.report = Some(crate::report::NodeReport::LabelAccuracy(report).to_json());
        Ok(())
    }
}
