//! Whole models on the GPU against the reference executor, on real images.
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::path::PathBuf;

use common::gpu;
use dynaflow_gpu::GpuModel;
use dynaflow_infer::detect::letterbox_bgr;
use dynaflow_infer::onnx::load;
use dynaflow_infer::reference::run;
use dynaflow_infer::tensor::Tensor;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn yolox_nano_on_the_gpu_equals_the_reference_on_real_images() {
    let Some(gpu) = gpu(
        "gpu::models::yolox_nano_on_the_gpu_equals_the_reference_on_real_images: GPU kernels vs the reference executor",
    ) else {
        return;
    };
    let model = load(&repo().join("models/yolox_nano/yolox_nano.onnx")).unwrap();
    let on_gpu = GpuModel::new(gpu, &model).unwrap();
    eprintln!("adapter: {}, plan: {:?}", on_gpu.adapter(), on_gpu.stats());
    // The SiLU of every convolution but the heads' outputs is fused; every Concat input that
    // a kernel produces is written in place.
    assert!(on_gpu.stats().fused_activations >= 60, "{:?}", on_gpu.stats());
    assert!(on_gpu.stats().concat_in_place >= 20, "{:?}", on_gpu.stats());
    for img in ["tests/fixtures/slambook2_rgbd_pair/rgb/1.png", "tests/fixtures/slambook2_dense_rgbd/color/1.png"] {
        let rgb = image::open(repo().join(img)).unwrap().into_rgb8();
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        let (x, _) = letterbox_bgr(rgb.as_raw(), w, h, 416);
        let input = Tensor::F32 { shape: vec![1, 3, 416, 416], data: x };
        let want = run(&model, &[("images", input.clone())]).unwrap();
        let t0 = std::time::Instant::now();
        let got = on_gpu.run(&[("images", input)]).unwrap();
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        assert_eq!(got[0].shape(), want[0].shape());
        let d = got[0].floats().iter().zip(want[0].floats()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        eprintln!("{img}: max |gpu - cpu| = {d:e} ({ms:.0} ms, one submit)");
        assert!(d <= 1e-3, "{img}: {d}");
    }
}

#[test]
fn fastestdet_on_the_gpu_equals_the_reference_on_real_images() {
    let Some(gpu) = gpu(
        "gpu::models::fastestdet_on_the_gpu_equals_the_reference_on_real_images: GPU kernels vs the reference executor",
    ) else {
        return;
    };
    let model = load(&repo().join("models/fastestdet/FastestDet.onnx")).unwrap();
    assert_eq!(GpuModel::unsupported(&model), None);
    let name = model.inputs[0].name.clone();
    let on_gpu = GpuModel::new(gpu, &model).unwrap();
    eprintln!("FastestDet plan: {:?}", on_gpu.stats());
    for img in ["tests/fixtures/slambook2_rgbd_pair/rgb/2.png", "tests/fixtures/slambook2_dense_rgbd/color/3.png"] {
        let rgb = image::open(repo().join(img)).unwrap().into_rgb8();
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        let x = dynaflow_infer::detect::resize_bgr_unit(rgb.as_raw(), w, h, 352);
        let input = Tensor::F32 { shape: vec![1, 3, 352, 352], data: x };
        let want = run(&model, &[(name.as_str(), input.clone())]).unwrap();
        let got = on_gpu.run(&[(name.as_str(), input)]).unwrap();
        assert_eq!(got[0].shape(), want[0].shape());
        let d = got[0].floats().iter().zip(want[0].floats()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        eprintln!("FastestDet {img}: max |gpu - cpu| = {d:e}");
        assert!(d <= 1e-3, "{img}: {d}");
    }
}

#[test]
fn the_segmenters_on_the_gpu_equal_the_reference_on_real_images() {
    use dynaflow_infer::segment::{Normalise, Segmenter, read_classes};
    let Some(gpu) = gpu(
        "gpu::models::the_segmenters_on_the_gpu_equal_the_reference_on_real_images: GPU kernels vs the reference executor",
    ) else {
        return;
    };
    let seg = repo().join("models/seg");
    for (file, range) in [
        ("pp_humansegv2_lite/pp_humansegv2_lite_256x144.onnx", Normalise::Symmetric),
        ("mediapipe_selfie_segmentation/selfie_segmentation.onnx", Normalise::Unit),
        ("mediapipe_selfie_segmentation/selfie_segmentation_landscape.onnx", Normalise::Unit),
        ("deeplabv3_mnv2_voc/deeplabv3_257_mv.onnx", Normalise::Symmetric),
    ] {
        let path = seg.join(file);
        let model = load(&path).unwrap();
        let s =
            Segmenter::new(model.clone(), read_classes(&path.with_file_name("classes.txt")).unwrap(), range).unwrap();
        let on_gpu = GpuModel::new(gpu.clone(), &model).unwrap_or_else(|e| panic!("{file}: {e}"));
        eprintln!("{file}: plan {:?}", on_gpu.stats());
        for img in ["tests/fixtures/slambook2_rgbd_pair/rgb/1.png", "tests/fixtures/slambook2_dense_rgbd/color/1.png"] {
            let rgb = image::open(repo().join(img)).unwrap().into_rgb8();
            let input = s.input(rgb.as_raw(), rgb.width() as usize, rgb.height() as usize);
            let want = run(&model, &[(s.input_name(), input.clone())]).unwrap();
            let got = on_gpu.run(&[(s.input_name(), input)]).unwrap();
            assert_eq!(got[0].shape(), want[0].shape(), "{file}");
            let d = got[0].floats().iter().zip(want[0].floats()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            eprintln!("{file} {img}: max |gpu - reference| = {d:e}");
            assert!(d <= 1e-3, "{file} {img}: {d}");
        }
    }
}
