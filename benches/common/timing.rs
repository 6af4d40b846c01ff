//! The benches' timer: the median wall time of `reps` runs after one warm-up run.

use std::time::Instant;

/// Median milliseconds of `reps` calls of `f`, after one call that is not timed.
pub fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..reps.max(1))
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}
