//! The geometric front-end against OpenCV, side by side on the same images and points,
//! single-threaded on both sides: ORB (1000 features, 8 levels, 640x480), Hamming matching,
//! and pyramidal LK (1000 points, window 21, maxLevel 3), with quality next to speed.
//!
//! `cargo bench --bench frontend` (add `-- REPS`, default 30). The OpenCV side is
//! `tests/peers/frontend_cv2.py` in the peers venv (`DYNAFLOW_PEERS`, default
//! `<target folder>/peers`, as `scripts/peers.sh` makes it).
#![allow(clippy::unwrap_used, clippy::panic)]

#[path = "common/timing.rs"]
mod timing;

#[path = "../tests/common/mod.rs"]
mod common;
#[path = "../vision/tests/common/frontend.rs"]
mod frontend;

use timing::median_ms;

use dynaflow_vision::flow::{LkConfig, LkTracker, Pyramid};
use dynaflow_vision::geometry::{RansacConfig, SplitMix64, fit_fundamental, pnp_ransac};
use dynaflow_vision::matching::{MatchConfig, match_brute_force};
use dynaflow_vision::orb::{Distribution, OrbConfig, OrbExtractor};
use serde_json::json;

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let reps: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(30);
    let dir = std::env::temp_dir().join(format!("dynaflow-bench-frontend-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ch7 = frontend::ch7();
    let ch8 = frontend::ch8();
    let (a7, b7) = (frontend::load_gray(&ch7[0]), frontend::load_gray(&ch7[1]));

    // ORB, in both distribution modes, and matching.
    let mut orb_ms = Vec::new();
    for distribution in [Distribution::Quadtree, Distribution::Harris] {
        let mut orb = OrbExtractor::new(OrbConfig { distribution, ..OrbConfig::default() });
        orb_ms.push(median_ms(reps, || {
            std::hint::black_box(orb.extract(&a7, None));
        }));
    }
    // ORB-SLAM's extractor with the default matcher, and OpenCV's recipe (Harris selection,
    // cross-check-only matching) for the like-for-like comparison.
    let (fa, fb, q_prev, q_cur) = frontend::our_matches(&a7, &b7, Distribution::Quadtree, &MatchConfig::default());
    let (_, _, h_prev, h_cur) = frontend::our_matches(&a7, &b7, Distribution::Harris, &frontend::cross_check_only());
    let angles = |f: &dynaflow_vision::orb::OrbFeatures| f.keypoints.iter().map(|k| k.angle).collect::<Vec<_>>();
    let (qa, ta) = (angles(&fb), angles(&fa));
    let match_ms = median_ms(reps, || {
        std::hint::black_box(match_brute_force(
            &fb.descriptors,
            &fa.descriptors,
            Some((&qa, &ta)),
            &MatchConfig::default(),
        ));
    });

    // LK on the real pair and on a synthetic pair with ground truth.
    let (a8, b8) = (frontend::load_gray(&ch8[0]), frontend::load_gray(&ch8[1]));
    let syn = frontend::synth_pair(10);
    let (sa, sb) = (dir.join("synth_a.png"), dir.join("synth_b.png"));
    frontend::save_gray(&syn.a, &sa);
    frontend::save_gray(&syn.b, &sb);
    let mut lk = LkTracker::new(LkConfig::default());
    let mut lk_cases = Vec::new();
    let mut ours_lk = Vec::new();
    for (name, a, b, pa_path, pb_path) in
        [("ch8", &a8, &b8, ch8[0].clone(), ch8[1].clone()), ("synth", &syn.a, &syn.b, sa.clone(), sb.clone())]
    {
        let mut pts = frontend::lk_points(a, 1000);
        if name == "synth" {
            pts.retain(|p| syn.class[p[1] as usize * syn.a.width + p[0] as usize] == 0);
        }
        let (mut pa, mut pb) = (Pyramid::default(), Pyramid::default());
        // Each call builds both pyramids (gradients for the first only), as OpenCV's does.
        let ms = median_ms(reps, || {
            pa.build(a, 3);
            pb.build_levels(b, 3);
            std::hint::black_box(lk.track(&pa, &pb, &pts));
        });
        let res = lk.track(&pa, &pb, &pts);
        pb.ensure_gradients();
        let back = lk.track(&pb, &pa, &res.iter().map(|r| r.point).collect::<Vec<_>>());
        let gt: Vec<[f32; 2]> = if name == "synth" {
            pts.iter()
                .map(|p| {
                    let f = syn.flow[p[1] as usize * syn.a.width + p[0] as usize];
                    [p[0] + f[0], p[1] + f[1]]
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut case = json!({ "name": name, "images": [pa_path, pb_path], "points": pts });
        if !gt.is_empty() {
            case["gt"] = json!(gt);
        }
        lk_cases.push(case);
        ours_lk.push((name, ms, pts.len(), res, back, pts, gt));
    }

    // Fundamental-matrix RANSAC on real ORB matches and synthetic LK tracks.
    let f_cases = frontend::fundamental_cases();
    let f_ours: Vec<(f64, usize)> = f_cases
        .iter()
        .map(|(_, p1, p2)| {
            let config = RansacConfig::default();
            let ms = median_ms(reps, || {
                std::hint::black_box(fit_fundamental(p1, p2, &config, &mut SplitMix64::new(7)));
            });
            (ms, fit_fundamental(p1, p2, &config, &mut SplitMix64::new(7)).map_or(0, |f| f.inlier_count()))
        })
        .collect();

    // PnP RANSAC + motion-only BA on the real RGB-D pair.
    let (pnp_world, pnp_pixels, pnp_cam) = frontend::ch7_pnp();
    let pnp_ms = median_ms(reps, || {
        std::hint::black_box(pnp_ransac(
            &pnp_world,
            &pnp_pixels,
            &pnp_cam,
            &RansacConfig { threshold: 3.0, max_iterations: 500, ..RansacConfig::default() },
            &mut SplitMix64::new(7),
        ));
    });

    println!("front-end, single thread, median of {reps} calls; peer: OpenCV (cv2) on the same inputs");
    let cv = frontend::cv2_python("bench frontend: OpenCV side by side").map(|py| {
        let job = json!({
            "reps": reps,
            "orb": { "images": ch7, "ours": [
                { "name": "quadtree", "prev": q_prev, "cur": q_cur },
                { "name": "harris", "prev": h_prev, "cur": h_cur },
            ] },
            "lk": lk_cases,
            "fundamental": f_cases.iter().map(|(name, p1, p2)| json!({ "name": name, "p1": p1, "p2": p2 })).collect::<Vec<_>>(),
            "pnp": [{
                "name": "ch7",
                "world": pnp_world.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>(),
                "pixels": pnp_pixels,
                "k": [[pnp_cam.fx, 0.0, pnp_cam.cx], [0.0, pnp_cam.fy, pnp_cam.cy], [0.0, 0.0, 1.0]],
            }],
        });
        frontend::run_cv2(&py, &dir, &job)
    });
    let ratio =
        |ours: f64, theirs: Option<f64>| theirs.map_or_else(|| "   n/a".to_owned(), |t| format!("{:5.2}x", ours / t));
    let cvf = |path: &[&str]| {
        let mut v = cv.as_ref()?;
        for p in path {
            v = v.get(p)?;
        }
        v.as_f64()
    };
    println!("{:<34} {:>10} {:>10} {:>8}", "", "dynaflow", "OpenCV", "ours/cv");
    let cv_orb = cvf(&["orb", "ms"]);
    for (name, ms) in ["ORB 1000 quadtree (ch7 640x480)", "ORB 1000 harris (ch7 640x480)"].iter().zip(&orb_ms) {
        println!("{:<34} {:>8.2}ms {:>8.2}ms {:>8}", name, ms, cv_orb.unwrap_or(f64::NAN), ratio(*ms, cv_orb));
    }
    println!(
        "{:<34} {:>10} {:>10}",
        "  keypoints",
        fa.keypoints.len(),
        cvf(&["orb", "count"]).map_or("n/a".into(), |v| format!("{v}"))
    );
    println!(
        "{:<34} {:>8.2}ms {:>8.2}ms {:>8}",
        "match (Hamming, cross-check)",
        match_ms,
        cvf(&["orb", "match_ms"]).unwrap_or(f64::NAN),
        ratio(match_ms, cvf(&["orb", "match_ms"]))
    );
    let show = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.0}"));
    println!(
        "{:<34} {:>10} {:>10}",
        "  F-RANSAC inliers, harris+xcheck",
        show(cvf(&["orb", "ours_inliers", "harris"])),
        show(cvf(&["orb", "inliers"]))
    );
    println!(
        "{:<34} {:>10} {:>10}",
        "  F-RANSAC inliers, quadtree+ratio",
        show(cvf(&["orb", "ours_inliers", "quadtree"])),
        show(cvf(&["orb", "inliers"]))
    );
    let mut total_ours = orb_ms[0] + match_ms;
    let mut total_cv = cvf(&["orb", "ms"]).unwrap_or(f64::NAN) + cvf(&["orb", "match_ms"]).unwrap_or(f64::NAN);
    for (name, ms, n, res, back, pts, gt) in &ours_lk {
        let theirs = cvf(&["lk", name, "ms"]);
        println!(
            "{:<34} {:>8.2}ms {:>8.2}ms {:>8}",
            format!("LK {n} pts ({name})"),
            ms,
            theirs.unwrap_or(f64::NAN),
            ratio(*ms, theirs)
        );
        if *name == "ch8" {
            total_ours += ms;
            total_cv += theirs.unwrap_or(f64::NAN);
        }
        let found = res.iter().filter(|r| r.found).count();
        println!(
            "{:<34} {:>10} {:>10}",
            "  found",
            found,
            cvf(&["lk", name, "found"]).map_or("n/a".into(), |v| format!("{v}"))
        );
        let fb_ours = median(
            res.iter()
                .zip(back)
                .zip(pts)
                .filter(|((r, b), _)| r.found && b.found)
                .map(|((_, b), p)| f64::from(((b.point[0] - p[0]).powi(2) + (b.point[1] - p[1]).powi(2)).sqrt()))
                .collect(),
        );
        let fb_cv = cv.as_ref().and_then(|c| {
            let l = &c["lk"][name];
            let v: Vec<f64> = l["fb"]
                .as_array()?
                .iter()
                .zip(l["fb_ok"].as_array()?)
                .filter(|(_, ok)| ok.as_bool() == Some(true))
                .filter_map(|(e, _)| e.as_f64())
                .collect();
            Some(median(v))
        });
        println!("{:<34} {:>10.4} {:>10.4}", "  median forward-backward error px", fb_ours, fb_cv.unwrap_or(f64::NAN));
        if !gt.is_empty() {
            let epe = median(
                res.iter()
                    .zip(gt)
                    .filter(|(r, _)| r.found)
                    .map(|(r, g)| f64::from(((r.point[0] - g[0]).powi(2) + (r.point[1] - g[1]).powi(2)).sqrt()))
                    .collect(),
            );
            let epe_cv = cv.as_ref().and_then(|c| {
                let l = &c["lk"][name];
                let v: Vec<f64> = l["epe"]
                    .as_array()?
                    .iter()
                    .zip(l["status"].as_array()?)
                    .filter(|(_, s)| s.as_f64() == Some(1.0))
                    .filter_map(|(e, _)| e.as_f64())
                    .collect();
                Some(median(v))
            });
            println!("{:<34} {:>10.4} {:>10.4}", "  median endpoint error px (GT)", epe, epe_cv.unwrap_or(f64::NAN));
        }
    }
    for ((name, p1, _), (ms, inliers)) in f_cases.iter().zip(&f_ours) {
        for method in ["ransac", "magsac"] {
            let theirs = cvf(&["fundamental", name, method, "ms"]);
            let cv_inliers = cv.as_ref().and_then(|c| {
                Some(
                    c["fundamental"][name][method]["inliers"]
                        .as_array()?
                        .iter()
                        .filter(|v| v.as_i64() == Some(1))
                        .count(),
                )
            });
            println!(
                "{:<34} {:>8.2}ms {:>8.2}ms {:>8}   inliers {} vs {}",
                format!("F LO-RANSAC vs {method} ({name}, {})", p1.len()),
                ms,
                theirs.unwrap_or(f64::NAN),
                ratio(*ms, theirs),
                inliers,
                cv_inliers.map_or("n/a".into(), |c| c.to_string())
            );
        }
    }
    let cv_pnp = cvf(&["pnp", "ch7", "ms"]);
    println!(
        "{:<34} {:>8.2}ms {:>8.2}ms {:>8}",
        format!("PnP RANSAC + BA ({} pts, ch7)", pnp_world.len()),
        pnp_ms,
        cv_pnp.unwrap_or(f64::NAN),
        ratio(pnp_ms, cv_pnp)
    );
    println!(
        "{:<34} {:>8.2}ms {:>8.2}ms {:>8}",
        "ORB + match + LK (ch8), together",
        total_ours,
        total_cv,
        ratio(total_ours, total_cv.is_finite().then_some(total_cv))
    );
    // The colour-to-grey conversion each front-end operator does on its own (ours only).
    let rgb = image::open(&ch7[0]).unwrap().to_rgb8();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let grey_ms = median_ms(reps, || {
        std::hint::black_box(dynaflow_vision::image::GrayImage::from_rgb8(w, h, rgb.as_raw()));
    });
    println!("{:<34} {:>8.2}ms", format!("RGB -> grey ({w}x{h})"), grey_ms);
    let _ = std::fs::remove_dir_all(&dir);
}
