//! The OctoMap peer (`tests/peers/octomap_peer.cpp`) for `octomap/tests/peer.rs` and the
//! workspace's `tests/octomap.rs`.
#![allow(clippy::unwrap_used, clippy::panic, dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// Build the peer into `dir`; `None` (or a panic under `DYNAFLOW_REQUIRE_PEERS`)
/// when g++ or liboctomap is missing.
pub fn octomap_peer(dir: &Path) -> Option<PathBuf> {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(if env!("CARGO_MANIFEST_DIR").ends_with("octomap") {
        "../tests/peers/octomap_peer.cpp"
    } else {
        "tests/peers/octomap_peer.cpp"
    });
    let exe = dir.join("octomap_peer");
    let ok = Command::new("g++")
        .args(["-O2", "-std=c++17"])
        .arg(&src)
        .args(["-loctomap", "-loctomath", "-o"])
        .arg(&exe)
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            std::env::var_os("DYNAFLOW_REQUIRE_PEERS").is_none(),
            "OctoMap peer required: g++ and liboctomap-dev (Debian) must be installed"
        );
        eprintln!("note: no g++ with liboctomap-dev; skipping the OctoMap comparison (CI runs it)");
        return None;
    }
    Some(exe)
}

/// One scan: world points, sensor origin, max range (negative: none).
pub type Scan = (Vec<[f32; 3]>, [f32; 3], f64);

/// Scans as the peer reads them.
pub fn scans_file(scans: &[Scan], path: &Path) {
    let mut b = Vec::new();
    for (pts, origin, range) in scans {
        b.extend((pts.len() as u32).to_le_bytes());
        for v in origin {
            b.extend(v.to_le_bytes());
        }
        b.extend(range.to_le_bytes());
        for p in pts {
            for v in p {
                b.extend(v.to_le_bytes());
            }
        }
    }
    std::fs::write(path, b).unwrap();
}

/// Run the peer on `scans` at `resolution`: its JSON report; it writes `PREFIX.ot` and
/// `PREFIX.bt`.
pub fn run_peer(peer: &Path, scans: &[Scan], resolution: f64, dir: &Path, prefix: &str) -> serde_json::Value {
    scans_file(scans, &dir.join(format!("{prefix}.scans")));
    let out = Command::new(peer)
        .arg(dir.join(format!("{prefix}.scans")))
        .arg(resolution.to_string())
        .arg(dir.join(prefix))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}
