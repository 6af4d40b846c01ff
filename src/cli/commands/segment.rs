//! `dynaflow segment [--model M] --out DIR IMAGE...`: per image, `<stem>.png` (the class id of
//! every pixel, 8-bit, at the image's size) and `<stem>.json` (class names and pixel counts).

use std::path::PathBuf;

use dynaflow_engine::msg::{Image, PixelFormat};
use dynaflow_operators::inference::{Backend, InputRange, load_segmenter, segment_frame};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow segment` arguments.
#[derive(Debug, clap::Args)]
pub struct SegmentArgs {
    /// Images (PNG or JPEG).
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// Output folder (created).
    #[arg(long)]
    pub out: PathBuf,
    /// ONNX segmenter; default: the embedded PP-HumanSegV2-Lite (person vs background).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Class names, one per output channel; default: `classes.txt` beside the model.
    #[arg(long)]
    pub classes: Option<PathBuf>,
    /// How pixels are scaled into the model's input: `symmetric` [-1, 1] (PP-HumanSeg,
    /// DeepLabV3) or `unit` [0, 1] (MediaPipe).
    #[arg(long, default_value = "symmetric", value_parser = super::infer::names(InputRange::NAMES, InputRange::from_name))]
    pub input_range: InputRange,
    /// Where the model runs: `cpu` (rten), `wgpu` (our GPU executor; falls back to `cpu`
    /// with a warning) or `reference` (plain loops; slow).
    #[arg(long, default_value = "cpu", value_parser = super::infer::names(Backend::NAMES, Backend::from_name))]
    pub backend: Backend,
    /// Probability a pixel needs for its class.
    #[arg(long, default_value_t = 0.5)]
    pub threshold: f32,
    /// Grow every class region by this many pixels (the `segment` operator's default is 15;
    /// here 0, the model's own mask).
    #[arg(long, default_value_t = 0)]
    pub dilate: usize,
    /// With `--backend wgpu`, use a software adapter (lavapipe) too.
    #[arg(long)]
    pub allow_software: bool,
}

/// Exit 0 with the files written, 2 on a bad model, image or folder, 1 if a run fails.
pub fn segment(args: &SegmentArgs) -> u8 {
    if !(0.0..=1.0).contains(&args.threshold) {
        eprintln!("error: --threshold must be in 0..=1, got {}", args.threshold);
        return EXIT_BAD_INPUT;
    }
    // Every output named before any work: none may be an input, and no two images may
    // write the same file.
    let stems: Vec<String> = args
        .images
        .iter()
        .map(|p| p.file_stem().map_or_else(|| "image".into(), |s| s.to_string_lossy().into_owned()))
        .collect();
    for (i, stem) in stems.iter().enumerate() {
        if let Some(j) = stems[..i].iter().position(|s| s == stem) {
            eprintln!(
                "error: {} and {} would both write {}: segment images of the same name into different --out folders",
                args.images[j].display(),
                args.images[i].display(),
                args.out.join(format!("{stem}.png")).display()
            );
            return EXIT_BAD_INPUT;
        }
        for ext in ["png", "json"] {
            let out = args.out.join(format!("{stem}.{ext}"));
            if let Err(e) = dynaflow_engine::files::refuse_overwriting_inputs(
                "output",
                &out,
                args.images.iter().map(PathBuf::as_path),
            ) {
                eprintln!("error: {e} (--out {})", args.out.display());
                return EXIT_BAD_INPUT;
            }
        }
    }
    let none = PathBuf::new();
    let loaded = load_segmenter(
        args.model.as_ref().unwrap_or(&none),
        args.classes.as_ref().unwrap_or(&none),
        args.input_range,
        args.backend,
        args.allow_software,
    );
    let (segmenter, runner, _) = match loaded {
        Ok(l) => l,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    if segmenter.classes().len() > 256 {
        eprintln!("error: {} classes do not fit an 8-bit class image", segmenter.classes().len());
        return EXIT_BAD_INPUT;
    }
    if let Err(e) = std::fs::create_dir_all(&args.out) {
        eprintln!("error: cannot create {}: {e}", args.out.display());
        return EXIT_BAD_INPUT;
    }
    for (k, path) in args.images.iter().enumerate() {
        let rgb = match crate::cli::plot::open_image(path) {
            Ok(i) => i.into_rgb8(),
            Err(e) => {
                eprintln!("error: {}: {e}", path.display());
                return EXIT_BAD_INPUT;
            }
        };
        let (w, h) = rgb.dimensions();
        let img = Image { width: w, height: h, format: PixelFormat::Rgb8, data: rgb.into_raw() };
        let (classes, instances) = match segment_frame(&segmenter, &runner, &img, args.threshold, args.dilate, None) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("error: {}: {e}", path.display());
                return EXIT_FAILED;
            }
        };
        let stem = &stems[k];
        let png = args.out.join(format!("{stem}.png"));
        let bytes: Vec<u8> = classes.iter().map(|&c| c as u8).collect();
        let written = crate::cli::plot::png_bytes(w, h, image::ExtendedColorType::L8, &bytes)
            .and_then(|b| dynaflow_engine::files::write_atomic(&png, &b).map_err(|e| e.to_string()));
        if let Err(e) = written {
            eprintln!("error: cannot write {}: {e}", png.display());
            return EXIT_FAILED;
        }
        let mut counts = vec![0u64; segmenter.classes().len()];
        for &c in &classes {
            if let Some(n) = counts.get_mut(usize::from(c)) {
                *n += 1;
            }
        }
        let summary = serde_json::json!({
            "image": path.display().to_string(),
            "width": w,
            "height": h,
            "classes": segmenter.classes(),
            "pixels": segmenter.classes().iter().zip(&counts).filter(|(_, n)| **n > 0).map(|(c, n)| (c.clone(), serde_json::Value::from(*n))).collect::<serde_json::Map<String, serde_json::Value>>(),
            "instances": instances.iter().copied().max().unwrap_or(0),
        });
        let json = args.out.join(format!("{stem}.json"));
        if let Err(e) = dynaflow_engine::files::write_atomic(&json, (summary.to_string() + "\n").as_bytes()) {
            eprintln!("error: cannot write {}: {e}", json.display());
            return EXIT_FAILED;
        }
    }
    EXIT_OK
}
