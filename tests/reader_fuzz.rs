//! Issue 29, done-when 2: the readers (TUM RGB-D, KITTI odometry, image folder, MCAP replay)
//! against random corruptions of small valid folders and recordings: numeric fields made
//! NaN, infinite, zero, negative or text, lines deleted, swapped or emptied, files deleted,
//! truncated, overwritten or resized. Every case ends one of two ways: the run refuses
//! (before it starts, the CLI's exit 2, or when it meets the frame, exit 1) with the broken
//! file named; or it completes, then every number it put out is finite and, where the
//! corruption takes frames away (a deleted index line), the frame count is the one left. A
//! corruption a reader must refuse that completes, or any run that puts out a NaN, fails
//! the test with the case's number and what was done.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};

use dynaflow_engine::msg::Body;
use dynaflow_engine::runtime::{self, RunOptions, RunStatus};
use dynaflow_engine::sink::{MemorySink, Sink};

/// What a case must end in.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Expect {
    /// Refused, naming the file.
    Refused,
    /// Completed with this many frames from the reader (`None`: any), or refused naming the
    /// file: both are right for this corruption (a flipped byte in a compressed image).
    Either(Option<usize>),
    /// Completed with this many frames.
    Frames(usize),
}

struct Case {
    what: String,
    expect: Expect,
    /// File names any of which the refusal must name.
    names: Vec<String>,
}

enum Ended {
    Refused(String),
    Completed(MemorySink, usize),
}

fn run(yaml: &str, node: &str, frame_port: &str) -> Ended {
    let loaded = dynaflow_engine::load_str("fuzz.yaml", yaml, None, &dynaflow::registry(), &Default::default());
    let Some(graph) = loaded.graph else {
        return Ended::Refused(
            loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect::<Vec<_>>().join("\n"),
        );
    };
    let sink = MemorySink::default();
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let sinks: Vec<Box<dyn Sink>> = vec![Box::new(sink.clone())];
    match rt.block_on(runtime::run(&graph, RunOptions::default(), sinks)) {
        Err(e) => Ended::Refused(e.to_string()),
        Ok(r) if r.status == RunStatus::Failed => {
            Ended::Refused(r.failures.iter().map(|f| f.error.clone()).collect::<Vec<_>>().join("\n"))
        }
        Ok(r) => {
            assert_eq!(r.status, RunStatus::Completed, "{:?}", r.failures);
            let n = sink.port(node, frame_port).len();
            Ended::Completed(sink, n)
        }
    }
}

/// The first number a message carries that is not finite (or a focal length that is not
/// positive), if any.
fn not_finite(body: &Body) -> Option<String> {
    let bad = |v: f64| !v.is_finite();
    match body {
        Body::Depth(d) => d.data.iter().find(|v| !v.is_finite()).map(|v| format!("depth {v}")),
        Body::CameraInfo(k) => {
            let all = [k.fx, k.fy, k.cx, k.cy].into_iter().chain(k.distortion);
            (all.clone().any(bad) || k.fx <= 0.0 || k.fy <= 0.0).then(|| format!("camera info {k:?}"))
        }
        Body::Pose(p) => {
            let m = p.world_from_cam.to_homogeneous();
            m.iter().any(|v| bad(*v)).then(|| format!("pose {m}"))
        }
        Body::Scalars(s) => s.values.iter().find(|(_, v)| bad(*v)).map(|(k, v)| format!("scalar {k} = {v}")),
        _ => None,
    }
}

/// Judge one case; `Err` says what was wrong.
fn judge(case: &Case, ended: Ended) -> Result<(), String> {
    match ended {
        Ended::Refused(msg) => {
            if matches!(case.expect, Expect::Frames(_)) {
                return Err(format!("refused where it should run: {msg}"));
            }
            if !case.names.iter().any(|n| msg.contains(n.as_str())) {
                return Err(format!("refused without naming {:?}: {msg}", case.names));
            }
            Ok(())
        }
        Ended::Completed(sink, frames) => {
            if case.expect == Expect::Refused {
                return Err(format!("completed with {frames} frames where it must refuse"));
            }
            if let Expect::Frames(n) | Expect::Either(Some(n)) = case.expect
                && frames != n
            {
                return Err(format!("completed with {frames} frames, {n} expected"));
            }
            let all: Vec<_> = sink.messages.lock().unwrap().iter().map(|(_, _, m)| m.clone()).collect();
            for m in all {
                if !m.header.stamp.is_finite() {
                    return Err(format!("a message stamped {}", m.header.stamp));
                }
                if let Some(why) = not_finite(&m.body) {
                    return Err(format!("put out {why}"));
                }
            }
            Ok(())
        }
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let t = to.join(p.file_name().unwrap());
        if p.is_dir() { copy_dir(&p, &t) } else { std::fs::copy(&p, &t).map(|_| ()).unwrap() }
    }
}

/// The data lines of a text file (not comments), as line indices.
fn data_lines(text: &str) -> Vec<usize> {
    text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#')).map(|(i, _)| i).collect()
}

fn edit_lines(path: &Path, f: impl FnOnce(&mut Vec<String>)) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    f(&mut lines);
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

/// Replace field `field` (whitespace-separated) of data line `nth` of `path` with `value`.
fn set_field(path: &Path, nth: usize, field: usize, value: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    let line = data_lines(&text)[nth];
    edit_lines(path, |lines| {
        let mut f: Vec<String> = lines[line].split_whitespace().map(str::to_owned).collect();
        if field < f.len() {
            f[field] = value.to_owned();
        }
        lines[line] = f.join(" ");
    });
}

/// A corruption of one image file: deleted, truncated, bytes overwritten, or another size.
fn break_image(rng: &mut common::Rng, path: &Path, resizable: bool) -> (String, Expect) {
    let name = path.file_name().unwrap().to_string_lossy().into_owned();
    let len = std::fs::metadata(path).unwrap().len();
    match rng.below(if resizable { 4 } else { 3 }) {
        0 => {
            std::fs::remove_file(path).unwrap();
            (format!("deleted {name}"), Expect::Refused)
        }
        1 => {
            let keep = rng.below(len) as usize;
            let bytes = std::fs::read(path).unwrap();
            std::fs::write(path, &bytes[..keep]).unwrap();
            (format!("truncated {name} to {keep} of {len} bytes"), Expect::Refused)
        }
        2 => {
            // Overwrite 8 bytes past the signature: PNG's chunk CRCs catch it, or the pixels
            // change (both are right; what comes out must still be finite).
            let mut bytes = std::fs::read(path).unwrap();
            let at = rng.range(8, len - 8) as usize;
            for b in &mut bytes[at..at + 8] {
                *b ^= 0x5a;
            }
            std::fs::write(path, &bytes).unwrap();
            (format!("overwrote 8 bytes of {name} at {at}"), Expect::Either(None))
        }
        _ => {
            let img = image::open(path).unwrap();
            img.resize_exact(img.width() / 2, img.height() / 2, image::imageops::FilterType::Nearest)
                .save(path)
                .unwrap();
            (format!("halved the size of {name}"), Expect::Refused)
        }
    }
}

const BAD_NUMBERS: [&str; 6] = ["nan", "NaN", "inf", "-inf", "abc", "1e999"];

/// A 4-frame 64x48 synthetic sequence (`dynaflow synth`) written once per test.
fn synth_folder(dir: &Path) -> PathBuf {
    let seq = dir.join("synth");
    let out = common::bin()
        .args(["synth", "--frames", "4", "--width", "64", "--height", "48", "--seed", "11", "--out"])
        .arg(&seq)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    seq
}

/// One reader's cases: each run and judged, the wrong ones kept, and a tally printed.
struct Fuzz {
    reader: &'static str,
    cases: usize,
    refused: usize,
    failures: Vec<String>,
}

impl Fuzz {
    fn new(reader: &'static str) -> Self {
        Self { reader, cases: 0, refused: 0, failures: Vec::new() }
    }

    /// Run `yaml` and judge case `i` on what `node.port` put out.
    fn check(&mut self, i: usize, case: &Case, yaml: &str, node: &str, port: &str) {
        let ended = run(yaml, node, port);
        self.cases += 1;
        self.refused += usize::from(matches!(ended, Ended::Refused(_)));
        if let Err(e) = judge(case, ended) {
            self.failures.push(format!("case {i} ({}): {e}", case.what));
        }
    }

    fn report(&self) {
        let (reader, cases) = (self.reader, self.cases);
        eprintln!(
            "{reader}: {cases} cases, {} refused naming the file, {} completed",
            self.refused,
            cases - self.refused
        );
        assert!(
            self.failures.is_empty(),
            "{reader}: {} of {cases} cases wrong:\n{}",
            self.failures.len(),
            self.failures.join("\n")
        );
    }
}

#[test]
fn tum_reader_refuses_or_reads_correctly_every_corruption() {
    let dir = common::TempDir::new("fuzz-tum");
    let valid = synth_folder(dir.path());
    let mut rng = common::Rng::new(29);
    let (mut fuzz, cases) = (Fuzz::new("tum_rgbd"), 60);
    for i in 0..cases {
        let seq = dir.path().join(format!("case{i}"));
        copy_dir(&valid, &seq);
        let index = ["rgb.txt", "depth.txt", "groundtruth.txt"];
        let case = match rng.below(7) {
            // A numeric field of an index, the ground truth or the calibration.
            0 | 1 => {
                let file = *rng.pick(&["rgb.txt", "depth.txt", "groundtruth.txt", "calibration.txt"]);
                let path = seq.join(file);
                let n = data_lines(&std::fs::read_to_string(&path).unwrap()).len();
                let line = rng.below(n as u64) as usize;
                let field = match file {
                    "groundtruth.txt" => rng.below(8) as usize,
                    "calibration.txt" => rng.below(4) as usize,
                    _ => 0,
                };
                let value = *rng.pick(&BAD_NUMBERS);
                set_field(&path, line, field, value);
                Case {
                    what: format!("{file} line {line} field {field} = {value}"),
                    expect: Expect::Refused,
                    names: vec![file.into()],
                }
            }
            // An index line deleted: one frame fewer (its colour or depth has no partner).
            2 => {
                let file = *rng.pick(&["rgb.txt", "depth.txt"]);
                let path = seq.join(file);
                let lines = data_lines(&std::fs::read_to_string(&path).unwrap());
                let line = *rng.pick(&lines);
                edit_lines(&path, |l| {
                    l.remove(line);
                });
                Case { what: format!("deleted {file} line {line}"), expect: Expect::Frames(3), names: vec![] }
            }
            // Two index lines swapped: time goes back.
            3 => {
                let file = *rng.pick(&index);
                let path = seq.join(file);
                let lines = data_lines(&std::fs::read_to_string(&path).unwrap());
                let a = rng.below(lines.len() as u64 - 1) as usize;
                edit_lines(&path, |l| l.swap(lines[a], lines[a + 1]));
                Case {
                    what: format!("swapped {file} lines {a}, {}", a + 1),
                    expect: Expect::Refused,
                    names: vec![file.into()],
                }
            }
            // An index emptied (comments kept).
            4 => {
                let file = *rng.pick(&["rgb.txt", "depth.txt"]);
                edit_lines(&seq.join(file), |l| l.retain(|x| x.starts_with('#')));
                Case { what: format!("emptied {file}"), expect: Expect::Refused, names: vec![file.into()] }
            }
            // A frame file broken.
            _ => {
                let sub = *rng.pick(&["rgb", "depth", "mask"]);
                let mut files: Vec<PathBuf> =
                    std::fs::read_dir(seq.join(sub)).unwrap().map(|e| e.unwrap().path()).collect();
                files.sort();
                let path = rng.pick(&files).clone();
                let (what, expect) = break_image(&mut rng, &path, true);
                let name = path.file_name().unwrap().to_string_lossy().into_owned();
                Case { what: format!("{sub}/: {what}"), expect, names: vec![name] }
            }
        };
        let yaml = format!("name: fuzz\nnodes:\n  cam: {{ op: tum_rgbd, params: {{ path: '{}' }} }}\n", seq.display());
        fuzz.check(i, &case, &yaml, "cam", "rgb");
    }
    fuzz.report();
}

/// A KITTI odometry sequence (`dataset/sequences/07` and `dataset/poses/07.txt`) from the
/// synthetic frames, both cameras the same images.
fn kitti_folder(dir: &Path, synth: &Path) -> PathBuf {
    let root = dir.join("kitti");
    let seq = root.join("dataset/sequences/07");
    let mut rgb: Vec<PathBuf> = std::fs::read_dir(synth.join("rgb")).unwrap().map(|e| e.unwrap().path()).collect();
    rgb.sort();
    for cam in ["image_0", "image_1"] {
        std::fs::create_dir_all(seq.join(cam)).unwrap();
        for (i, f) in rgb.iter().enumerate() {
            std::fs::copy(f, seq.join(cam).join(format!("{i:06}.png"))).unwrap();
        }
    }
    let p = |tx: f64| format!("53.54 0 31.56 {tx} 0 53.92 24.31 0 0 0 1 0");
    std::fs::write(
        seq.join("calib.txt"),
        format!("P0: {}\nP1: {}\nP2: {}\nP3: {}\nTr: 1 0 0 0 0 1 0 0 0 0 1 0\n", p(0.0), p(-28.5), p(0.0), p(0.0)),
    )
    .unwrap();
    std::fs::write(seq.join("times.txt"), "0.000000e+00\n1.036300e-01\n2.072600e-01\n3.108900e-01\n").unwrap();
    std::fs::create_dir_all(root.join("dataset/poses")).unwrap();
    std::fs::write(
        root.join("dataset/poses/07.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0.1 0 1 0 0 0 0 1 0.5\n0 0 1 0.2 0 1 0 0 -1 0 0 1.0\n1 0 0 0.3 0 1 0 0 0 0 1 1.5\n",
    )
    .unwrap();
    root
}

#[test]
fn kitti_reader_refuses_or_reads_correctly_every_corruption() {
    let dir = common::TempDir::new("fuzz-kitti");
    let synth = synth_folder(dir.path());
    let valid = kitti_folder(dir.path(), &synth);
    let mut rng = common::Rng::new(2929);
    let (mut fuzz, cases) = (Fuzz::new("kitti_odometry"), 50);
    for i in 0..cases {
        let root = dir.path().join(format!("case{i}"));
        copy_dir(&valid, &root);
        let seq = root.join("dataset/sequences/07");
        let case = match rng.below(6) {
            // The left camera's fx, cx, fy or cy: not a number, or not positive.
            0 => {
                let field = *rng.pick(&[1usize, 3, 6, 7]);
                let value = *rng.pick(&["nan", "inf", "0", "-53.5", "abc"]);
                set_field(&seq.join("calib.txt"), 0, field, value);
                Case {
                    what: format!("calib.txt P0 entry {field} = {value}"),
                    expect: Expect::Refused,
                    names: vec!["calib.txt".into()],
                }
            }
            // A time stamp.
            1 => {
                let line = rng.below(4) as usize;
                let value = *rng.pick(&BAD_NUMBERS);
                set_field(&seq.join("times.txt"), line, 0, value);
                Case {
                    what: format!("times.txt line {line} = {value}"),
                    expect: Expect::Refused,
                    names: vec!["times.txt".into()],
                }
            }
            // Time going back, or no times at all.
            2 => {
                if rng.chance(0.5) {
                    let a = rng.below(3) as usize;
                    edit_lines(&seq.join("times.txt"), |l| l.swap(a, a + 1));
                    Case {
                        what: format!("times.txt lines {a}, {} swapped", a + 1),
                        expect: Expect::Refused,
                        names: vec!["times.txt".into()],
                    }
                } else {
                    std::fs::write(seq.join("times.txt"), "").unwrap();
                    Case { what: "times.txt emptied".into(), expect: Expect::Refused, names: vec!["times.txt".into()] }
                }
            }
            // A pose entry: not a number, or a matrix that is no rotation.
            3 => {
                let line = rng.below(4) as usize;
                let field = rng.below(12) as usize;
                let value = if [3, 7, 11].contains(&field) {
                    *rng.pick(&BAD_NUMBERS)
                } else {
                    *rng.pick(&["nan", "inf", "5", "abc"])
                };
                set_field(&root.join("dataset/poses/07.txt"), line, field, value);
                Case {
                    what: format!("07.txt line {line} entry {field} = {value}"),
                    expect: Expect::Refused,
                    names: vec!["07.txt".into()],
                }
            }
            // A camera image broken.
            _ => {
                let cam = *rng.pick(&["image_0", "image_1"]);
                let name = format!("{:06}.png", rng.below(4));
                let (what, expect) = break_image(&mut rng, &seq.join(cam).join(&name), true);
                Case { what: format!("{cam}/: {what}"), expect, names: vec![name] }
            }
        };
        let yaml =
            format!("name: fuzz\nnodes:\n  cam: {{ op: kitti_odometry, params: {{ path: '{}' }} }}\n", seq.display());
        fuzz.check(i, &case, &yaml, "cam", "rgb");
    }
    fuzz.report();
}

#[test]
fn image_folder_reader_refuses_or_reads_correctly_every_corruption() {
    let dir = common::TempDir::new("fuzz-folder");
    let synth = synth_folder(dir.path());
    let mut rng = common::Rng::new(292929);
    let (mut fuzz, cases) = (Fuzz::new("image_folder"), 30);
    for i in 0..cases {
        let folder = dir.path().join(format!("case{i}"));
        copy_dir(&synth.join("rgb"), &folder);
        let mut files: Vec<PathBuf> = std::fs::read_dir(&folder).unwrap().map(|e| e.unwrap().path()).collect();
        files.sort();
        let case = match rng.below(5) {
            // A file that is no image, under the pattern or not.
            0 => {
                if rng.chance(0.5) {
                    std::fs::write(folder.join("notes.txt"), "not an image").unwrap();
                    Case { what: "added notes.txt".into(), expect: Expect::Frames(4), names: vec![] }
                } else {
                    std::fs::write(folder.join("zz_empty.png"), b"").unwrap();
                    Case {
                        what: "added an empty zz_empty.png".into(),
                        expect: Expect::Refused,
                        names: vec!["zz_empty.png".into()],
                    }
                }
            }
            _ => {
                let path = rng.pick(&files).clone();
                let name = path.file_name().unwrap().to_string_lossy().into_owned();
                let (what, expect) = break_image(&mut rng, &path, true);
                // A deleted image is simply not in the folder: one frame fewer.
                let expect = if what.starts_with("deleted") { Expect::Frames(3) } else { expect };
                Case { what, expect, names: vec![name] }
            }
        };
        let yaml = format!(
            "name: fuzz\nnodes:\n  cam: {{ op: image_folder, params: {{ path: '{}', intrinsics: fr3 }} }}\n",
            folder.display()
        );
        fuzz.check(i, &case, &yaml, "cam", "rgb");
    }
    fuzz.report();
}

#[test]
fn mcap_replay_refuses_or_reads_correctly_every_corruption() {
    let dir = common::TempDir::new("fuzz-mcap");
    let out = common::bin()
        .args([
            "run",
            "--no-progress",
            "--frames",
            "4",
            "--record",
            "mcap",
            "--image-format",
            "raw",
            "--set",
            "camera.width=64",
            "--set",
            "camera.height=48",
            "--out",
        ])
        .arg(dir.path())
        .arg(common::repo().join("graphs/default.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let valid = std::fs::read(dir.path().join("default.mcap")).unwrap();
    let mut rng = common::Rng::new(29_292_929);
    let (mut fuzz, cases) = (Fuzz::new("mcap_replay"), 40);
    for i in 0..cases {
        let path = dir.path().join(format!("case{i}.mcap"));
        let mut bytes = valid.clone();
        let what = if rng.chance(0.4) {
            let keep = rng.below(bytes.len() as u64) as usize;
            bytes.truncate(keep);
            format!("truncated to {keep} of {} bytes", valid.len())
        } else {
            let at = rng.below(bytes.len() as u64 - 4) as usize;
            let flip = rng.range(1, 255) as u8;
            for b in &mut bytes[at..at + 4] {
                *b ^= flip;
            }
            format!("4 bytes at {at} xor {flip:#04x}")
        };
        std::fs::write(&path, &bytes).unwrap();
        let case = Case { what, expect: Expect::Either(None), names: vec![format!("case{i}.mcap")] };
        let yaml = format!(
            "name: fuzz\nnodes:\n  src: {{ op: mcap_replay, params: {{ path: '{}', topics: 'rgb=/camera/rgb,depth=/camera/depth,pose=/camera/gt_pose,camera_info=/camera/camera_info' }} }}\n",
            path.display()
        );
        fuzz.check(i, &case, &yaml, "src", "rgb");
    }
    fuzz.report();
}
