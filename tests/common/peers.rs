//! Whether a comparison against a peer (OpenCV, evo, onnxruntime, OctoMap, the rerun CLI, the
//! `mcap` reader, a GPU adapter) runs, shared by every test crate of the workspace.
//!
//! `scripts/test.sh` (the README's test command) installs every peer and sets
//! `DYNAFLOW_REQUIRE_PEERS=1`: a missing peer then fails its test. A peer named in
//! `DYNAFLOW_SKIP_PEERS` (comma-separated: `opencv,evo,onnxruntime,octomap,rerun,mcap,gpu,chromium,rosbags,numpy`)
//! is skipped on purpose. Every skipped comparison is written to `DYNAFLOW_SKIP_LOG` (a
//! folder), from which the script's last line names them all.
#![allow(clippy::panic, dead_code)]

use std::io::Write as _;

/// The peers, as `DYNAFLOW_SKIP_PEERS` names them.
pub const PEERS: &[&str] =
    &["opencv", "evo", "onnxruntime", "octomap", "rerun", "mcap", "gpu", "chromium", "rosbags", "numpy"];

fn skipped_on_purpose(peer: &str) -> bool {
    std::env::var("DYNAFLOW_SKIP_PEERS")
        .is_ok_and(|list| list.split(',').map(str::trim).any(|p| p == peer || p == "all"))
}

/// Records that `comparison` did not run (on stderr, and in `DYNAFLOW_SKIP_LOG`).
pub fn note_skip(peer: &str, comparison: &str, why: &str) {
    eprintln!("note: skipping `{comparison}`: peer `{peer}` {why}");
    if let Some(dir) = std::env::var_os("DYNAFLOW_SKIP_LOG") {
        let path = std::path::Path::new(&dir).join(format!("skips-{}.txt", std::process::id()));
        if let Ok(mut f) = std::fs::OpenOptions::new().create(true).append(true).open(path) {
            let _ = writeln!(f, "{comparison} ({peer}: {why})");
        }
    }
}

/// Whether `comparison` against `peer` runs: not when the peer is named in
/// `DYNAFLOW_SKIP_PEERS`; else when `probe` finds it; a missing peer fails under
/// `DYNAFLOW_REQUIRE_PEERS` and is skipped (visibly) otherwise.
pub fn peer_runs(peer: &str, comparison: &str, probe: impl FnOnce() -> Result<(), String>) -> bool {
    assert!(PEERS.contains(&peer), "unknown peer `{peer}`");
    if skipped_on_purpose(peer) {
        note_skip(peer, comparison, "named in DYNAFLOW_SKIP_PEERS");
        return false;
    }
    match probe() {
        Ok(()) => true,
        Err(why) => {
            assert!(
                std::env::var_os("DYNAFLOW_REQUIRE_PEERS").is_none(),
                "`{comparison}` needs peer `{peer}`, which is missing ({why}): run scripts/peers.sh, or skip it \
                 visibly with DYNAFLOW_SKIP_PEERS={peer}"
            );
            note_skip(peer, comparison, &format!("not installed ({why})"));
            false
        }
    }
}

/// The peers' virtual environment: `DYNAFLOW_PEERS`, else `target/peers` as `scripts/peers.sh`
/// makes it.
pub fn venv() -> std::path::PathBuf {
    std::env::var_os("DYNAFLOW_PEERS").map_or_else(
        || {
            // The workspace root: the crate's folder, or its parent for the member crates.
            let manifest = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
            let root = if manifest.join("Cargo.lock").exists() { manifest.clone() } else { manifest.join("..") };
            let target =
                std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root.join("target"), std::path::PathBuf::from);
            target.join("peers")
        },
        std::path::PathBuf::from,
    )
}
