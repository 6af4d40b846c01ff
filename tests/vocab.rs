//! `dynaflow vocab train` and place recognition with the vocabulary (first part):
//! trained on one synthetic sequence, it tells frames of another sequence that see the same
//! place from frames that do not, and its file is refused when damaged.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::{Path, PathBuf};

use dynaflow_datasets::png::load_rgb;
use dynaflow_slam::bow::{Vocabulary, score};
use dynaflow_vision::GrayImage;
use dynaflow_vision::orb::{OrbConfig, OrbExtractor};

fn synth(dir: &Path, motion: &str, seed: u64, frames: u64) -> Vec<PathBuf> {
    let o = common::bin()
        .args([
            "synth",
            "--motion",
            motion,
            "--people",
            "0",
            "--frames",
            &frames.to_string(),
            "--seed",
            &seed.to_string(),
            "--out",
        ])
        .arg(dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir.join("rgb")).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    files
}

#[test]
fn a_vocabulary_trained_on_one_sequence_recognises_places_in_another() {
    let dir = common::TempDir::new("vocab");
    // Training: every 4th frame of an xyz sequence (seed 31).
    let train: Vec<PathBuf> = synth(&dir.path().join("train"), "xyz", 31, 120).into_iter().step_by(4).collect();
    let voc_path = dir.path().join("voc.bin");
    let o =
        common::bin().args(["vocab", "train", "--levels", "4", "--out"]).arg(&voc_path).args(&train).output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("from 30000 descriptors of 30 images"), "{stdout}");
    let voc = Vocabulary::load(&voc_path).unwrap();
    assert_eq!(voc.levels(), 4);
    assert!(stdout.contains(&voc.id()), "{stdout}");

    // Test: a halfsphere orbit of another scene (seed 32), never seen in training.
    let frames = synth(&dir.path().join("test"), "halfsphere", 32, 300);
    let mut orb = OrbExtractor::new(OrbConfig::default());
    let bows: Vec<_> = frames
        .iter()
        .step_by(10)
        .map(|f| {
            let img = load_rgb(f).unwrap();
            let g = GrayImage::from_rgb8(img.width as usize, img.height as usize, &img.data).unwrap();
            voc.transform(&orb.extract(&g, None).descriptors, 2).0
        })
        .collect();
    let mean = |pairs: &[(usize, usize)]| {
        pairs.iter().map(|&(a, b)| score(&bows[a], &bows[b])).sum::<f64>() / pairs.len() as f64
    };
    let n = bows.len();
    for d in [1, 2, 3, 5, 8, 12, 15, 20, 25] {
        let pairs: Vec<(usize, usize)> = (0..n.saturating_sub(d)).map(|i| (i, i + d)).collect();
        if !pairs.is_empty() {
            eprintln!("distance {} frames: {:.4}", 10 * d, mean(&pairs));
        }
    }
    let near: Vec<(usize, usize)> = (0..n - 1).map(|i| (i, i + 1)).collect();
    let far: Vec<(usize, usize)> = (0..n / 2).map(|i| (i, i + n / 2)).collect();
    let (near_s, far_s) = (mean(&near), mean(&far));
    eprintln!("BoW score: frames 10 apart {near_s:.4}, 150 apart {far_s:.4} (ratio {:.2})", near_s / far_s);
    // The room repeats one brick texture on every wall, so any two views share many words
    // (measured 0.19 at 10 frames, 0.155 at 150); the ranking is what place recognition uses.
    assert!(near_s > 1.1 * far_s, "near {near_s} vs far {far_s}");
    // The best match of each frame among the others is a neighbour (within 20 frames).
    let mut right = 0;
    for i in 0..n {
        let best = (0..n)
            .filter(|&j| j != i)
            .max_by(|&a, &b| score(&bows[i], &bows[a]).total_cmp(&score(&bows[i], &bows[b])))
            .unwrap();
        right += usize::from(best.abs_diff(i) <= 2);
    }
    eprintln!("best match within 20 frames: {right} of {n}");
    // Measured 28 of 30.
    assert!(right as f64 >= 0.8 * n as f64, "{right} of {n}");

    // A damaged file is refused, naming it.
    let bytes = std::fs::read(&voc_path).unwrap();
    let cut = dir.path().join("cut.bin");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = Vocabulary::load(&cut).unwrap_err().to_string();
    assert!(e.contains("cut.bin") && e.contains("truncated"), "{e}");
    // Bad images are bad input.
    let o = common::bin()
        .args(["vocab", "train", "--out"])
        .arg(dir.path().join("x.bin"))
        .arg(dir.path().join("nope.png"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("nope.png"));
}
