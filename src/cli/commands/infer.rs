//! `dynaflow infer --model M IMAGE...`: detections per image as JSON.

use std::io::Write;
use std::path::PathBuf;

use dynaflow_infer::detect::Detector;
use dynaflow_infer::onnx;
use dynaflow_operators::inference::{Backend, COCO_NAMES, DecoderName, Runner, YOLOX_NANO};

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// `dynaflow infer` arguments.
#[derive(Debug, clap::Args)]
pub struct InferArgs {
    /// Images (PNG or JPEG).
    #[arg(required = true)]
    pub images: Vec<PathBuf>,
    /// ONNX model; default: the embedded YOLOX-nano (COCO-80).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Output decoding of the model.
    #[arg(long, default_value = "yolox", value_parser = names(DecoderName::NAMES, DecoderName::from_name))]
    pub decoder: DecoderName,
    /// Where the model runs: `cpu` (rten), `wgpu` (our GPU executor; falls back to `cpu`
    /// with a warning without an adapter or for a model it cannot plan) or `reference` (plain
    /// loops; slow).
    #[arg(long, default_value = "cpu", value_parser = names(Backend::NAMES, Backend::from_name))]
    pub backend: Backend,
    /// Score threshold.
    #[arg(long, default_value_t = 0.3)]
    pub score: f32,
    /// NMS overlap threshold.
    #[arg(long, default_value_t = 0.45)]
    pub iou: f32,
    /// With `--backend wgpu`, use a software adapter (Mesa's lavapipe, WARP) too; without it
    /// such an adapter counts as no GPU and the model runs on the CPU (rten).
    #[arg(long)]
    pub allow_software: bool,
}

/// A clap parser for the names of a graph parameter's enum, so the flag and the parameter
/// take the same values.
pub(super) fn names<T: Clone + Send + Sync + 'static>(
    names: &'static [&'static str],
    from: fn(&str) -> Option<T>,
) -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser as _;
    clap::builder::PossibleValuesParser::new(names).try_map(move |s: String| from(&s).ok_or("unknown name"))
}

/// Exit 0 with one JSON object per image, 2 on a bad model or image.
pub fn infer(args: &InferArgs) -> u8 {
    let loaded = match &args.model {
        Some(p) => onnx::load_with_bytes(p),
        None => onnx::parse(YOLOX_NANO).map(|m| (m, YOLOX_NANO.to_vec())),
    };
    for (flag, v) in [("--score", args.score), ("--iou", args.iou)] {
        if !(0.0..=1.0).contains(&v) {
            eprintln!("error: {flag} must be in 0..=1, got {v}");
            return EXIT_BAD_INPUT;
        }
    }
    let decoder = args.decoder.decoder();
    // Without an adapter (or for a model it cannot plan) `wgpu` warns and runs on the CPU.
    let ready = loaded.map_err(|e| e.to_string()).and_then(|(m, bytes)| {
        let (runner, _) = Runner::new(&bytes, &m, args.backend, args.allow_software).map_err(|e| e.to_string())?;
        let which =
            args.model.as_ref().map_or_else(|| "the embedded YOLOX-nano".to_owned(), |p| p.display().to_string());
        Ok((Detector::new(m, decoder).map_err(|e| format!("{which}: {e}"))?, runner))
    });
    let (detector, runner) = match ready {
        Ok(d) => d,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    let names: Vec<&str> = COCO_NAMES.lines().collect();
    let mut out = std::io::stdout().lock();
    for path in &args.images {
        let img = match crate::cli::plot::open_image(path) {
            Ok(i) => i.into_rgb8(),
            Err(e) => {
                eprintln!("error: {}: {e}", path.display());
                return EXIT_BAD_INPUT;
            }
        };
        let (w, h) = (img.width() as usize, img.height() as usize);
        let found = detector
            .detect_with(img.as_raw(), w, h, names.len(), args.score, args.iou, |name, input| runner.run(name, input));
        let dets = match found {
            Ok(d) => d,
            Err(e) => {
                eprintln!("error: {}: {e}", path.display());
                return EXIT_FAILED;
            }
        };
        let list: Vec<serde_json::Value> = dets
            .iter()
            .map(|d| {
                serde_json::json!({
                    "class": names.get(d.class).copied().unwrap_or("?"),
                    "class_id": d.class,
                    "score": d.score,
                    "box": d.bbox,
                })
            })
            .collect();
        let line =
            serde_json::json!({ "image": path.display().to_string(), "width": w, "height": h, "detections": list });
        // A closed pipe ends the output, not the command's success.
        if writeln!(out, "{line}").is_err() {
            return EXIT_OK;
        }
    }
    EXIT_OK
}
