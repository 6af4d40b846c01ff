//! Label sets combined (OR, AND, one over the other) and scored against a reference.

use super::*;

/// How [`combine`] joins two decisions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Combine {
    /// Dynamic if either says so (MG-SLAM's S+G).
    Or,
    /// Dynamic only if both do.
    And,
}

/// Two rules' decisions about one point, `(dynamic, reason, score)` each, `None` where a rule
/// left the point unlabelled (it then counts as static). The combined decision takes the
/// reason and score of the rule that decided: `a`'s when `a` agrees with the result, else
/// `b`'s (falling back to the other's measure when the decider gave none); a static result
/// has reason `Static`.
pub fn combine(a: Option<Decision>, b: Option<Decision>, how: Combine) -> Decision {
    let (da, db) = (a.is_some_and(|l| l.dynamic), b.is_some_and(|l| l.dynamic));
    let dynamic = match how {
        Combine::Or => da || db,
        Combine::And => da && db,
    };
    let decider = if dynamic == da { a.or(b) } else { b.or(a) };
    Decision {
        dynamic,
        reason: if dynamic { decider.map_or(LabelReason::Static, |l| l.reason) } else { LabelReason::Static },
        score: decider.map_or(f32::NAN, |l| l.score),
    }
}

/// Labels scored against a reference (the generator's masks): counts of true and false
/// positives and negatives, "positive" meaning dynamic. For evaluation only; no rule reads it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Confusion {
    /// Labelled dynamic and truly dynamic.
    pub tp: u64,
    /// Labelled dynamic but static.
    pub fp: u64,
    /// Labelled static but dynamic.
    pub fn_: u64,
    /// Labelled static and static.
    pub tn: u64,
}

impl Confusion {
    /// Count one point.
    pub fn add(&mut self, predicted: bool, truth: bool) {
        match (predicted, truth) {
            (true, true) => self.tp += 1,
            (true, false) => self.fp += 1,
            (false, true) => self.fn_ += 1,
            (false, false) => self.tn += 1,
        }
    }

    /// Both counts together.
    pub fn merge(&mut self, other: &Self) {
        self.tp += other.tp;
        self.fp += other.fp;
        self.fn_ += other.fn_;
        self.tn += other.tn;
    }

    /// Of the points labelled dynamic, the share truly dynamic (1 when none is labelled).
    pub fn precision(&self) -> f64 {
        ratio(self.tp, self.tp + self.fp)
    }

    /// Of the truly dynamic points, the share labelled dynamic (1 when there is none).
    pub fn recall(&self) -> f64 {
        ratio(self.tp, self.tp + self.fn_)
    }

    /// Harmonic mean of precision and recall (0 when both are 0).
    pub fn f1(&self) -> f64 {
        let (p, r) = (self.precision(), self.recall());
        if p + r > 0.0 { 2.0 * p * r / (p + r) } else { 0.0 }
    }
}

fn ratio(n: u64, d: u64) -> f64 {
    if d == 0 { 1.0 } else { n as f64 / d as f64 }
}
