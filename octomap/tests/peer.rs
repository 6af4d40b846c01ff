//! Our octree against OctoMap 1.9 itself (`tests/peers/octomap_peer.cpp`, built with g++
//! against Debian's liboctomap-dev): the same scans in, the same `.ot` and `.bt` bytes out.
//! Skips when no compiler or library is there, unless `DYNAFLOW_REQUIRE_PEERS` is set (CI).
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use common::{Scan, octomap_peer, run_peer};
use dynaflow_octomap::io::{bt_bytes, ot_bytes};
use dynaflow_octomap::{OcTree, Params};

/// A box room seen from a few places, with a pillar and some far points beyond the range.
fn room_scans() -> Vec<Scan> {
    let mut scans = Vec::new();
    for s in 0..6 {
        let origin = [0.3 * s as f32 - 0.7, 0.11 * s as f32, 1.2 + 0.05 * s as f32];
        let mut pts = Vec::new();
        for i in 0..90 {
            for j in 0..60 {
                // A fan of rays, each ending on the room's walls (x = +-2.5, y = +-2, z = 0, 2.6).
                let az = -1.4 + 2.8 * i as f64 / 89.0 + 0.3 * s as f64;
                let el = -0.9 + 1.5 * j as f64 / 59.0;
                let d = [az.cos() * el.cos(), az.sin() * el.cos(), el.sin()];
                let o = [f64::from(origin[0]), f64::from(origin[1]), f64::from(origin[2])];
                let mut t = f64::MAX;
                for (axis, lo, hi) in [(0, -2.5, 2.5), (1, -2.0, 2.0), (2, 0.0, 2.6)] {
                    if d[axis] > 1e-9 {
                        t = t.min((hi - o[axis]) / d[axis]);
                    } else if d[axis] < -1e-9 {
                        t = t.min((lo - o[axis]) / d[axis]);
                    }
                }
                // A pillar at (1, 0.5): radius 0.3.
                let (px, py) = (o[0] - 1.0, o[1] - 0.5);
                let a = d[0] * d[0] + d[1] * d[1];
                let b = 2.0 * (px * d[0] + py * d[1]);
                let c = px * px + py * py - 0.09;
                let disc = b * b - 4.0 * a * c;
                if a > 0.0 && disc > 0.0 {
                    let tp = (-b - disc.sqrt()) / (2.0 * a);
                    if tp > 0.0 {
                        t = t.min(tp);
                    }
                }
                pts.push([(o[0] + t * d[0]) as f32, (o[1] + t * d[1]) as f32, (o[2] + t * d[2]) as f32]);
            }
        }
        scans.push((pts, origin, if s % 2 == 0 { -1.0 } else { 3.0 }));
    }
    scans
}

#[test]
fn our_files_equal_octomaps_for_the_same_scans() {
    let dir = std::env::temp_dir().join(format!("dynaflow-octo-peer-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let Some(peer) = octomap_peer(&dir, "octomap::peer::our_files_equal_octomaps_for_the_same_scans: vs liboctomap")
    else {
        return;
    };
    let scans = room_scans();
    let report = run_peer(&peer, &scans, 0.05, &dir, "peer");
    let mut tree = OcTree::new(Params::default(), false).unwrap();
    for (pts, origin, range) in &scans {
        tree.insert_scan(pts, None, *origin, *range).expect("within the memory budget");
    }
    let theirs_ot = std::fs::read(dir.join("peer.ot")).unwrap();
    let theirs_bt = std::fs::read(dir.join("peer.bt")).unwrap();
    let (ours_ot, ours_bt) = (ot_bytes(&tree), bt_bytes(&tree));
    eprintln!(
        "OctoMap: {report}\nours: {} nodes, {} leaves, {} occupied; .ot {} / {} bytes, .bt {} / {} bytes",
        tree.size(),
        tree.leaves().len(),
        tree.occupied_leaves().len(),
        ours_ot.len(),
        theirs_ot.len(),
        ours_bt.len(),
        theirs_bt.len()
    );
    assert!(ours_ot == theirs_ot, ".ot differs from OctoMap's");
    assert!(ours_bt == theirs_bt, ".bt differs from OctoMap's");
    let _ = std::fs::remove_dir_all(&dir);
}
