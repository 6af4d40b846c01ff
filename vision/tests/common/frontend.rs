//! Shared by `vision/tests/frontend.rs`, the workspace's end-to-end tests and
//! `benches/frontend.rs`: the images, our side of the front-end comparison, and the OpenCV
//! peer (`tests/peers/frontend_cv2.py`).
#![allow(clippy::unwrap_used, clippy::panic, dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

use dynaflow_datasets::synth::{Generator, SynthConfig};
use dynaflow_vision::GrayImage;
use dynaflow_vision::flow::{LkConfig, LkTracker, Pyramid, seed_corners};
use dynaflow_vision::matching::{MatchConfig, match_brute_force};
use dynaflow_vision::orb::{Distribution, OrbConfig, OrbExtractor, OrbFeatures};

/// The repository root (the workspace's folder, whichever member crate's test this is).
pub fn repo() -> PathBuf {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    manifest.ancestors().find(|d| d.join("Cargo.lock").exists()).map_or(manifest.clone(), Path::to_path_buf)
}

/// The real Kinect pair (slambook2 ch7) and the real LK pair (slambook2 ch8).
pub fn ch7() -> [PathBuf; 2] {
    let d = repo().join("tests/fixtures/slambook2_rgbd_pair/rgb");
    [d.join("1.png"), d.join("2.png")]
}
pub fn ch8() -> [PathBuf; 2] {
    let d = repo().join("tests/fixtures/slambook2_lk_pair");
    [d.join("LK1.png"), d.join("LK2.png")]
}

/// A PNG as grey, with OpenCV's conversion weights (what `cv2.imread(.., GRAYSCALE)` gives).
pub fn load_gray(path: &Path) -> GrayImage {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    match img {
        image::DynamicImage::ImageLuma8(g) => {
            let (w, h) = g.dimensions();
            GrayImage::from_vec(w as usize, h as usize, g.into_raw()).unwrap()
        }
        other => {
            let rgb = other.to_rgb8();
            let (w, h) = rgb.dimensions();
            GrayImage::from_rgb8(w as usize, h as usize, rgb.as_raw()).unwrap()
        }
    }
}

pub fn save_gray(img: &GrayImage, path: &Path) {
    image::GrayImage::from_raw(img.width as u32, img.height as u32, img.data.clone()).unwrap().save(path).unwrap();
}

/// Two consecutive synthetic frames (grey), the ground-truth flow of the first and its class
/// mask (0 = static).
pub struct SynthPair {
    pub a: GrayImage,
    pub b: GrayImage,
    pub flow: Vec<[f32; 2]>,
    pub class: Vec<u16>,
}

pub fn synth_pair(frame: u64) -> SynthPair {
    let g = Generator::new(SynthConfig::default());
    let (fa, fb) = (g.frame(frame, true), g.frame(frame + 1, false));
    let k = &g.config().intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    SynthPair {
        a: GrayImage::from_rgb8(w, h, &fa.rgb).unwrap(),
        b: GrayImage::from_rgb8(w, h, &fb.rgb).unwrap(),
        flow: fa.flow.unwrap(),
        class: fa.class,
    }
}

/// Points to track on `img`: up to `n` FAST corners 5 px apart, 10 px from the border.
pub fn lk_points(img: &GrayImage, n: usize) -> Vec<[f32; 2]> {
    seed_corners(img, n, 20, 5.0, 10, &[])
}

/// Our ORB (in `distribution` mode) + matcher (`config`) on a pair: features of both and the
/// matched positions (previous, current).
pub fn our_matches(
    a: &GrayImage,
    b: &GrayImage,
    distribution: Distribution,
    config: &MatchConfig,
) -> (OrbFeatures, OrbFeatures, Vec<[f32; 2]>, Vec<[f32; 2]>) {
    let mut orb = OrbExtractor::new(OrbConfig { distribution, ..OrbConfig::default() });
    let (fa, fb) = (orb.extract(a, None), orb.extract(b, None));
    let angles = |f: &OrbFeatures| f.keypoints.iter().map(|k| k.angle).collect::<Vec<_>>();
    let (qa, ta) = (angles(&fb), angles(&fa));
    let m = match_brute_force(&fb.descriptors, &fa.descriptors, Some((&qa, &ta)), config);
    let prev = m.iter().map(|m| fa.keypoints[m.train as usize]).map(|k| [k.x, k.y]).collect();
    let cur = m.iter().map(|m| fb.keypoints[m.query as usize]).map(|k| [k.x, k.y]).collect();
    (fa, fb, prev, cur)
}

/// The matcher set up like `cv2.BFMatcher(NORM_HAMMING, crossCheck=True)`: mutual best
/// matches, no ratio test, no distance bound (rotation check kept).
pub fn cross_check_only() -> MatchConfig {
    MatchConfig { ratio: 1.0, max_distance: 256, ..MatchConfig::default() }
}

/// A named set of point correspondences `(name, p1, p2)`.
pub type Correspondences = (&'static str, Vec<[f64; 2]>, Vec<[f64; 2]>);

/// Tracks for the fundamental-matrix comparison: ORB matches on the real Kinect pair, LK
/// tracks on a synthetic pair with walking people (their points are outliers to F).
pub fn fundamental_cases() -> Vec<Correspondences> {
    let ch7 = ch7();
    let (a7, b7) = (load_gray(&ch7[0]), load_gray(&ch7[1]));
    let (_, _, prev, cur) = our_matches(&a7, &b7, Distribution::Harris, &cross_check_only());
    let to64 = |v: &[[f32; 2]]| v.iter().map(|p| [f64::from(p[0]), f64::from(p[1])]).collect::<Vec<_>>();
    let syn = synth_pair(60);
    let pts = lk_points(&syn.a, 800);
    let (mut pa, mut pb) = (Pyramid::default(), Pyramid::default());
    pa.build(&syn.a, 3);
    pb.build(&syn.b, 3);
    let res = LkTracker::new(LkConfig::default()).track(&pa, &pb, &pts);
    let (s1, s2): (Vec<[f32; 2]>, Vec<[f32; 2]>) =
        pts.iter().zip(&res).filter(|(_, r)| r.found).map(|(p, r)| (*p, r.point)).unzip();
    vec![("ch7_orb", to64(&prev), to64(&cur)), ("synth_lk", to64(&s1), to64(&s2))]
}

/// 3-D points of the real ch7 pair's first frame (ORB matches back-projected with its depth,
/// TUM fr2 intrinsics, depth / 5000 = metres) and their pixels in the second frame.
pub fn ch7_pnp() -> (Vec<nalgebra::Point3<f64>>, Vec<[f64; 2]>, dynaflow_vision::camera::Pinhole) {
    let cam = dynaflow_vision::camera::Pinhole { fx: 520.9, fy: 521.0, cx: 325.1, cy: 249.7 };
    let [a, b] = ch7();
    let (ga, gb) = (load_gray(&a), load_gray(&b));
    let (_, _, prev, cur) = our_matches(&ga, &gb, Distribution::Harris, &cross_check_only());
    let depth = image::open(repo().join("tests/fixtures/slambook2_rgbd_pair/depth/1.png")).unwrap().into_luma16();
    let (mut world, mut pixels) = (Vec::new(), Vec::new());
    for (p, c) in prev.iter().zip(&cur) {
        let (x, y) = (p[0].round() as u32, p[1].round() as u32);
        let d = f64::from(depth.get_pixel(x.min(depth.width() - 1), y.min(depth.height() - 1))[0]) / 5000.0;
        if d > 0.0 {
            let (u, v) = (f64::from(p[0]), f64::from(p[1]));
            world.push(nalgebra::Point3::new((u - cam.cx) / cam.fx * d, (v - cam.cy) / cam.fy * d, d));
            pixels.push([f64::from(c[0]), f64::from(c[1])]);
        }
    }
    (world, pixels, cam)
}

/// The Python of the peers venv (or `python3`) that can `import modules`, for `comparison`
/// against `peer`; `None` when that comparison is skipped ([`crate::common::peers::peer_runs`]).
pub fn python_with(peer: &str, modules: &str, comparison: &str) -> Option<PathBuf> {
    let import = format!("import {modules}");
    let mut found = None;
    let runs = crate::common::peers::peer_runs(peer, comparison, || {
        found = [crate::common::peers::venv().join("bin/python"), PathBuf::from("python3")]
            .into_iter()
            .find(|p| Command::new(p).args(["-c", &import]).output().is_ok_and(|o| o.status.success()));
        found.as_ref().map(|_| ()).ok_or_else(|| format!("no Python that can `{import}`"))
    });
    found.filter(|_| runs)
}

/// The Python with OpenCV, for `comparison`.
pub fn cv2_python(comparison: &str) -> Option<PathBuf> {
    python_with("opencv", "cv2, numpy", comparison)
}

/// Run the OpenCV side on `job` (written to `dir`).
pub fn run_cv2(python: &Path, dir: &Path, job: &serde_json::Value) -> serde_json::Value {
    let path = dir.join("job.json");
    std::fs::write(&path, job.to_string()).unwrap();
    let out = Command::new(python).arg(repo().join("tests/peers/frontend_cv2.py")).arg(&path).output().unwrap();
    assert!(out.status.success(), "cv2 peer: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}
