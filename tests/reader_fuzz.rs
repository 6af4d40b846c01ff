//! The readers (TUM RGB-D, KITTI odometry, image folder, MCAP replay)
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

/// The fields of a map file (`dynaflow_slam::map_file`'s layout) at their byte offsets, found
/// by walking it as the reader does: what a structure-aware mutation changes.
#[derive(Default)]
struct MapFields {
    counts: Vec<usize>,
    point_ids: Vec<usize>,
    point_positions: Vec<usize>,
    kf_ids: Vec<usize>,
    kf_stamps: Vec<usize>,
    kf_translations: Vec<usize>,
    kf_parents: Vec<usize>,
    kp_uv: Vec<usize>,
    kp_octaves: Vec<usize>,
    kp_depths: Vec<usize>,
    kp_points: Vec<usize>,
}

fn map_fields(b: &[u8]) -> MapFields {
    let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap()) as usize;
    let mut f = MapFields { counts: vec![32, 36], ..MapFields::default() };
    let (nk, np) = (u32_at(32), u32_at(36));
    let mut at = 40;
    for _ in 0..np {
        f.point_ids.push(at);
        f.point_positions.push(at + 8);
        at += 72;
    }
    for _ in 0..nk {
        f.kf_ids.push(at);
        f.kf_stamps.push(at + 8);
        f.kf_translations.push(at + 16);
        f.kf_parents.push(at + 72);
        let loops = u32_at(at + 80);
        at += 84 + 8 * loops;
        let kps = u32_at(at);
        at += 4;
        for _ in 0..kps {
            f.kp_uv.push(at);
            f.kp_octaves.push(at + 16);
            f.kp_depths.push(at + 17);
            f.kp_points.push(at + 57);
            at += 65;
        }
    }
    assert_eq!(at + 8, b.len(), "the test's walk of the map layout is out of date");
    f
}

/// Done-when 2 of the trust pass: saved maps and vocabularies with valid checksums but
/// impossible contents (duplicate or dangling ids, cyclic parents, pyramid level 255,
/// coordinates of 1e300, counts that disagree with the bytes) are refused naming the file, or
/// load and run with finite outputs; never a panic.
#[test]
fn map_and_vocabulary_files_with_impossible_contents_are_refused_or_run_finite() {
    let dir = common::TempDir::new("fuzz-map");
    let graph = common::repo().join("graphs/orb_baseline.yaml");
    let valid = dir.path().join("valid.dfmap");
    let o = common::bin()
        .args(["run", "--no-progress", "--record", "none", "--frames", "40", "--out"])
        .arg(dir.path().join("save"))
        .arg(&graph)
        .arg("--save-map")
        .arg(&valid)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(&valid).unwrap();
    let fields = map_fields(&bytes);
    let voc = std::sync::Arc::new(
        dynaflow_slam::bow::Vocabulary::from_bytes(dynaflow_operators::tracking::DEFAULT_VOCABULARY, "default")
            .unwrap(),
    );
    let cam = dynaflow_vision::camera::Pinhole { fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 };
    let reseal = |b: &mut Vec<u8>| {
        let n = b.len() - 8;
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for x in &b[..n] {
            h ^= u64::from(*x);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
        b[n..].copy_from_slice(&h.to_le_bytes());
    };
    let put = |b: &mut Vec<u8>, at: usize, v: &[u8]| b[at..at + v.len()].copy_from_slice(v);
    let mut rng = common::Rng::new(49);
    let (mut refused, mut loaded, mut ran, mut failures) = (0, 0, 0, Vec::new());
    for case in 0..60 {
        let mut b = bytes.clone();
        let pick = |rng: &mut common::Rng, v: &[usize]| *rng.pick(v);
        let what = match rng.below(10) {
            0 => {
                let (x, y) = (pick(&mut rng, &fields.point_ids), pick(&mut rng, &fields.point_ids));
                let id = b[y..y + 8].to_vec();
                put(&mut b, x, &id);
                "a point id made another's".to_owned()
            }
            1 => {
                let v = *rng.pick(&[1e300, -1e300, 1e7, f64::MIN_POSITIVE]);
                put(&mut b, pick(&mut rng, &fields.point_positions) + 8 * rng.below(3) as usize, &v.to_le_bytes());
                format!("a point coordinate {v:e}")
            }
            2 => {
                let (x, y) = (pick(&mut rng, &fields.kf_ids), pick(&mut rng, &fields.kf_ids));
                let id = b[y..y + 8].to_vec();
                put(&mut b, x, &id);
                "a key-frame id made another's".to_owned()
            }
            3 => {
                // A parent made the key frame itself, another key frame, or a stranger.
                let at = pick(&mut rng, &fields.kf_parents);
                let idx = fields.kf_parents.iter().position(|&p| p == at).unwrap();
                let own = b[fields.kf_ids[idx]..fields.kf_ids[idx] + 8].to_vec();
                let other = pick(&mut rng, &fields.kf_ids);
                let other = b[other..other + 8].to_vec();
                let v = match rng.below(3) {
                    0 => own,
                    1 => other,
                    _ => 987_654_321u64.to_le_bytes().to_vec(),
                };
                put(&mut b, at, &v);
                "a parent changed".to_owned()
            }
            4 => {
                let v = *rng.pick(&[255u8, 31, 32, 7]);
                put(&mut b, pick(&mut rng, &fields.kp_octaves), &[v]);
                format!("a keypoint on level {v}")
            }
            5 => {
                let v: f64 = *rng.pick(&[1e300, -5.0, 70_000.0, 1e-300]);
                put(&mut b, pick(&mut rng, &fields.kp_uv) + 8 * rng.below(2) as usize, &v.to_le_bytes());
                format!("a keypoint coordinate {v:e}")
            }
            6 => {
                let v: f64 = *rng.pick(&[-1.0, 1e300, 1e-300]);
                put(&mut b, pick(&mut rng, &fields.kp_depths), &f64::to_le_bytes(v));
                format!("a keypoint depth {v:e}")
            }
            7 => {
                let v = *rng.pick(&[123_456_789u64, u64::MAX - 1]);
                put(&mut b, pick(&mut rng, &fields.kp_points), &v.to_le_bytes());
                format!("a keypoint of point {v}")
            }
            8 => {
                let at = pick(&mut rng, &fields.counts);
                let n = u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
                let v = *rng.pick(&[n + 1, n.saturating_sub(1), u32::MAX]);
                put(&mut b, at, &v.to_le_bytes());
                format!("count at byte {at} {n} -> {v}")
            }
            _ => {
                let v: f64 = *rng.pick(&[1e300, -1e12, 1e5]);
                put(&mut b, pick(&mut rng, &fields.kf_translations), &v.to_le_bytes());
                format!("a key-frame position {v:e}")
            }
        };
        reseal(&mut b);
        let file = dir.path().join(format!("case{case}.dfmap"));
        std::fs::write(&file, &b).unwrap();
        let result = std::panic::catch_unwind(|| {
            dynaflow_slam::map_file::load(&file, cam, 640.0, 480.0, 1.2, voc.clone())
                .map(|_| ())
                .map_err(|e| e.to_string())
        });
        match result {
            Err(_) => failures.push(format!("case {case} ({what}): the reader panicked")),
            Ok(Err(e)) if e.contains(&format!("case{case}.dfmap")) => refused += 1,
            Ok(Err(e)) => failures.push(format!("case {case} ({what}): refused without naming the file: {e}")),
            Ok(Ok(())) => {
                loaded += 1;
                // Loaded: it must run, with finite outputs (a few such cases: each is a run).
                if ran >= 4 {
                    continue;
                }
                ran += 1;
                let out = dir.path().join(format!("run{case}"));
                let o = common::bin()
                    .args(["run", "--no-progress", "--record", "none", "--frames", "15", "--out"])
                    .arg(&out)
                    .arg(&graph)
                    .arg("--load-map")
                    .arg(&file)
                    .output()
                    .unwrap();
                let err = String::from_utf8_lossy(&o.stderr);
                if !matches!(o.status.code(), Some(0..=2)) || err.contains("panicked") {
                    failures.push(format!("case {case} ({what}): loaded, then the run ended {:?}: {err}", o.status));
                } else if o.status.code() == Some(0) {
                    let s = common::summary(&out.join("orb_baseline.summary.json"));
                    if s.ate.as_ref().is_some_and(|a| !a.rmse.is_finite()) {
                        failures.push(format!("case {case} ({what}): a non-finite ATE"));
                    }
                }
            }
        }
    }
    eprintln!("maps: 60 cases, {refused} refused naming the file, {loaded} loaded ({ran} of them run)");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(refused >= 30, "only {refused} of 60 impossible maps were refused");

    // Vocabularies: node fields and the header changed, the checksum made valid.
    let base = dynaflow_operators::tracking::DEFAULT_VOCABULARY.to_vec();
    let nodes = (base.len() - 24 - 8) / 48;
    let descriptors: Vec<[u8; 32]> = (0..64u8).map(|i| [i.wrapping_mul(37); 32]).collect();
    let mut vfail = Vec::new();
    let mut vrefused = 0;
    for case in 0..200 {
        let mut b = base.clone();
        let node = 24 + 48 * rng.below(nodes as u64) as usize;
        let what = match rng.below(6) {
            0 => {
                put(&mut b, node, &(rng.below(nodes as u64 * 2) as u32).to_le_bytes());
                "a parent"
            }
            1 => {
                put(&mut b, node + 4, &(rng.below(nodes as u64 + 2) as u32).to_le_bytes());
                "a word"
            }
            2 => {
                put(&mut b, node + 8, &rng.pick(&[f64::NAN, -1.0, 1e308, 0.0]).to_le_bytes());
                "a weight"
            }
            3 => {
                put(&mut b, 12 + 4 * rng.below(2) as usize, &(rng.below(100) as u32).to_le_bytes());
                "k or levels"
            }
            4 => {
                // Only the root left: a well-formed vocabulary with no word.
                b.truncate(24 + 48 + 8);
                put(&mut b, 20, &1u32.to_le_bytes());
                put(&mut b, 24 + 4, &0u32.to_le_bytes());
                "no word"
            }
            _ => {
                let v = rng.below(256) as u8;
                b[node + 16 + rng.below(32) as usize] = v;
                "a descriptor byte"
            }
        };
        reseal(&mut b);
        let name = format!("case{case}.voc");
        let result = std::panic::catch_unwind(|| {
            let v = dynaflow_slam::bow::Vocabulary::from_bytes(&b, &name).map_err(|e| e.to_string())?;
            let (bow, _) = v.transform(&descriptors, 2);
            Ok::<bool, String>(bow.values().all(|w| w.is_finite()))
        });
        match result {
            Err(_) => vfail.push(format!("vocabulary case {case} ({what}): panicked")),
            Ok(Err(e)) if e.contains(&name) => vrefused += 1,
            Ok(Err(e)) => vfail.push(format!("vocabulary case {case} ({what}): refused without the name: {e}")),
            Ok(Ok(false)) => vfail.push(format!("vocabulary case {case} ({what}): non-finite weights")),
            Ok(Ok(true)) if what == "no word" => {
                vfail.push(format!("vocabulary case {case}: a vocabulary with no word loaded"))
            }
            Ok(Ok(true)) => {}
        }
    }
    eprintln!("vocabularies: 200 cases, {vrefused} refused naming the file");
    assert!(vfail.is_empty(), "{}", vfail.join("\n"));
}
