//! The OctoMap operator and library against OctoMap itself: the same depth frames
//! and poses (real ICL-NUIM frames, synthetic walking frames) give the same tree as
//! liboctomap's `insertPointCloud`; OctoMap's tools read our files; people excluded by their
//! masks leave no ghost voxels in their swept volume.
#![allow(clippy::unwrap_used, clippy::panic)]
// `common` and the OctoMap crate's test helpers (`peer`) both include the shared `peers.rs`.
#![allow(clippy::duplicate_mod)]

mod common;
#[path = "../octomap/tests/common/mod.rs"]
mod peer;

use std::collections::HashSet;
use std::path::Path;
use std::process::Command;

use dynaflow_datasets::synth::{Generator, SynthConfig};
use dynaflow_octomap::io::{bt_bytes, ot_bytes};
use dynaflow_octomap::{Key, OcTree, Params, read};
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};

/// Every `step`-th pixel of a depth image back-projected and placed in the world (pixels
/// where `keep` says no are left out), as the `octomap` operator makes its scans: the scan
/// (points, sensor origin, range) and the pixel index of each point.
#[allow(clippy::too_many_arguments)]
fn scan(
    depth: &[f32],
    w: usize,
    k: [f64; 4],
    pose: &Isometry3<f64>,
    step: usize,
    max_range: f64,
    keep: impl Fn(usize) -> bool,
) -> (peer::Scan, Vec<usize>) {
    let [fx, fy, cx, cy] = k;
    let h = depth.len() / w;
    let (mut pts, mut pixels) = (Vec::new(), Vec::new());
    for v in (0..h).step_by(step) {
        for u in (0..w).step_by(step) {
            let i = v * w + u;
            let z = f64::from(depth[i]);
            if z > 0.0 && z.is_finite() && keep(i) {
                let q = pose * Point3::new((u as f64 - cx) * z / fx, (v as f64 - cy) * z / fy, z);
                pts.push([q.x as f32, q.y as f32, q.z as f32]);
                pixels.push(i);
            }
        }
    }
    let t = pose.translation.vector;
    ((pts, [t.x as f32, t.y as f32, t.z as f32], max_range), pixels)
}

/// `n` frames (every `every`-th) of the synthetic walking scene with seed `seed`, the
/// people left out by their ground-truth masks as `graphs/octomap.yaml` does: the scans and
/// each point's image colour.
fn coloured_scans(seed: u64, n: u64, every: u64) -> (Vec<peer::Scan>, Vec<Vec<[u8; 3]>>) {
    let g = Generator::new(SynthConfig { seed, ..SynthConfig::default() });
    let c = g.config().intrinsics.clone();
    (0..n)
        .map(|k| {
            let f = g.frame(k * every, false);
            let kk = [c.fx, c.fy, c.cx, c.cy];
            let (s, pixels) = scan(&f.depth, c.width as usize, kk, &f.world_from_cam, 4, 4.0, |i| f.class[i] == 0);
            let colours = pixels.iter().map(|&i| [f.rgb[3 * i], f.rgb[3 * i + 1], f.rgb[3 * i + 2]]).collect();
            (s, colours)
        })
        .unzip()
}

/// A fresh folder with the OctoMap peer built in it, for `comparison`; `None` when that
/// comparison is skipped.
fn peer_in(tag: &str, comparison: &str) -> Option<(common::TempDir, std::path::PathBuf)> {
    let dir = common::TempDir::new(tag);
    let exe = peer::octomap_peer(dir.path(), &format!("octomap::{comparison}: vs liboctomap"))?;
    Some((dir, exe))
}

/// `compare_octrees`' KLD between two OcTree files.
fn kld(said: &str) -> f64 {
    let line = said.lines().find(|l| l.trim_start().starts_with("KLD:")).unwrap_or_else(|| panic!("no KLD: {said}"));
    line.trim_start().trim_start_matches("KLD:").trim().parse().unwrap_or_else(|_| panic!("{line}"))
}

/// The five ICL-NUIM frames of slambook2's ch12 with their poses.
fn icl_scans() -> Vec<peer::Scan> {
    let dir = common::repo().join("tests/fixtures/slambook2_dense_rgbd");
    let poses = std::fs::read_to_string(dir.join("pose.txt")).unwrap();
    poses
        .lines()
        .enumerate()
        .map(|(i, line)| {
            let v: Vec<f64> = line.split_whitespace().map(|s| s.parse().unwrap()).collect();
            let pose = Isometry3::from_parts(
                Translation3::new(v[0], v[1], v[2]),
                UnitQuaternion::from_quaternion(Quaternion::new(v[6], v[3], v[4], v[5])),
            );
            let img = image::open(dir.join(format!("depth/{}.png", i + 1))).unwrap().into_luma16();
            let w = img.width() as usize;
            let depth: Vec<f32> = img.as_raw().iter().map(|&d| f32::from(d) / 5000.0).collect();
            scan(&depth, w, [481.2, -480.0, 319.5, 239.5], &pose, 4, -1.0, |_| true).0
        })
        .collect()
}

/// `n` frames of the synthetic walking scene, people included.
fn synthetic_scans(n: u64) -> Vec<peer::Scan> {
    let g = Generator::new(SynthConfig::default());
    let c = g.config().intrinsics.clone();
    (0..n)
        .map(|k| {
            let f = g.frame(k * 5, false);
            scan(&f.depth, c.width as usize, [c.fx, c.fy, c.cx, c.cy], &f.world_from_cam, 4, 4.0, |_| true).0
        })
        .collect()
}

fn ours(scans: &[peer::Scan]) -> OcTree {
    let mut t = OcTree::new(Params::default(), false).unwrap();
    for (pts, origin, range) in scans {
        t.insert_scan(pts, None, *origin, *range).expect("within the memory budget");
    }
    t
}

/// Occupancy decision (occupied, free, unknown) of both trees at every voxel centre that is
/// a leaf of either, plus a grid over their joint bounding box: the share that agrees.
fn agreement(a: &OcTree, b: &OcTree) -> (f64, usize) {
    let mut keys: HashSet<Key> = HashSet::new();
    let (mut lo, mut hi) = ([u16::MAX; 3], [0u16; 3]);
    for l in a.leaves().iter().chain(b.leaves().iter()) {
        keys.insert(l.key);
        for i in 0..3 {
            lo[i] = lo[i].min(l.key.0[i]);
            hi[i] = hi[i].max(l.key.0[i]);
        }
    }
    for x in (lo[0]..=hi[0]).step_by(3) {
        for y in (lo[1]..=hi[1]).step_by(3) {
            for z in (lo[2]..=hi[2]).step_by(3) {
                keys.insert(Key([x, y, z]));
            }
        }
    }
    let state = |t: &OcTree, k: Key| t.search(k).map(|n| t.is_occupied(n));
    let same = keys.iter().filter(|&&k| state(a, k) == state(b, k)).count();
    (same as f64 / keys.len() as f64, keys.len())
}

fn compare_octrees(a: &Path, b: &Path) -> String {
    let out = Command::new("compare_octrees").arg(a).arg(b).output().unwrap();
    assert!(out.status.success(), "compare_octrees: {}", String::from_utf8_lossy(&out.stderr));
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

#[test]
fn our_tree_equals_octomaps_on_real_and_synthetic_depth() {
    let Some((dir, exe)) = peer_in("octomap-peer", "our_tree_equals_octomaps_on_real_and_synthetic_depth") else {
        return;
    };
    for (name, scans) in [("icl_nuim", icl_scans()), ("synthetic_walking", synthetic_scans(12))] {
        let report = peer::run_peer(&exe, &scans, 0.05, dir.path(), name);
        let t = ours(&scans);
        let theirs = read(&dir.path().join(format!("{name}.ot"))).unwrap();
        let (occ_ours, occ_theirs) = (t.occupied_leaves().len(), report["occupied_leafs"].as_u64().unwrap() as usize);
        let (share, sampled) = agreement(&t, &theirs);
        eprintln!(
            "{name}: {} rays; occupied leaves ours {occ_ours} / OctoMap {occ_theirs}; same decision at {:.4} % of {sampled} sampled voxels",
            scans.iter().map(|s| s.0.len()).sum::<usize>(),
            100.0 * share
        );
        // The same tree: the same files, byte for byte.
        assert!(ot_bytes(&t) == std::fs::read(dir.path().join(format!("{name}.ot"))).unwrap(), "{name}: .ot differs");
        assert!(bt_bytes(&t) == std::fs::read(dir.path().join(format!("{name}.bt"))).unwrap(), "{name}: .bt differs");
        assert_eq!(occ_ours, occ_theirs);
        assert_eq!(t.leaves().len(), report["leafs"].as_u64().unwrap() as usize);
        assert_eq!(share, 1.0);
        // OctoMap's own comparison of our .ot against its tree: no divergence at all.
        let path = dir.path().join(format!("{name}.ours.ot"));
        dynaflow_octomap::write_ot(&t, &path).unwrap();
        let said = compare_octrees(&path, &dir.path().join(format!("{name}.ot")));
        eprintln!("compare_octrees: {}", said.lines().filter(|l| !l.trim().is_empty()).collect::<Vec<_>>().join(" | "));
        assert!(!said.to_lowercase().contains("error"), "{said}");
        assert_eq!(kld(&said), 0.0, "{said}");
    }
}

#[test]
fn our_color_tree_equals_octomaps_color_octree() {
    // The same coloured scans (synthetic walking frames, people masked out, image colours):
    // OctoMap's ColorOcTree, coloured as octomap_server does (averageNodeColor per point after
    // each insertion, updateInnerOccupancy before writing), and ours write the same bytes.
    let Some((dir, exe)) = peer_in("octomap-color", "our_color_tree_equals_octomaps_color_octree") else { return };
    let (scans, colours) = coloured_scans(3, 10, 6);
    peer::run_peer_with(&exe, &scans, Some(&colours), 0.05, dir.path(), "color");
    let mut t = OcTree::new(Params::default(), true).unwrap();
    for (s, c) in scans.iter().zip(&colours) {
        let labels: Vec<dynaflow_octomap::Label> =
            c.iter().map(|&color| dynaflow_octomap::Label { color, class: 0 }).collect();
        t.insert_scan(&s.0, Some(&labels), s.1, s.2).expect("within the memory budget");
    }
    let theirs = std::fs::read(dir.path().join("color.ot")).unwrap();
    let ours = ot_bytes(&t);
    let coloured = t.leaves().iter().filter(|l| l.node.color_set()).count();
    eprintln!(
        "ColorOcTree: {} nodes, {coloured} coloured leaves; .ot {} / {} bytes",
        t.size(),
        ours.len(),
        theirs.len()
    );
    assert!(coloured > 1000, "{coloured}");
    assert!(ours == theirs, "our ColorOcTree .ot differs from OctoMap's");
}

#[test]
fn the_colour_octree_a_run_writes_equals_octomaps() {
    // `graphs/octomap.yaml` itself: its ColorOcTree file against OctoMap's ColorOcTree built
    // from the same frames (the generator's, with the run's seed), the same way.
    let Some((dir, exe)) = peer_in("octomap-run-color", "the_colour_octree_a_run_writes_equals_octomaps") else {
        return;
    };
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", "6", "--set", "camera.seed=5", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/octomap.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let (scans, colours) = coloured_scans(5, 6, 1);
    peer::run_peer_with(&exe, &scans, Some(&colours), 0.05, dir.path(), "peer");
    let ours = std::fs::read(dir.path().join("octomap.map.ot")).unwrap();
    let theirs = std::fs::read(dir.path().join("peer.ot")).unwrap();
    assert!(ours == theirs, "the run's .ot ({} bytes) differs from OctoMap's ({} bytes)", ours.len(), theirs.len());
}

#[test]
fn octomap_tools_read_the_files_a_run_writes() {
    let dir = common::TempDir::new("octomap-run");
    let graph = common::repo().join("graphs/octomap.yaml");
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", "8", "--out"])
        .arg(dir.path())
        .arg(&graph)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let (ot, bt) = (dir.path().join("octomap.map.ot"), dir.path().join("octomap.map.bt"));
    let tree = read(&ot).unwrap();
    assert!(tree.semantic() && !tree.occupied_leaves().is_empty());
    let tools = || {
        Command::new("convert_octree").arg("--help").output().map(|_| ()).map_err(|e| format!("convert_octree: {e}"))
    };
    if !peer::peers::peer_runs("octomap", "octomap: convert_octree reads a run's files", tools) {
        return;
    }
    for (input, output) in [(&bt, dir.path().join("from_bt.ot")), (&ot, dir.path().join("from_ot.bt"))] {
        let r = Command::new("convert_octree").arg(input).arg(&output).output().unwrap();
        let said = format!("{}{}", String::from_utf8_lossy(&r.stdout), String::from_utf8_lossy(&r.stderr));
        assert!(r.status.success() && output.exists(), "convert_octree {}: {said}", input.display());
    }
    // What OctoMap wrote back reads here too, with the same occupied voxels.
    let back = read(&dir.path().join("from_ot.bt")).unwrap();
    let ml = read(&bt).unwrap();
    assert_eq!(back.occupied_leaves().len(), ml.occupied_leaves().len());
}

/// Voxels whose centre lies inside a person's body part at some frame and more than one
/// voxel from any static surface: the people's swept volume.
fn swept_volume(g: &Generator, frames: u64, res: f64) -> HashSet<Key> {
    let grid = dynaflow_octomap::Grid::new(res);
    let inside = |(pose, half): &(Isometry3<f64>, Vector3<f64>), p: &Point3<f64>, margin: f64| {
        let q = pose.inverse_transform_point(p);
        (0..3).all(|i| q[i].abs() <= half[i] + margin)
    };
    let statics = g.static_boxes();
    let mut out = HashSet::new();
    for k in 0..frames {
        for b in g.people_boxes(k) {
            let r = b.1.norm();
            let c = b.0.translation.vector;
            let lo = grid.key([(c.x - r) as f32, (c.y - r) as f32, (c.z - r) as f32]).unwrap();
            let hi = grid.key([(c.x + r) as f32, (c.y + r) as f32, (c.z + r) as f32]).unwrap();
            for x in lo.0[0]..=hi.0[0] {
                for y in lo.0[1]..=hi.0[1] {
                    for z in lo.0[2]..=hi.0[2] {
                        let key = Key([x, y, z]);
                        let p = grid.centre(key);
                        let p = Point3::new(p[0], p[1], p[2]);
                        if inside(&b, &p, 0.0) && !statics.iter().any(|s| inside(s, &p, res)) {
                            out.insert(key);
                        }
                    }
                }
            }
        }
    }
    out
}

#[test]
fn masked_people_leave_no_trace_and_unmasked_ones_leave_ghosts() {
    let g = Generator::new(SynthConfig::default());
    let c = g.config().intrinsics.clone();
    let frames = 90;
    let (mut masked, mut all) = (ours(&[]), ours(&[]));
    for k in 0..frames {
        let f = g.frame(k, false);
        let kk = [c.fx, c.fy, c.cx, c.cy];
        let ((p, o, r), _) = scan(&f.depth, c.width as usize, kk, &f.world_from_cam, 4, 4.0, |i| f.class[i] == 0);
        masked.insert_scan(&p, None, o, r).expect("within the memory budget");
        let ((p, o, r), _) = scan(&f.depth, c.width as usize, kk, &f.world_from_cam, 4, 4.0, |_| true);
        all.insert_scan(&p, None, o, r).expect("within the memory budget");
    }
    let swept = swept_volume(&g, frames, 0.05);
    let ghosts = |t: &OcTree| swept.iter().filter(|&&k| t.search(k).is_some_and(|n| t.is_occupied(n))).count();
    let (gm, ga) = (ghosts(&masked), ghosts(&all));
    let share = |n: usize| 100.0 * n as f64 / swept.len() as f64;
    eprintln!(
        "swept volume {} voxels; occupied at the end: masked {gm} ({:.2} %), unmasked {ga} ({:.2} %)",
        swept.len(),
        share(gm),
        share(ga)
    );
    assert!(swept.len() > 1000);
    // Bounded by what the same frames give without masks: the masks take away at least three
    // quarters of the ghost voxels (what stays are pixels at the masks' borders, where the
    // Kinect model mixes a person's depth with the wall's), and without masks the people
    // leave a trail over at least 1 % of their swept volume.
    assert!(4 * gm <= ga, "masked {gm} ghost voxels, unmasked {ga}");
    assert!(share(ga) >= 1.0, "unmasked: {:.2} %", share(ga));
}

#[test]
fn octree_command_summarises_plots_and_refuses_corrupt_files() {
    let dir = common::TempDir::new("octree-cli");
    let mut t = OcTree::new(Params::default(), false).unwrap();
    for (p, o, r) in icl_scans().iter().take(2) {
        t.insert_scan(p, None, *o, *r).expect("within the memory budget");
    }
    let (ot, bt) = (dir.path().join("t.ot"), dir.path().join("t.bt"));
    dynaflow_octomap::write_ot(&t, &ot).unwrap();
    dynaflow_octomap::write_bt(&t, &bt).unwrap();
    let png = dir.path().join("top.png");
    let out = common::bin().arg("octree").arg(&ot).arg("--plot").arg(&png).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["occupied_leaves"].as_u64().unwrap() as usize, t.occupied_leaves().len());
    assert_eq!(v["type"], "OcTree");
    let img = image::open(&png).unwrap().into_rgb8();
    assert!(img.pixels().any(|p| p.0 != [255, 255, 255]), "the plot draws something");
    // Truncated, flipped and foreign files: exit 2 with the file named, never a panic.
    let bytes = std::fs::read(&bt).unwrap();
    let cut = dir.path().join("cut.bt");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let text = common::repo().join("README.md");
    for bad in [cut.as_path(), text.as_path(), Path::new("/nonexistent.ot")] {
        let out = common::bin().arg("octree").arg(bad).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{}: {err}", bad.display());
        assert!(err.contains(&bad.display().to_string()) && !err.contains("panicked"), "{err}");
    }
}

#[test]
fn a_resolution_too_fine_for_the_memory_budget_ends_the_run_with_an_error_and_valid_files() {
    // `resolution: 0.001` (inside its documented range) made one frame take
    // gigabytes and three abort on allocation (exit 134, no summary, an MCAP without footer).
    // Now the first frame is refused on the default 4 GiB budget before its nodes are
    // allocated: exit 1, the error says what it needed and what to change, the summary names
    // the node, the map of the frames before is written and the MCAP is complete.
    let dir = common::TempDir::new("octomap-budget");
    let out = common::bin()
        .args(["run", "--no-progress", "--record", "mcap", "--frames", "3", "--set", "map.resolution=0.001", "--out"])
        .arg(dir.path())
        .arg(common::repo().join("graphs/octomap.yaml"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("frame 0") && err.contains("over the 4096 MiB memory budget"), "{err}");
    assert!(err.contains("raise `resolution` or `subsample`"), "{err}");
    let summary = common::summary(&dir.path().join("octomap.summary.json"));
    assert_eq!(summary.run.status, dynaflow_engine::runtime::RunStatus::Failed);
    assert_eq!(summary.run.failures[0].node, "map");
    // The (empty) map is a valid OctoMap file; the recording reads to its end.
    let tree = read(&dir.path().join("octomap.map.ot")).unwrap();
    assert_eq!(tree.size(), 0);
    let rec = dynaflow_recordings::diff::read_mcap(&dir.path().join("octomap.mcap")).unwrap();
    assert!(!rec.topics.is_empty());
}
