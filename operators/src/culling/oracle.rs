//! `oracle_boxes`: ground-truth boxes from the generator's masks.

use super::*;

// --- oracle_boxes ------------------------------------------------------------------------

params! {
    struct OracleConfig {
        /// instances smaller than this are left out (a detector would not see them)
        min_pixels: u64 [1, 100_000_000] = 50,
    }
}

const GT_MASK: In<SegmentationMask> = In::required("mask", "ground-truth class and instance mask");
const ORACLE_DETECTIONS: Out<Detections> = Out::new("detections", "one box per instance (score 1.0)");

const ORACLE_BOXES_DOC: &str = "ORACLE, not a detector: turns a ground-truth instance mask (the `synth` source's `gt_mask`) into one box per instance with its class name and score 1, so the semantic rules can be developed and measured before a detector exists. Never use it to claim detection results.";

/// The `oracle_boxes` operator (its doc: `dynaflow ops oracle_boxes`).
pub const ORACLE_BOXES: OpSpec = OpSpec::transform("oracle_boxes", "culling", ORACLE_BOXES_DOC, |p: &Params| {
    Ok(Instance::Transform(Box::new(OracleOp(OracleConfig::from_params(p)?))))
})
.inputs(&[GT_MASK.spec])
.outputs(&[ORACLE_DETECTIONS.spec])
.params(OracleConfig::PARAMS);

struct OracleOp(OracleConfig);

impl Operator for OracleOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, m) = GT_MASK.require(inputs)?;
        let ids = m.instances.as_deref().unwrap_or(&m.classes);
        let detections = rules::instance_boxes(ids, &m.classes, m.width as usize, self.0.min_pixels)
            .into_iter()
            .map(|(bbox, class)| Detection {
                bbox,
                class_id: u32::from(class),
                label: m.class_names.get(usize::from(class)).cloned().unwrap_or_else(|| "object".into()),
                score: 1.0,
            })
            .collect();
        Ok(Outputs::new().send(&ORACLE_DETECTIONS, msg.header.clone(), Detections { detections }))
    }
}
