//! Utility operators: pass-through, gating and mask statistics (no vision algorithm; they
//! shape and describe frames).
//!
//! The operators that exist only to exercise the engine (`testing.*`) live in the engine's
//! `testing` module; they are registered here with the rest.

mod transform;

use dynaflow_engine::op::Registry;

pub(crate) fn register(r: &mut Registry) {
    dynaflow_engine::testing::register(r);
    r.register(transform::PASSTHROUGH);
    r.register(transform::GATE);
    r.register(transform::MASK_STATS);
}
