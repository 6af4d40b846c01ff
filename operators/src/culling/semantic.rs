//! `cull_mask` (DynaSLAM, MG-SLAM) and `cull_semantic_prior` (YG-SLAM).

use super::*;

params! {
    struct MaskConfig {
        /// class names that count as dynamic
        classes: Vec<ClassName> = class_list(&["person"]),
    }
}

const MASK: In<SegmentationMask> =
    In::wired("mask", "segmentation of dynamic classes (a frame without: every track static)");

rule_op!(CULL_MASK, "cull_mask", &[TRACKS.spec, MASK.spec], MaskConfig, MaskOp);

struct MaskOp(MaskConfig);

impl Operator for MaskOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (_, cur) = endpoints(t);
        let decisions = match MASK.get(inputs)? {
            Some(m) => {
                let dynamic_ids: Vec<u16> = m
                    .class_names
                    .iter()
                    .enumerate()
                    .filter(|(_, n)| self.0.classes.iter().any(|c| c.as_str() == &***n))
                    .map(|(i, _)| i as u16)
                    .collect();
                let (w, h) = (m.width as usize, m.height as usize);
                rules::mask_rule(&cur, |x, y| {
                    x < w && y < h && m.classes.get(y * w + x).is_some_and(|c| dynamic_ids.contains(c))
                })
            }
            None => all_static(cur.len(), 0.0),
        };
        Ok(labelled(msg, t, &decisions, &[]))
    }
}

/// A class's dynamic value (YG-SLAM's scale: 0 static .. 1 always moving).
#[derive(Clone, Copy, Debug)]
struct DynamicValue(f64);

impl Param for DynamicValue {
    const TYPE: ParamType = ParamType::Float { min: 0.0, max: 1.0 };
    fn from_json(value: &serde_json::Value, params: &Params) -> Result<Self, String> {
        f64::from_json(value, params).map(DynamicValue)
    }
    fn to_json(&self) -> serde_json::Value {
        self.0.into()
    }
}

params! {
    struct PriorConfig {
        /// dynamic values per class overriding YG-SLAM's table (person 1.0; cup, cell phone, keyboard, mouse 0.7; chair 0.6; tvmonitor 0.5; diningtable 0.2; book 0.1), e.g. `{ chair: 1.0 }`
        values: ParamMap<ClassName, DynamicValue> = ParamMap(Vec::new()),
    }
}

const PRIOR_DETECTIONS: In<Detections> =
    In::wired("detections", "boxes with class names (a frame without: no box, every track static)");
const KEY_FRAME: In<Body> = In::optional("key_frame", "present on key frames (the 0.4-0.8 band counts only there)");

rule_op!(
    CULL_SEMANTIC_PRIOR,
    "cull_semantic_prior",
    &[TRACKS.spec, PRIOR_DETECTIONS.spec, KEY_FRAME.spec],
    PriorConfig,
    |c: PriorConfig| {
        let mut values: Vec<(String, f32)> =
            rules::DEFAULT_DYNAMIC_VALUES.iter().map(|(n, v)| ((*n).to_owned(), *v)).collect();
        for (name, v) in c.values.0 {
            values.retain(|(n, _)| *n != name.0);
            values.push((name.0, v.0 as f32));
        }
        PriorOp { values }
    }
);

struct PriorOp {
    values: Vec<(String, f32)>,
}

impl Operator for PriorOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (_, cur) = endpoints(t);
        let key = KEY_FRAME.message(inputs)?.is_some();
        let value_of = |l: &str| self.values.iter().find(|(n, _)| n == l).map_or(0.0, |(_, v)| *v);
        let decisions = rules::semantic_prior(&cur, &boxes(PRIOR_DETECTIONS.get(inputs)?), value_of, key);
        Ok(labelled(msg, t, &decisions, &[]))
    }
}
