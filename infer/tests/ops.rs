//! The reference executor's ops for the segmenters, on values worked out by hand from the ONNX
//! operator definitions (the whole models are compared with onnxruntime in the workspace's
//! `tests/infer.rs`): bilinear `Resize` under each coordinate transformation and at a
//! non-integer factor, `ConvTranspose` with padding, output padding, dilation and groups,
//! `auto_pad` on `Conv`, `Clip`, `HardSigmoid`, `HardSwish`, `GlobalAveragePool`.
#![allow(clippy::unwrap_used, clippy::panic)]

use dynaflow_infer::onnx::{Attribute, Node, Op};
use dynaflow_infer::reference::eval_node;
use dynaflow_infer::tensor::Tensor;

fn node(op: &str, attributes: &[(&str, Attribute)]) -> Node {
    Node {
        name: op.into(),
        op: Op::parse(op),
        domain: String::new(),
        inputs: Vec::new(),
        outputs: vec!["y".into()],
        attributes: attributes.iter().map(|(k, v)| ((*k).to_string(), v.clone())).collect(),
    }
}

fn text(s: &str) -> Attribute {
    Attribute::String(s.as_bytes().to_vec())
}

fn f32s(shape: &[usize], data: &[f32]) -> Tensor {
    Tensor::F32 { shape: shape.to_vec(), data: data.to_vec() }
}

fn run(n: &Node, args: &[Option<&Tensor>]) -> (Vec<usize>, Vec<f32>) {
    let out = eval_node(n, args).unwrap_or_else(|e| panic!("{e}"));
    (out[0].shape().to_vec(), out[0].floats())
}

fn close(a: &[f32], b: &[f32]) {
    assert_eq!(a.len(), b.len(), "{a:?} vs {b:?}");
    assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6), "{a:?} vs {b:?}");
}

#[test]
fn bilinear_resize_follows_each_coordinate_transformation() {
    let x = f32s(&[1, 1, 1, 2], &[0.0, 1.0]);
    let sizes = Tensor::I64 { shape: vec![4], data: vec![1, 1, 1, 4] };
    let resize = |ctm: &str| node("Resize", &[("mode", text("linear")), ("coordinate_transformation_mode", text(ctm))]);
    // half_pixel: x_in = (o + 0.5) / 2 - 0.5 = -0.25, 0.25, 0.75, 1.25, clamped to [0, 1].
    let (s, y) = run(&resize("half_pixel"), &[Some(&x), None, None, Some(&sizes)]);
    assert_eq!(s, vec![1, 1, 1, 4]);
    close(&y, &[0.0, 0.25, 0.75, 1.0]);
    // align_corners: x_in = o * (2 - 1) / (4 - 1).
    let (_, y) = run(&resize("align_corners"), &[Some(&x), None, None, Some(&sizes)]);
    close(&y, &[0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0]);
    // asymmetric: x_in = o / 2.
    let (_, y) = run(&resize("asymmetric"), &[Some(&x), None, None, Some(&sizes)]);
    close(&y, &[0.0, 0.5, 1.0, 1.0]);
    // A non-integer factor by `scales` (3 -> floor(3 * 1.5) = 4; half_pixel x_in = (o + 0.5) / 1.5 - 0.5).
    let x = f32s(&[1, 1, 1, 3], &[0.0, 3.0, 6.0]);
    let scales = f32s(&[4], &[1.0, 1.0, 1.0, 1.5]);
    let (s, y) = run(&resize("half_pixel"), &[Some(&x), None, Some(&scales)]);
    assert_eq!(s, vec![1, 1, 1, 4]);
    let want: Vec<f32> = (0..4).map(|o| (((o as f32 + 0.5) / 1.5 - 0.5).clamp(0.0, 2.0)) * 3.0).collect();
    close(&y, &want);
    // Height and width together: a 2x2 patch to 3x3 with align_corners is its bilinear grid.
    let x = f32s(&[1, 1, 2, 2], &[0.0, 2.0, 4.0, 6.0]);
    let sizes = Tensor::I64 { shape: vec![4], data: vec![1, 1, 3, 3] };
    let (_, y) = run(&resize("align_corners"), &[Some(&x), None, None, Some(&sizes)]);
    close(&y, &[0.0, 1.0, 2.0, 2.0, 3.0, 4.0, 4.0, 5.0, 6.0]);
    // Nearest under half_pixel with round_prefer_ceil: 2 -> 3, x_in = (o + 0.5) * 2 / 3 - 0.5.
    let x = f32s(&[1, 1, 1, 2], &[7.0, 9.0]);
    let sizes = Tensor::I64 { shape: vec![4], data: vec![1, 1, 1, 3] };
    let n = node("Resize", &[("mode", text("nearest")), ("nearest_mode", text("round_prefer_ceil"))]);
    let (_, y) = run(&n, &[Some(&x), None, None, Some(&sizes)]);
    close(&y, &[7.0, 9.0, 9.0]);
}

#[test]
fn a_resize_of_the_batch_or_channels_is_refused() {
    let x = f32s(&[1, 2, 1, 1], &[1.0, 2.0]);
    let sizes = Tensor::I64 { shape: vec![4], data: vec![1, 4, 1, 1] };
    let err =
        eval_node(&node("Resize", &[("mode", text("linear"))]), &[Some(&x), None, None, Some(&sizes)]).unwrap_err();
    assert!(err.to_string().contains("only height and width"), "{err}");
    let sizes = Tensor::I64 { shape: vec![4], data: vec![1, 2, 2, 2] };
    let err =
        eval_node(&node("Resize", &[("mode", text("cubic"))]), &[Some(&x), None, None, Some(&sizes)]).unwrap_err();
    assert!(err.to_string().contains("cubic"), "{err}");
}

#[test]
fn conv_transpose_scatters_through_the_kernel_with_pads_output_padding_dilation_and_groups() {
    let ints = |v: &[i64]| Attribute::Ints(v.to_vec());
    // 1 input channel, 2x2 input, 2x2 kernel of ones, stride 2: each input pixel becomes a
    // 2x2 block (depth to space).
    let x = f32s(&[1, 1, 2, 2], &[1.0, 2.0, 3.0, 4.0]);
    let w = f32s(&[1, 1, 2, 2], &[1.0; 4]);
    let (s, y) = run(&node("ConvTranspose", &[("strides", ints(&[2, 2]))]), &[Some(&x), Some(&w)]);
    assert_eq!(s, vec![1, 1, 4, 4]);
    close(&y, &[1.0, 1.0, 2.0, 2.0, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 4.0, 4.0, 3.0, 3.0, 4.0, 4.0]);
    // Stride 1, 3x3 kernel of ones, pads 1: each output is the sum of its 3x3 input
    // neighbourhood (a same-size box filter), plus the bias.
    let x = f32s(&[1, 1, 2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    let w = f32s(&[1, 1, 3, 3], &[1.0; 9]);
    let b = f32s(&[1], &[0.5]);
    let (s, y) = run(&node("ConvTranspose", &[("pads", ints(&[1, 1, 1, 1]))]), &[Some(&x), Some(&w), Some(&b)]);
    assert_eq!(s, vec![1, 1, 2, 3]);
    close(&y, &[12.5, 21.5, 16.5, 12.5, 21.5, 16.5]);
    // Output padding adds a row and a column at the end (zero there without bias); a 1x1
    // kernel with dilation 2 changes nothing but the size formula.
    let x = f32s(&[1, 1, 1, 1], &[5.0]);
    let w = f32s(&[1, 1, 1, 1], &[2.0]);
    let n = node(
        "ConvTranspose",
        &[("strides", ints(&[2, 2])), ("output_padding", ints(&[1, 1])), ("dilations", ints(&[2, 2]))],
    );
    let (s, y) = run(&n, &[Some(&x), Some(&w)]);
    assert_eq!(s, vec![1, 1, 2, 2]);
    close(&y, &[10.0, 0.0, 0.0, 0.0]);
    // Two groups: input channel 0 feeds output channel 0 only, channel 1 output 1 only.
    let x = f32s(&[1, 2, 1, 1], &[1.0, 10.0]);
    let w = f32s(&[2, 1, 1, 1], &[3.0, 4.0]);
    let (s, y) = run(&node("ConvTranspose", &[("group", Attribute::Int(2))]), &[Some(&x), Some(&w)]);
    assert_eq!(s, vec![1, 2, 1, 1]);
    close(&y, &[3.0, 40.0]);
    // SAME_UPPER: the output is input x stride, the odd pad at the end.
    let x = f32s(&[1, 1, 1, 2], &[1.0, 2.0]);
    let w = f32s(&[1, 1, 1, 3], &[1.0, 10.0, 100.0]);
    let n = node("ConvTranspose", &[("strides", ints(&[1, 2])), ("auto_pad", text("SAME_UPPER"))]);
    let (s, y) = run(&n, &[Some(&x), Some(&w)]);
    assert_eq!(s, vec![1, 1, 1, 4]);
    // Full output (length 5): [1, 10, 100 + 2, 20, 200]; total pad 1, at the end.
    close(&y, &[1.0, 10.0, 102.0, 20.0]);
}

#[test]
fn conv_same_upper_pads_to_ceil_of_input_over_stride() {
    let x = f32s(&[1, 1, 1, 4], &[1.0, 2.0, 3.0, 4.0]);
    let w = f32s(&[1, 1, 1, 3], &[1.0, 1.0, 1.0]);
    let n = node("Conv", &[("auto_pad", text("SAME_UPPER")), ("strides", Attribute::Ints(vec![1, 2]))]);
    // Output ceil(4 / 2) = 2; total pad (2 - 1) * 2 + 3 - 4 = 1, at the end: windows [1,2,3], [3,4,0].
    let (s, y) = run(&n, &[Some(&x), Some(&w)]);
    assert_eq!(s, vec![1, 1, 1, 2]);
    close(&y, &[6.0, 7.0]);
    let n = node("Conv", &[("auto_pad", text("SAME_LOWER")), ("strides", Attribute::Ints(vec![1, 2]))]);
    // The pad at the start: windows [0,1,2], [2,3,4].
    let (_, y) = run(&n, &[Some(&x), Some(&w)]);
    close(&y, &[3.0, 9.0]);
}

#[test]
fn clip_hard_sigmoid_hard_swish_and_global_average_pool() {
    let x = f32s(&[1, 1, 1, 5], &[-4.0, -1.0, 0.0, 2.0, 7.0]);
    let (lo, hi) = (f32s(&[], &[0.0]), f32s(&[], &[6.0]));
    let (_, y) = run(&node("Clip", &[]), &[Some(&x), Some(&lo), Some(&hi)]);
    close(&y, &[0.0, 0.0, 0.0, 2.0, 6.0]);
    let (_, y) = run(&node("Clip", &[]), &[Some(&x), None, Some(&hi)]);
    close(&y, &[-4.0, -1.0, 0.0, 2.0, 6.0]);
    let (_, y) = run(&node("HardSigmoid", &[]), &[Some(&x)]);
    close(&y, &[0.0, 0.3, 0.5, 0.9, 1.0]);
    let (_, y) =
        run(&node("HardSigmoid", &[("alpha", Attribute::Float(0.5)), ("beta", Attribute::Float(0.25))]), &[Some(&x)]);
    close(&y, &[0.0, 0.0, 0.25, 1.0, 1.0]);
    // x * relu6(x + 3) / 6.
    let (_, y) = run(&node("HardSwish", &[]), &[Some(&x)]);
    close(&y, &[0.0, -1.0 / 3.0, 0.0, 2.0 * 5.0 / 6.0, 7.0]);
    let x = f32s(&[1, 2, 2, 2], &[1.0, 2.0, 3.0, 4.0, -1.0, -1.0, 5.0, 5.0]);
    let (s, y) = run(&node("GlobalAveragePool", &[]), &[Some(&x)]);
    assert_eq!(s, vec![1, 2, 1, 1]);
    close(&y, &[2.5, 2.0]);
    let (a, b) = (f32s(&[2], &[6.0, 1.0]), f32s(&[1], &[4.0]));
    let (_, y) = run(&node("Div", &[]), &[Some(&a), Some(&b)]);
    close(&y, &[1.5, 0.25]);
}
