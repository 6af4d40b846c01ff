//! The default graph's recording as a user sees it: served by the rerun web viewer
//! of the pinned `rerun-sdk` (`rerun --serve-web`, nothing downloaded), opened in headless
//! Chromium with software rendering (`tests/peers/screenshot.py`), and the screenshot checked:
//! the viewer loaded (not its loading screen, not a blank frame), the camera image is not
//! tinted by the mask's background class (the defect: every image view red edge to edge), and
//! the tracker's decisions are drawn on it in the recorder's two colours, the static points
//! outnumbering the dynamic ones (the defect: every point set of the frame on every image, and
//! the red tint drowning the green).
//!
//! `DYNAFLOW_SCREENSHOTS=docs/img cargo test --release --test viewer` also writes the
//! screenshot there (docs/img/default-view.png).
#![allow(clippy::unwrap_used, clippy::panic)]

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;

/// What the rrd recorder draws a point label with (recordings/src/rrd/mod.rs).
const DYNAMIC: [i32; 3] = [230, 40, 40];
const STATIC: [i32; 3] = [40, 200, 60];

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// The viewer and the browser, when installed (`scripts/peers.sh`).
fn tools() -> Option<(std::path::PathBuf, std::path::PathBuf)> {
    let venv = common::peers::venv();
    let (rerun, python) = (venv.join("bin/rerun"), venv.join("bin/python"));
    let runs = |c: &mut Command| c.stdin(Stdio::null()).output().is_ok_and(|o| o.status.success());
    let rerun_ok = common::peers::peer_runs("rerun", "viewer: the rerun web viewer", || {
        if runs(Command::new(&rerun).arg("--version")) { Ok(()) } else { Err(format!("no {}", rerun.display())) }
    });
    let chromium_ok = common::peers::peer_runs("chromium", "viewer: headless Chromium screenshot", || {
        if !runs(Command::new("chromium").arg("--version")) {
            return Err("no `chromium` on PATH".into());
        }
        if !runs(Command::new(&python).args(["-c", "import websocket"])) {
            return Err("no websocket-client in the peers' Python".into());
        }
        Ok(())
    });
    (rerun_ok && chromium_ok).then_some((rerun, python))
}

/// Serve `rrd` with the web viewer and take the browser's screenshot into `png`.
fn screenshot(rerun: &Path, python: &Path, rrd: &Path, png: &Path) {
    let (web, grpc) = (free_port(), free_port());
    // The `rerun` script starts the viewer binary: both are ended with the test's group.
    let _server = common::process::Reaped::spawn(
        Command::new(rerun)
            .args(["--serve-web", "--web-viewer-port", &web.to_string(), "--port", &grpc.to_string()])
            .arg(rrd)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null()),
    )
    .unwrap();
    let t0 = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", web)).is_err() {
        assert!(t0.elapsed() < Duration::from_secs(60), "the web viewer did not start");
        std::thread::sleep(Duration::from_millis(200));
    }
    let url = format!("http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy");
    let out = Command::new(python)
        .arg(common::repo().join("tests/peers/screenshot.py"))
        .arg(&url)
        .arg(png)
        .arg("150")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "screenshot: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn near(p: &image::Rgb<u8>, c: [i32; 3]) -> bool {
    p.0.iter().zip(c).all(|(&v, w)| (i32::from(v) - w).abs() < 40)
}

#[test]
fn the_default_graph_opens_on_the_camera_with_its_decisions_in_a_real_browser() {
    let Some((rerun, python)) = tools() else { return };
    let dir = common::TempDir::new("viewer");
    let out = common::bin()
        .arg("run")
        .arg(common::repo().join("graphs/default.yaml"))
        .args(["--frames", "30", "--no-progress", "--record", "rrd", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let png = dir.path().join("default-view.png");
    screenshot(&rerun, &python, &dir.path().join("default.rrd"), &png);
    if let Some(to) = std::env::var_os("DYNAFLOW_SCREENSHOTS") {
        std::fs::copy(&png, Path::new(&to).join("default-view.png")).unwrap();
    }
    let img = image::open(&png).unwrap().to_rgb8();
    let n = f64::from(img.width() * img.height());
    // Loaded: the viewer's loading screen and a blank page have a few hundred colours; the
    // views (images, depth colour map, 3-D points, plots) tens of thousands.
    let colours: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(colours.len() > 5_000, "{} colours: the viewer did not show the recording", colours.len());
    // The mask's background class is transparent: with it opaque, the image views were red
    // edge to edge (4.8 % of the screenshot strongly red, 1.0 % without).
    let reddish = img
        .pixels()
        .filter(|p| {
            let [r, g, b] = p.0.map(f32::from);
            r > 120.0 && r > 1.6 * g && r > 1.6 * b
        })
        .count() as f64
        / n;
    assert!(reddish < 0.025, "{:.1} % of the screenshot is red: the mask tints the image", 100.0 * reddish);
    // The decisions, each in its colour; most points are static.
    let dynamic = img.pixels().filter(|p| near(p, DYNAMIC)).count();
    let stat = img.pixels().filter(|p| near(p, STATIC)).count();
    assert!(stat >= 1_000 && dynamic >= 100, "static {stat} px, dynamic {dynamic} px: the labels are not drawn");
    assert!(dynamic < stat, "dynamic {dynamic} px outnumber static {stat} px: a red tint or the wrong points");
}

/// The pixels near each label colour in `png`, and its distinct colours.
fn label_pixels(png: &Path) -> (usize, usize, usize) {
    let img = image::open(png).unwrap().to_rgb8();
    let colours: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    let dynamic = img.pixels().filter(|p| near(p, DYNAMIC)).count();
    let stat = img.pixels().filter(|p| near(p, STATIC)).count();
    (colours.len(), dynamic, stat)
}

#[test]
fn a_comparison_of_three_variants_shows_each_run_with_its_labels_in_a_real_browser() {
    let Some((rerun, python)) = tools() else { return };
    let dir = common::TempDir::new("viewer-compare");
    let mut files = Vec::new();
    for v in ["S", "G", "base"] {
        let mut c = common::bin();
        c.arg("run").arg(common::repo().join("graphs/mg_slam.yaml"));
        if v != "base" {
            c.args(["--variant", v]);
        }
        let out = c
            .args(["--frames", "30", "--record", "mcap", "--no-progress", "--out"])
            .arg(dir.path().join(v))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
        let stem = if v == "base" { "mg_slam".to_owned() } else { format!("mg_slam-{v}") };
        files.push(dir.path().join(v).join(format!("{stem}.mcap")));
    }
    let rrd = dir.path().join("compare.rrd");
    let out =
        common::bin().arg("compare").args(&files).args(["--names", "S,G,S+G", "--out"]).arg(&rrd).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let png = dir.path().join("compare-view.png");
    screenshot(&rerun, &python, &rrd, &png);
    if let Some(to) = std::env::var_os("DYNAFLOW_SCREENSHOTS") {
        std::fs::copy(&png, Path::new(&to).join("compare-view.png")).unwrap();
    }
    let (colours, dynamic, stat) = label_pixels(&png);
    assert!(colours > 5_000, "{colours} colours: the viewer did not show the comparison");
    // Three runs' images with their labels: at least the single view's share of each colour.
    assert!(stat >= 3_000 && dynamic >= 300, "static {stat} px, dynamic {dynamic} px: the runs' labels are not drawn");
    assert!(dynamic < stat, "dynamic {dynamic} px outnumber static {stat} px");
}
