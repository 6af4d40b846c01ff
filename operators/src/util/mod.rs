//! Utility operators: mask statistics, a mask's and a rule's labels' agreement with a
//! reference (no vision algorithm; they describe frames).
//!
//! The flow operators (`passthrough`, `gate`) and the operators that exist only to exercise
//! the engine (`testing.*`) live in the engine (`dynaflow_engine::flow`, `::testing`); they
//! are registered here with the rest.

mod transform;

use dynaflow_engine::op::Registry;

pub(crate) fn register(r: &mut Registry) {
    dynaflow_engine::testing::register(r);
    dynaflow_engine::flow::register(r);
    r.register(transform::MASK_STATS);
    r.register(transform::MASK_IOU);
    r.register(transform::LABEL_ACCURACY);
}
