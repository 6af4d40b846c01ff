//! The OctoMap peer (`tests/peers/octomap_peer.cpp`) for `octomap/tests/peer.rs` and the
//! workspace's `tests/octomap.rs`.
#![allow(clippy::unwrap_used, clippy::panic, dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "../../../tests/common/peers.rs"]
pub mod peers;

/// Build the peer into `dir` for `comparison`; `None` when that comparison is skipped
/// ([`peers::peer_runs`]: a panic under `DYNAFLOW_REQUIRE_PEERS` when g++ or liboctomap is
/// missing).
pub fn octomap_peer(dir: &Path, comparison: &str) -> Option<PathBuf> {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(if env!("CARGO_MANIFEST_DIR").ends_with("octomap") {
        "../tests/peers/octomap_peer.cpp"
    } else {
        "tests/peers/octomap_peer.cpp"
    });
    let exe = dir.join("octomap_peer");
    peers::peer_runs("octomap", comparison, || {
        let out = Command::new("g++")
            .args(["-O2", "-std=c++17"])
            .arg(&src)
            .args(["-loctomap", "-loctomath", "-o"])
            .arg(&exe)
            .output()
            .map_err(|e| format!("g++: {e}"))?;
        if out.status.success() {
            Ok(())
        } else {
            Err(format!(
                "g++ with liboctomap-dev: {}",
                String::from_utf8_lossy(&out.stderr).lines().next().unwrap_or("")
            ))
        }
    })
    .then_some(exe)
}

/// One scan: world points, sensor origin, max range (negative: none).
pub type Scan = (Vec<[f32; 3]>, [f32; 3], f64);

/// Scans as the peer reads them.
pub fn scans_file(scans: &[Scan], path: &Path) {
    scans_file_with(scans, None, path);
}

/// Scans as the peer reads them, with a colour per point (`colors`, one list per scan).
pub fn scans_file_with(scans: &[Scan], colors: Option<&[Vec<[u8; 3]>]>, path: &Path) {
    let mut b = Vec::new();
    for (k, (pts, origin, range)) in scans.iter().enumerate() {
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
        if let Some(c) = colors {
            assert_eq!(c[k].len(), pts.len());
            b.extend(c[k].iter().flatten());
        }
    }
    std::fs::write(path, b).unwrap();
}

/// Run the peer on `scans` at `resolution`: its JSON report; it writes `PREFIX.ot` and
/// `PREFIX.bt`.
pub fn run_peer(peer: &Path, scans: &[Scan], resolution: f64, dir: &Path, prefix: &str) -> serde_json::Value {
    run_peer_with(peer, scans, None, resolution, dir, prefix)
}

/// [`run_peer`]; with `colors` (one per point) OctoMap builds a ColorOcTree, colouring each
/// scan's points with `averageNodeColor` after inserting it.
pub fn run_peer_with(
    peer: &Path,
    scans: &[Scan],
    colors: Option<&[Vec<[u8; 3]>]>,
    resolution: f64,
    dir: &Path,
    prefix: &str,
) -> serde_json::Value {
    scans_file_with(scans, colors, &dir.join(format!("{prefix}.scans")));
    let mut cmd = Command::new(peer);
    cmd.arg(dir.join(format!("{prefix}.scans"))).arg(resolution.to_string()).arg(dir.join(prefix));
    if colors.is_some() {
        cmd.arg("color");
    }
    let out = cmd.output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}
