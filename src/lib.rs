//! The `dynaflow` package: the CLI binary (`src/main.rs`) and this small library that wires
//! the crates together, so tests and benches see exactly the operators the CLI sees.

use dynaflow_engine::op::Registry;

/// Every operator dynaflow ships: the `dynaflow-operators` families plus the recording-backed
/// sources of `dynaflow-recordings` (`mcap_replay`).
pub fn registry() -> Registry {
    let mut r = dynaflow_operators::registry();
    dynaflow_recordings::register(&mut r);
    r
}
