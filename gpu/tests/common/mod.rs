//! Shared by the GPU tests.
#![allow(clippy::panic)]

use dynaflow_gpu::Gpu;

#[path = "../../../tests/common/peers.rs"]
pub mod peers;

/// The adapter there is for `comparison`; `None` when it is skipped ([`peers::peer_runs`]:
/// without an adapter a failure under `DYNAFLOW_REQUIRE_PEERS`, as on CI's lavapipe).
pub fn gpu(comparison: &str) -> Option<Gpu> {
    let mut gpu = None;
    let runs = peers::peer_runs("gpu", comparison, || {
        gpu = Some(Gpu::new().map_err(|e| e.to_string())?);
        Ok(())
    });
    gpu.filter(|_| runs)
}
