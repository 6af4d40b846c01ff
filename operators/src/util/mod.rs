//! Utility operators: a synthetic test source, pass-through, gating, scalar arithmetic,
//! seeded randomness and fault injection. They carry no vision algorithm; they exist so
//! graphs, joins, queues, determinism and shutdown can be exercised and benchmarked.
//!
//! Split: `source` (frame producers), `transform` (per-frame operators).

mod source;
mod transform;

use dynaflow_engine::op::Registry;

pub(crate) fn register(r: &mut Registry) {
    r.register(source::TEST_PATTERN);
    r.register(transform::PASSTHROUGH);
    r.register(transform::SIMULATE_WORK);
    r.register(transform::RANDOM_SCALAR);
    r.register(transform::GATE);
    r.register(transform::SCALAR_SUM);
    r.register(transform::FAULT);
    r.register(transform::MASK_STATS);
}
