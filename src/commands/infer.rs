//! `dynaflow infer --model M IMAGE...`: detections per image as JSON.

use std::io::Write;
use std::path::PathBuf;

use dynaflow_infer::detect::{Decoder, Detector};
use dynaflow_infer::onnx;
use dynaflow_operators::inference::{COCO_NAMES, YOLOX_NANO, wgpu_or_fallback};

use crate::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

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
    #[arg(long, default_value = "yolox", value_parser = ["yolox", "fastestdet"])]
    pub decoder: String,
    /// Where the model runs: `cpu` (the reference executor) or `wgpu` (falls back to `cpu`
    /// with a warning without an adapter or for an op with no GPU kernel).
    #[arg(long, default_value = "cpu", value_parser = ["cpu", "wgpu"])]
    pub backend: String,
    /// Score threshold.
    #[arg(long, default_value_t = 0.3)]
    pub score: f32,
    /// NMS overlap threshold.
    #[arg(long, default_value_t = 0.45)]
    pub iou: f32,
}

/// Exit 0 with one JSON object per image, 2 on a bad model or image.
pub fn infer(args: &InferArgs) -> u8 {
    let model = match &args.model {
        Some(p) => onnx::load(p),
        None => onnx::parse(YOLOX_NANO),
    };
    let decoder = if args.decoder == "fastestdet" { Decoder::FastestDet } else { Decoder::Yolox };
    let detector = match model.map_err(|e| e.to_string()).and_then(|m| Detector::new(m, decoder)) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    let names: Vec<&str> = COCO_NAMES.lines().collect();
    let gpu = if args.backend == "wgpu" {
        // Without an adapter (or for an op with no GPU kernel) this warns and runs on the CPU.
        wgpu_or_fallback(detector.model()).0
    } else {
        None
    };
    let mut out = std::io::stdout().lock();
    for path in &args.images {
        let img = match image::open(path) {
            Ok(i) => i.into_rgb8(),
            Err(e) => {
                eprintln!("error: {}: {e}", path.display());
                return EXIT_BAD_INPUT;
            }
        };
        let (w, h) = (img.width() as usize, img.height() as usize);
        let found = match &gpu {
            Some(g) => detector.detect_with(img.as_raw(), w, h, names.len(), args.score, args.iou, |name, input| {
                g.run(&[(name, input)]).map_err(|e| e.to_string())
            }),
            None => detector.detect(img.as_raw(), w, h, names.len(), args.score, args.iou).map_err(|e| e.to_string()),
        };
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
