//! Source throughput: the synthetic scene generator (frames/s at 640×480, noise on), and TUM
//! decoding of the folder it wrote (colour + depth PNG per frame), side by side with OpenCV's
//! `cv2.imread` on the same files when a Python with OpenCV is available
//! (`DYNAFLOW_PEERS` venv, default `<target folder>/peers` as `scripts/peers.sh` makes it).
//!
//! `cargo bench --bench sources` (add `-- FRAMES`, default 120).

use std::path::Path;
use std::time::Instant;

use dynaflow_datasets::png::{load_depth, load_rgb};
use dynaflow_datasets::synth::{Generator, SynthConfig, WriteOptions, write_tum};
use dynaflow_datasets::tum::{associate, read_index};

fn main() {
    let frames: u64 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(120);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let generator = Generator::new(SynthConfig::default());
    let _ = generator.frame(0, false);
    let t = Instant::now();
    for k in 0..frames {
        std::hint::black_box(generator.frame(k, false));
    }
    let synth = t.elapsed().as_secs_f64();
    let clean =
        Generator::new(SynthConfig { depth_noise: false, image_noise: 0.0, blur: false, ..SynthConfig::default() });
    let t = Instant::now();
    for k in 0..frames {
        std::hint::black_box(clean.frame(k, false));
    }
    let render = t.elapsed().as_secs_f64();
    // The loop walks through the middle of the room: people and furniture beside and behind
    // the camera, where the culling by screen rectangles matters most.
    let round = Generator::new(SynthConfig {
        motion: dynaflow_datasets::synth::Motion::Loop,
        depth_noise: false,
        image_noise: 0.0,
        blur: false,
        ..SynthConfig::default()
    });
    let t = Instant::now();
    for k in 0..frames {
        // Spread over the whole round (900 frames).
        std::hint::black_box(round.frame(k * 900 / frames.max(1), false));
    }
    let looped = t.elapsed().as_secs_f64();
    println!("synth: {frames} frames 640x480 (2 people, xyz), {threads} threads");
    println!("  render only (clean)   : {:6.1} frames/s", frames as f64 / render);
    println!("  render only, loop     : {:6.1} frames/s (frames spread over one round)", frames as f64 / looped);
    println!("  render + sensor model : {:6.1} frames/s (Kinect noise, blur; goal >= 30)", frames as f64 / synth);

    let dir = std::env::temp_dir().join(format!("dynaflow-bench-src-{}", std::process::id()));
    let t = Instant::now();
    write_tum(&generator, &dir, &WriteOptions { frames, flow: false }).expect("write");
    println!(
        "  written as TUM folder : {:6.1} frames/s (rgb, depth, mask, instance PNGs)",
        frames as f64 / t.elapsed().as_secs_f64()
    );

    let pairs = associate(
        &read_index(&dir.join("rgb.txt")).expect("rgb.txt"),
        &read_index(&dir.join("depth.txt")).expect("depth.txt"),
        0.02,
    );
    let t = Instant::now();
    for p in &pairs {
        std::hint::black_box(load_rgb(&dir.join(&p.rgb)).expect("rgb"));
        std::hint::black_box(load_depth(&dir.join(&p.depth), 5000.0).expect("depth"));
    }
    let ours = t.elapsed().as_secs_f64();
    println!("TUM decode: {} frames (colour PNG + 16-bit depth PNG → metres)", pairs.len());
    println!("  dynaflow (image crate): {:6.1} frames/s", pairs.len() as f64 / ours);
    // The venv `scripts/peers.sh` makes: `DYNAFLOW_PEERS`, else `<target folder>/peers`.
    let venv = std::env::var("DYNAFLOW_PEERS").unwrap_or_else(|_| {
        let target =
            std::env::var("CARGO_TARGET_DIR").unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/target").into());
        format!("{target}/peers")
    });
    let python = Path::new(&venv).join("bin/python");
    let script = r##"
import sys, time, cv2, numpy as np
d = sys.argv[1]
pairs = []
rgb = [l.split() for l in open(d + "/rgb.txt") if not l.startswith("#")]
dep = [l.split() for l in open(d + "/depth.txt") if not l.startswith("#")]
t = time.perf_counter()
for (_, r), (_, z) in zip(rgb, dep):
    a = cv2.imread(d + "/" + r, cv2.IMREAD_COLOR)
    b = cv2.imread(d + "/" + z, cv2.IMREAD_UNCHANGED).astype(np.float32) / 5000.0
print(len(rgb) / (time.perf_counter() - t))
"##;
    match std::process::Command::new(&python).arg("-c").arg(script).arg(&dir).output() {
        Ok(out) if out.status.success() => {
            let fps: f64 = String::from_utf8_lossy(&out.stdout).trim().parse().unwrap_or(f64::NAN);
            println!("  OpenCV cv2.imread     : {fps:6.1} frames/s");
            println!("  ratio dynaflow / OpenCV: {:.2}x", (pairs.len() as f64 / ours) / fps);
        }
        _ => println!("  (OpenCV peer not available: install opencv-python-headless into {venv})"),
    }
    // The same on the real Kinect frames (written by TUM's libpng/zlib, not by us), repeated.
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/slambook2_rgbd_pair");
    let reps = 50;
    let t = Instant::now();
    for _ in 0..reps {
        for f in ["1.png", "2.png"] {
            std::hint::black_box(load_rgb(&real.join("rgb").join(f)).expect("rgb"));
            std::hint::black_box(load_depth(&real.join("depth").join(f), 5000.0).expect("depth"));
        }
    }
    let ours_real = (2 * reps) as f64 / t.elapsed().as_secs_f64();
    println!("TUM decode of real TUM PNGs (tests/fixtures/slambook2_rgbd_pair, {} frames)", 2 * reps);
    println!("  dynaflow (image crate): {ours_real:6.1} frames/s");
    let script_real = r##"
import sys, time, cv2, numpy as np
d, reps = sys.argv[1], int(sys.argv[2])
t = time.perf_counter()
for _ in range(reps):
    for f in ("1.png", "2.png"):
        a = cv2.imread(d + "/rgb/" + f, cv2.IMREAD_COLOR)
        b = cv2.imread(d + "/depth/" + f, cv2.IMREAD_UNCHANGED).astype(np.float32) / 5000.0
print(2 * reps / (time.perf_counter() - t))
"##;
    match std::process::Command::new(&python).arg("-c").arg(script_real).arg(&real).arg(reps.to_string()).output() {
        Ok(out) if out.status.success() => {
            let fps: f64 = String::from_utf8_lossy(&out.stdout).trim().parse().unwrap_or(f64::NAN);
            println!("  OpenCV cv2.imread     : {fps:6.1} frames/s");
            println!("  ratio dynaflow / OpenCV: {:.2}x", ours_real / fps);
        }
        _ => println!("  (OpenCV peer not available)"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}
