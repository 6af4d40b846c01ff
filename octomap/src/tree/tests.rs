use super::scan::{morton, unmorton};
use super::*;

fn tree() -> OcTree {
    OcTree::new(Params::default(), false).unwrap()
}

#[test]
fn hits_and_misses_follow_octomaps_log_odds_and_clamp() {
    let mut t = tree();
    let k = t.grid().key([0.3, 0.2, 0.1]).unwrap();
    t.update(k, true, None);
    assert!((t.search(k).unwrap().log_odds - logodds(0.7)).abs() < 1e-7);
    for _ in 0..20 {
        t.update(k, true, None);
    }
    assert_eq!(t.search(k).unwrap().log_odds, logodds(0.971));
    for _ in 0..40 {
        t.update(k, false, None);
    }
    assert_eq!(t.search(k).unwrap().log_odds, logodds(0.1192));
    // One voxel: 16 levels of single children plus the root.
    assert_eq!(t.size(), 17);
    assert!(t.search(Key([1, 2, 3])).is_none());
}

#[test]
fn eight_equal_siblings_are_pruned_and_expand_again() {
    let mut t = tree();
    let base = t.grid().key([0.0, 0.0, 0.0]).unwrap();
    let sib = |i: u16| Key([base.0[0] + (i & 1), base.0[1] + ((i >> 1) & 1), base.0[2] + ((i >> 2) & 1)]);
    for i in 0..8 {
        t.update(sib(i), true, None);
    }
    assert_eq!(t.size(), 16, "the eight leaves merged into their parent");
    assert_eq!(t.leaves().len(), 1);
    assert_eq!(t.leaves()[0].size, 2);
    t.update(sib(3), true, None);
    assert_eq!(t.size(), 24, "expanded back into eight");
    assert!(t.search(sib(3)).unwrap().log_odds > t.search(sib(2)).unwrap().log_odds);
}

#[test]
fn a_scan_clears_its_rays_and_marks_its_end_points() {
    let mut t = tree();
    let wall: Vec<[f32; 3]> =
        (0..20).flat_map(|i| (0..20).map(move |j| [2.0, -0.5 + i as f32 * 0.05, -0.5 + j as f32 * 0.05])).collect();
    t.insert_scan(&wall, None, [0.01, 0.01, 0.01], -1.0).unwrap();
    assert!(t.occupancy_at([2.0, 0.0, 0.0]).unwrap() > 0.5);
    assert!(t.occupancy_at([1.0, 0.0, 0.0]).unwrap() < 0.5);
    assert!(t.occupancy_at([3.0, 0.0, 0.0]).is_none(), "behind the wall is unknown");
    match t.cast_ray([0.01, 0.01, 0.01], [1.0, 0.0, 0.0], -1.0) {
        RayHit::Occupied(p) => assert!((p[0] - 2.025).abs() < 1e-9, "{p:?}"),
        other => panic!("{other:?}"),
    }
    assert_eq!(t.cast_ray([0.01, 0.01, 0.01], [1.0, 0.0, 0.0], 1.0), RayHit::Free);
    let occupied_now = t.last_changes().iter().filter(|c| c.1).count();
    assert_eq!(occupied_now, t.occupied_leaves().iter().map(|l| (l.size as usize).pow(3)).sum::<usize>());
    // The same scan again changes nothing.
    t.insert_scan(&wall, None, [0.01, 0.01, 0.01], -1.0).unwrap();
    assert!(t.last_changes().is_empty());
    assert!(matches!(t.cast_ray([0.01, 0.01, 0.01], [0.0, 0.0, -1.0], -1.0), RayHit::Unknown(_)));
    // Beyond max range: the ray is cleared to the range, nothing is marked.
    let mut u = tree();
    u.insert_scan(&wall, None, [0.01, 0.01, 0.01], 1.0).unwrap();
    assert!(u.occupancy_at([2.0, 0.0, 0.0]).is_none());
    assert!(u.occupancy_at([0.9, 0.0, 0.0]).unwrap() < 0.5);
}

#[test]
fn a_semantic_tree_keeps_colour_and_class() {
    let mut t = OcTree::new(Params::default(), true).unwrap();
    let pts = [[1.0f32, 0.0, 0.0], [1.01, 0.01, 0.0], [2.0, 0.0, 0.0]];
    let labels = [
        Label { color: [10, 20, 30], class: 5 },
        Label { color: [30, 40, 50], class: 5 },
        Label { color: [200, 0, 0], class: 1 },
    ];
    t.insert_scan(&pts, Some(&labels), [0.0, 0.0, 0.0], -1.0).unwrap();
    let k = t.grid().key([1.0, 0.0, 0.0]).unwrap();
    let n = t.search(k).unwrap();
    assert_eq!((n.color, n.class, n.color_set()), ([20, 30, 40], 5, true));
    assert_eq!(t.search(t.grid().key([2.0, 0.0, 0.0]).unwrap()).unwrap().class, 1);
}

#[test]
fn morton_codes_round_trip_and_order_depth_first() {
    for k in [Key([0, 0, 0]), Key([65_535, 1, 32_768]), Key([12_345, 54_321, 777])] {
        assert_eq!(unmorton(morton(k)), k);
    }
    // The eight children of one node are consecutive.
    assert_eq!(morton(Key([1, 1, 1])), 7);
    assert!(morton(Key([1, 1, 1])) < morton(Key([2, 0, 0])));
}

/// A fan of rays from the origin to a wall `at` metres away.
fn fan(at: f32, n: usize) -> Vec<[f32; 3]> {
    (0..n).flat_map(|i| (0..n).map(move |j| [at, -0.5 + i as f32 / n as f32, -0.4 + j as f32 / n as f32])).collect()
}

#[test]
fn the_blocks_a_scan_adds_are_counted_exactly_before_it_runs() {
    let mut t = tree();
    for (scan, origin) in [(fan(2.0, 30), [0.01f32, 0.02, 0.03]), (fan(3.0, 25), [0.3, -0.2, 0.1])] {
        // The count the budget uses, on the tree as it is (the scan's sorted key lists).
        let mut probe = t.clone();
        probe.insert_scan(&scan, None, origin, -1.0).unwrap();
        let (free, occupied) = (probe.scratch.free.list.clone(), probe.scratch.occupied.list.clone());
        let predicted = t.new_blocks(&free, &occupied, true);
        assert!(predicted <= t.new_blocks(&free, &occupied, false), "the quick bound bounds");
        let (allocated, released) = (t.allocated, t.released);
        t.insert_scan(&scan, None, origin, -1.0).unwrap();
        let (used, pruned) = (t.allocated - allocated, t.released - released);
        // Every predicted block is taken; more only under nodes the scan pruned.
        assert!(predicted <= used && used <= predicted + pruned, "used {used}, pruned {pruned}, predicted {predicted}");
    }
}

#[test]
fn a_scan_over_the_memory_budget_is_refused_and_changes_nothing() {
    let params = Params { max_memory_bytes: 1 << 20, ..Params::default() };
    let mut t = OcTree::new(params, false).unwrap();
    t.insert_scan(&fan(2.0, 10), None, [0.0, 0.0, 0.0], -1.0).unwrap();
    let (leaves, size, bytes) = (t.leaves(), t.size(), t.memory_bytes());
    assert!(!t.last_changes().is_empty());
    // 1 mm voxels over 2 m rays: far past 1 MiB, refused before any work (the visit bound).
    let mut fine = OcTree::new(Params { resolution: 0.001, ..params }, false).unwrap();
    let err = fine.insert_scan(&fan(2.0, 40), None, [0.0, 0.0, 0.0], -1.0).unwrap_err();
    let Error::OverBudget { voxels, scan_bytes, budget, .. } = err.clone() else { panic!("{err}") };
    assert!(voxels >= 1600 * 2000 && scan_bytes > budget, "{err}");
    assert!(err.to_string().contains("over the 1 MiB memory budget"), "{err}");
    assert_eq!(fine.size(), 0);
    // Within the visit bound but not the nodes: refused after the walk, the tree as it was.
    let err = t.insert_scan(&fan(4.0, 60), None, [0.0, 0.0, 0.0], -1.0).unwrap_err();
    assert!(matches!(err, Error::OverBudget { .. }), "{err}");
    assert_eq!((t.leaves(), t.size(), t.memory_bytes()), (leaves, size, bytes));
    assert!(t.last_changes().is_empty(), "a refused scan changed nothing");
    // The arena never grows past the budget while scans fit.
    let mut u = OcTree::new(Params { max_memory_bytes: 8 << 20, ..Params::default() }, false).unwrap();
    for i in 0..40 {
        let _ = u.insert_scan(&fan(1.0 + 0.1 * i as f32, 40), None, [0.1 * i as f32, 0.0, 0.0], -1.0);
        assert!(u.memory_bytes() as u64 <= 8 << 20);
    }
}

#[test]
fn bad_parameters_are_refused() {
    assert!(OcTree::new(Params { resolution: 0.0, ..Params::default() }, false).is_err());
    assert!(OcTree::new(Params { prob_hit: 0.4, ..Params::default() }, false).is_err());
    assert!(OcTree::new(Params { clamp_min: 0.99, ..Params::default() }, false).is_err());
}
