//! OctoMap insertion, ours against OctoMap 1.9 itself, side by side in one run on the same
//! scans (same points, same origins, same range), one core each: milliseconds per frame and
//! memory per million leaves.
//!
//! `cargo bench --bench octomap` (add `-- FRAMES`, default 60). Needs g++ and Debian's
//! liboctomap-dev for the peer (`tests/peers/octomap_peer.cpp`).
#![allow(clippy::unwrap_used, clippy::panic)]

#[path = "../octomap/tests/common/mod.rs"]
mod peer;

use std::time::Instant;

use dynaflow_datasets::synth::{Generator, SynthConfig};
use dynaflow_octomap::{OcTree, Params};
use nalgebra::Point3;

fn main() {
    let frames: u64 = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(60);
    let dir = std::env::temp_dir().join(format!("dynaflow-bench-octomap-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let g = Generator::new(SynthConfig::default());
    let c = g.config().intrinsics.clone();
    let (w, h) = (c.width as usize, c.height as usize);
    println!("# OctoMap insertion: synthetic walking scene, {frames} frames of {w}x{h}, 5 cm voxels, max range 4 m\n");
    println!(
        "| subsample | rays per frame | ours ms/frame (mean / median) | OctoMap ms/frame (mean / median) | OctoMap / ours | occupied leaves ours / OctoMap | bytes per leaf ours / OctoMap |"
    );
    println!("|---|---|---|---|---|---|---|");
    let depth_frames: Vec<_> = (0..frames).map(|k| g.frame(k, false)).collect();
    for step in [4usize, 2, 1] {
        let scans: Vec<peer::Scan> = depth_frames
            .iter()
            .map(|f| {
                let mut pts = Vec::new();
                for v in (0..h).step_by(step) {
                    for u in (0..w).step_by(step) {
                        let z = f64::from(f.depth[v * w + u]);
                        if z > 0.0 {
                            let q = f.world_from_cam
                                * Point3::new((u as f64 - c.cx) * z / c.fx, (v as f64 - c.cy) * z / c.fy, z);
                            pts.push([q.x as f32, q.y as f32, q.z as f32]);
                        }
                    }
                }
                let t = f.world_from_cam.translation.vector;
                (pts, [t.x as f32, t.y as f32, t.z as f32], 4.0)
            })
            .collect();
        let rays = scans.iter().map(|s| s.0.len()).sum::<usize>() / scans.len().max(1);
        let mut tree = OcTree::new(Params::default(), false).unwrap();
        let mut ours: Vec<f64> = scans
            .iter()
            .map(|(p, o, r)| {
                let t = Instant::now();
                tree.insert_scan(p, None, *o, *r).expect("within the memory budget");
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        let leaves = tree.leaves().len();
        let occupied = tree.occupied_leaves().len();
        let stats = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            (v.iter().sum::<f64>() / v.len().max(1) as f64, v[v.len() / 2])
        };
        let (om, od) = stats(&mut ours);
        let peer_row = peer::octomap_peer(&dir, "bench octomap: liboctomap side by side")
            .map(|exe| peer::run_peer(&exe, &scans, 0.05, &dir, "bench"));
        match peer_row {
            Some(r) => {
                let mut theirs: Vec<f64> = r["ms"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
                let (tm, td) = stats(&mut theirs);
                let t_leaves = r["leafs"].as_f64().unwrap();
                println!(
                    "| {step} | {rays} | {om:.1} / {od:.1} | {tm:.1} / {td:.1} | {:.2}x | {occupied} / {} | {:.1} / {:.1} |",
                    tm / om,
                    r["occupied_leafs"],
                    tree.memory_bytes() as f64 / leaves as f64,
                    r["memory_bytes"].as_f64().unwrap() / t_leaves
                );
            }
            None => println!("| {step} | {rays} | {om:.1} / {od:.1} | (no peer) | | {occupied} / | |"),
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
