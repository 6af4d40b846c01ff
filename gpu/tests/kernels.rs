//! Every kernel, through the planner, against `dynaflow-infer`'s reference executor on odd
//! shapes: small ONNX graphs built here, run by both. On whatever adapter there is (Mesa's
//! lavapipe under `scripts/test.sh`, which requires it).
#![allow(clippy::unwrap_used, clippy::panic)]

mod common;

use std::collections::BTreeMap;

use common::gpu;
use dynaflow_gpu::{ConvShape, Gpu, GpuModel, PlanStats};
use dynaflow_infer::onnx::{Attribute, DataType, Model, Node, TensorData, ValueInfo};
use dynaflow_infer::reference::run;
use dynaflow_infer::tensor::Tensor;

/// Deterministic values in -1..1.
fn values(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}

fn node(op: &str, inputs: &[&str], output: &str, attributes: &[(&str, Attribute)]) -> Node {
    Node {
        name: format!("{op}_{output}"),
        op: dynaflow_infer::onnx::Op::parse(op),
        domain: String::new(),
        inputs: inputs.iter().map(|s| (*s).to_string()).collect(),
        outputs: vec![output.into()],
        attributes: attributes.iter().map(|(k, v)| ((*k).to_string(), v.clone())).collect(),
    }
}

fn floats(name: &str, dims: &[usize], data: Vec<f32>) -> (String, TensorData) {
    let t = TensorData {
        name: name.into(),
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: DataType::Float,
        floats: data,
        ints: Vec::new(),
    };
    (name.into(), t)
}

fn int64s(name: &str, dims: &[usize], data: Vec<i64>) -> (String, TensorData) {
    let t = TensorData {
        name: name.into(),
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: DataType::Int64,
        floats: Vec::new(),
        ints: data,
    };
    (name.into(), t)
}

fn ints(v: &[usize]) -> Attribute {
    Attribute::Ints(v.iter().map(|&x| x as i64).collect())
}

fn text(s: &str) -> Attribute {
    Attribute::String(s.as_bytes().to_vec())
}

fn graph(nodes: Vec<Node>, initializers: Vec<(String, TensorData)>, outputs: &[&str]) -> Model {
    Model {
        ir_version: 7,
        opset: 11,
        producer: String::new(),
        nodes,
        initializers: initializers.into_iter().collect::<BTreeMap<_, _>>(),
        inputs: vec![],
        outputs: outputs.iter().map(|o| ValueInfo { name: (*o).into(), elem_type: 1, shape: vec![] }).collect(),
    }
}

/// Run `model` on the GPU (planned for these inputs) and on the reference executor; the
/// largest difference over all outputs and the plan's statistics.
fn compare(gpu: Gpu, model: &Model, inputs: &[(&str, Vec<usize>)]) -> (f32, PlanStats) {
    let tensors: Vec<(&str, Tensor)> = inputs
        .iter()
        .enumerate()
        .map(|(k, (name, shape))| {
            (*name, Tensor::F32 { shape: shape.clone(), data: values(shape.iter().product(), 100 + k as u64) })
        })
        .collect();
    let planned = GpuModel::with_inputs(gpu, model, inputs).unwrap();
    let got = planned.run(&tensors).unwrap();
    let want = run(model, &tensors).unwrap();
    assert_eq!(got.len(), want.len());
    let mut d = 0.0f32;
    for (g, w) in got.iter().zip(&want) {
        assert_eq!(g.shape(), w.shape());
        d = g.floats().iter().zip(w.floats()).map(|(a, b)| (a - b).abs()).fold(d, f32::max);
    }
    (d, planned.stats().clone())
}

#[test]
fn convolutions_equal_the_reference_on_odd_shapes() {
    // (input, kernel m/kh/kw, stride, pads, dilation, group): grouped 3x3 stride 2 and
    // depthwise 3x3 (direct kernel); 1x1, dilated 5x5 (few channels: 16x256 tiles), a
    // 3x3 with more than one 64x64 tile and K not a multiple of 16, batch 2 (implicit GEMM).
    let cases = [
        ([1, 6, 13, 11], [4, 3, 3], [2, 2], [1, 1, 1, 1], [1, 1], 2),
        ([1, 5, 9, 7], [5, 3, 3], [1, 1], [1, 1, 1, 1], [1, 1], 5),
        ([2, 7, 5, 9], [3, 1, 1], [1, 1], [0, 0, 0, 0], [1, 1], 1),
        ([1, 3, 17, 15], [2, 5, 5], [1, 2], [2, 1, 2, 3], [2, 1], 1),
        ([2, 19, 23, 21], [70, 3, 3], [1, 1], [1, 1, 1, 1], [1, 1], 1),
        // At most 16 output channels: the 16x256 tile (YOLOX's stem), over 256 pixels; 17 to
        // 32: the 32x128 tile (FastestDet's stem, stride 2).
        ([1, 12, 29, 31], [13, 3, 3], [1, 1], [1, 1, 1, 1], [1, 1], 1),
        ([1, 3, 37, 41], [29, 3, 3], [2, 2], [1, 1, 1, 1], [1, 1], 1),
    ];
    for (k, (input, kernel, stride, pads, dilation, group)) in cases.into_iter().enumerate() {
        let Some(gpu) =
            gpu("gpu::kernels::convolutions_equal_the_reference_on_odd_shapes: GPU kernels vs the reference executor")
        else {
            return;
        };
        let cg = input[1] / group;
        let seed = 10 * k as u64;
        let model = graph(
            vec![node(
                "Conv",
                &["x", "w", "b"],
                "y",
                &[
                    ("kernel_shape", ints(&kernel[1..])),
                    ("strides", ints(&stride)),
                    ("pads", ints(&pads)),
                    ("dilations", ints(&dilation)),
                    ("group", Attribute::Int(group as i64)),
                ],
            )],
            vec![
                floats(
                    "w",
                    &[kernel[0], cg, kernel[1], kernel[2]],
                    values(kernel[0] * cg * kernel[1] * kernel[2], seed),
                ),
                floats("b", &[kernel[0]], values(kernel[0], seed + 1)),
            ],
            &["y"],
        );
        let (d, _) = compare(gpu, &model, &[("x", input.to_vec())]);
        eprintln!("conv case {k} {input:?} kernel {kernel:?} group {group}: max |gpu - cpu| = {d:e}");
        assert!(d <= 1e-4, "case {k}: {d}");
    }
}

#[test]
fn activations_fuse_into_convolutions() {
    let conv = |out: &str| {
        node("Conv", &["x", "w", "b"], out, &[("kernel_shape", ints(&[3, 3])), ("pads", ints(&[1, 1, 1, 1]))])
    };
    let weights = || vec![floats("w", &[9, 4, 3, 3], values(9 * 36, 1)), floats("b", &[9], values(9, 2))];
    let x = [("x", vec![1, 4, 11, 13])];
    // YOLOX's SiLU: Conv -> Sigmoid -> Mul(conv, sigmoid).
    let silu = graph(
        vec![conv("c"), node("Sigmoid", &["c"], "s", &[]), node("Mul", &["c", "s"], "y", &[])],
        weights(),
        &["y"],
    );
    // FastestDet's Conv -> Relu; and a sigmoid whose input is also an output (not fused).
    let relu = graph(vec![conv("c"), node("Relu", &["c"], "y", &[])], weights(), &["y"]);
    let kept = graph(vec![conv("c"), node("Sigmoid", &["c"], "y", &[])], weights(), &["c", "y"]);
    for (name, model, fused, dispatches) in [("silu", silu, 1, 1), ("relu", relu, 1, 1), ("kept", kept, 0, 2)] {
        let Some(gpu) = gpu("gpu::kernels::activations_fuse_into_convolutions: GPU kernels vs the reference executor")
        else {
            return;
        };
        let (d, stats) = compare(gpu, &model, &x);
        eprintln!("{name}: max |gpu - cpu| = {d:e}, {stats:?}");
        assert!(d <= 1e-5, "{name}: {d}");
        assert_eq!((stats.fused_activations, stats.dispatches), (fused, dispatches), "{name}");
    }
}

#[test]
fn concat_inputs_are_written_in_place_and_copied_when_they_must_be() {
    let Some(gpu) = gpu(
        "gpu::kernels::concat_inputs_are_written_in_place_and_copied_when_they_must_be: GPU kernels vs the reference executor",
    ) else {
        return;
    };
    let conv = |w: &str, out: &str| node("Conv", &["x", w, ""], out, &[("kernel_shape", ints(&[1, 1]))]);
    // Two convolutions write straight into the concatenation; the graph input `x` is copied;
    // `a` is also read by the Add, which reads it inside the concatenation's buffer.
    let model = graph(
        vec![
            conv("wa", "a"),
            conv("wb", "b"),
            node("Concat", &["a", "x", "b"], "c", &[("axis", Attribute::Int(1))]),
            node("Add", &["a", "b"], "s", &[]),
            node("Sigmoid", &["c"], "y", &[]),
        ],
        vec![floats("wa", &[3, 5, 1, 1], values(15, 3)), floats("wb", &[3, 5, 1, 1], values(15, 4))],
        &["y", "s"],
    );
    let (d, stats) = compare(gpu, &model, &[("x", vec![1, 5, 7, 9])]);
    eprintln!("concat: max |gpu - cpu| = {d:e}, {stats:?}");
    assert!(d <= 1e-5, "{d}");
    assert_eq!((stats.concat_in_place, stats.concat_copied), (2, 1));
}

#[test]
fn element_wise_shape_and_pooling_kernels_equal_the_reference() {
    let x4 = vec![2, 5, 13, 11];
    type Inputs = Vec<(&'static str, Vec<usize>)>;
    let cases: Vec<(&str, Model, Inputs)> = vec![
        (
            "add",
            graph(vec![node("Add", &["a", "b"], "y", &[])], vec![], &["y"]),
            vec![("a", vec![67_013]), ("b", vec![67_013])],
        ),
        (
            "mul",
            graph(vec![node("Mul", &["a", "b"], "y", &[])], vec![], &["y"]),
            vec![("a", x4.clone()), ("b", x4.clone())],
        ),
        ("sigmoid", graph(vec![node("Sigmoid", &["x"], "y", &[])], vec![], &["y"]), vec![("x", x4.clone())]),
        ("relu", graph(vec![node("Relu", &["x"], "y", &[])], vec![], &["y"]), vec![("x", x4.clone())]),
        (
            "slice (YOLOX's space-to-depth)",
            graph(
                vec![node("Slice", &["x", "st", "en", "ax", "sp"], "y", &[])],
                vec![
                    int64s("st", &[2], vec![1, 0]),
                    int64s("en", &[2], vec![i64::MAX, 9]),
                    int64s("ax", &[2], vec![2, 3]),
                    int64s("sp", &[2], vec![2, 2]),
                ],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "transpose",
            graph(vec![node("Transpose", &["x"], "y", &[("perm", ints(&[0, 2, 3, 1]))])], vec![], &["y"]),
            vec![("x", x4.clone())],
        ),
        (
            "gather (channel split)",
            graph(
                vec![node("Gather", &["x", "i"], "y", &[("axis", Attribute::Int(1))])],
                vec![int64s("i", &[], vec![3])],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "max pool (SPP 5/9/13)",
            graph(
                [5usize, 9, 13]
                    .iter()
                    .map(|&k| {
                        let p = k / 2;
                        node(
                            "MaxPool",
                            &["x"],
                            &format!("y{k}"),
                            &[
                                ("kernel_shape", ints(&[k, k])),
                                ("pads", ints(&[p, p, p, p])),
                                ("strides", ints(&[1, 1])),
                            ],
                        )
                    })
                    .collect(),
                vec![],
                &["y5", "y9", "y13"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "max pool stride 2",
            graph(
                vec![node("MaxPool", &["x"], "y", &[("kernel_shape", ints(&[3, 2])), ("strides", ints(&[2, 2]))])],
                vec![],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "average pool",
            graph(
                vec![node(
                    "AveragePool",
                    &["x"],
                    "y",
                    &[("kernel_shape", ints(&[3, 3])), ("pads", ints(&[1, 1, 1, 1])), ("strides", ints(&[2, 2]))],
                )],
                vec![],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "resize nearest x2",
            graph(
                vec![node(
                    "Resize",
                    &["x", "", "sc"],
                    "y",
                    &[
                        ("mode", text("nearest")),
                        ("coordinate_transformation_mode", text("asymmetric")),
                        ("nearest_mode", text("floor")),
                    ],
                )],
                vec![floats("sc", &[4], vec![1.0, 1.0, 2.0, 2.0])],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "pad",
            graph(
                vec![node("Pad", &["x", "p", "v"], "y", &[])],
                vec![int64s("p", &[8], vec![0, 1, 2, 0, 0, 0, 1, 3]), floats("v", &[], vec![0.25])],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "softmax over channels",
            graph(vec![node("Softmax", &["x"], "y", &[("axis", Attribute::Int(1))])], vec![], &["y"]),
            vec![("x", x4.clone())],
        ),
        (
            "reshape then softmax (last axis)",
            graph(
                vec![node("Reshape", &["x", "s"], "r", &[]), node("Softmax", &["r"], "y", &[])],
                vec![int64s("s", &[3], vec![2, -1, 11])],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
    ];
    for (name, model, inputs) in cases {
        let Some(gpu) = gpu(
            "gpu::kernels::element_wise_shape_and_pooling_kernels_equal_the_reference: GPU kernels vs the reference executor",
        ) else {
            return;
        };
        let (d, stats) = compare(gpu, &model, &inputs);
        eprintln!("{name}: max |gpu - cpu| = {d:e} ({} dispatches)", stats.dispatches);
        assert!(d <= 1e-6, "{name}: {d}");
    }
}

#[test]
fn the_segmenters_kernels_equal_the_reference_on_odd_shapes() {
    let x4 = vec![1, 5, 13, 11];
    let f = |v: f32| Attribute::Float(v);
    type Inputs = Vec<(&'static str, Vec<usize>)>;
    let resize = |ctm: &str, sizes: Vec<i64>| {
        graph(
            vec![node(
                "Resize",
                &["x", "", "", "sz"],
                "y",
                &[("mode", text("linear")), ("coordinate_transformation_mode", text(ctm))],
            )],
            vec![int64s("sz", &[4], sizes)],
            &["y"],
        )
    };
    let cases: Vec<(&str, Model, Inputs)> = vec![
        (
            "hard sigmoid",
            graph(vec![node("HardSigmoid", &["x"], "y", &[("alpha", f(0.3)), ("beta", f(0.4))])], vec![], &["y"]),
            vec![("x", x4.clone())],
        ),
        ("hard swish", graph(vec![node("HardSwish", &["x"], "y", &[])], vec![], &["y"]), vec![("x", x4.clone())]),
        (
            "clip (relu6)",
            graph(
                vec![node("Clip", &["x", "lo", "hi"], "y", &[])],
                vec![floats("lo", &[], vec![-0.2]), floats("hi", &[], vec![0.3])],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "sub",
            graph(vec![node("Sub", &["a", "b"], "y", &[])], vec![], &["y"]),
            vec![("a", x4.clone()), ("b", x4.clone())],
        ),
        (
            "div by a constant",
            graph(vec![node("Div", &["a", "k"], "y", &[])], vec![floats("k", &[1], vec![6.0])], &["y"]),
            vec![("a", x4.clone())],
        ),
        (
            "mul per channel (squeeze-excite)",
            graph(
                vec![node("GlobalAveragePool", &["a"], "g", &[]), node("Mul", &["a", "g"], "y", &[])],
                vec![],
                &["y"],
            ),
            vec![("a", x4.clone())],
        ),
        (
            "add a per-channel constant",
            graph(
                vec![node("Add", &["a", "k"], "y", &[])],
                vec![floats("k", &[1, 5, 1, 1], vec![0.5, -1.0, 2.0, 0.0, 3.0])],
                &["y"],
            ),
            vec![("a", x4.clone())],
        ),
        (
            "global average pool",
            graph(vec![node("GlobalAveragePool", &["x"], "y", &[])], vec![], &["y"]),
            vec![("x", vec![2, 3, 7, 9])],
        ),
        ("resize linear half_pixel 13x11 -> 29x16", resize("half_pixel", vec![1, 5, 29, 16]), vec![("x", x4.clone())]),
        ("resize linear half_pixel down 13x11 -> 5x4", resize("half_pixel", vec![1, 5, 5, 4]), vec![("x", x4.clone())]),
        (
            "resize linear align_corners 13x11 -> 31x23",
            resize("align_corners", vec![1, 5, 31, 23]),
            vec![("x", x4.clone())],
        ),
        ("resize linear from 1x1 (a broadcast)", resize("half_pixel", vec![1, 5, 9, 7]), vec![("x", vec![1, 5, 1, 1])]),
        ("resize linear pytorch_half_pixel", resize("pytorch_half_pixel", vec![1, 5, 20, 1]), vec![("x", x4.clone())]),
        (
            "conv transpose 2x2 stride 2 (MediaPipe's upsampler)",
            graph(
                vec![node("ConvTranspose", &["x", "w", "b"], "y", &[("strides", ints(&[2, 2]))])],
                vec![floats("w", &[5, 3, 2, 2], values(60, 7)), floats("b", &[3], vec![0.1, -0.2, 0.3])],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "conv transpose 3x3, pads, output padding, dilation, groups",
            graph(
                vec![node(
                    "ConvTranspose",
                    &["x", "w"],
                    "y",
                    &[
                        ("strides", ints(&[2, 3])),
                        ("pads", ints(&[1, 0, 2, 1])),
                        ("output_padding", ints(&[1, 2])),
                        ("dilations", ints(&[2, 1])),
                        ("group", Attribute::Int(2)),
                    ],
                )],
                vec![floats("w", &[6, 2, 3, 3], values(108, 9))],
                &["y"],
            ),
            vec![("x", vec![1, 6, 7, 5])],
        ),
        (
            "conv 1x1 on a 1x1 plane with bias (squeeze-excite)",
            graph(
                vec![node("Conv", &["x", "w", "b"], "y", &[])],
                vec![floats("w", &[8, 5, 1, 1], values(40, 13)), floats("b", &[8], values(8, 14))],
                &["y"],
            ),
            vec![("x", vec![1, 5, 1, 1])],
        ),
        (
            "conv whose weights and bias are Constant nodes' values (PP-HumanSeg's)",
            graph(
                vec![
                    node(
                        "Constant",
                        &[],
                        "w",
                        &[("value", Attribute::Tensor(floats("", &[4, 5, 3, 3], values(180, 15)).1))],
                    ),
                    node("Constant", &[], "b", &[("value", Attribute::Tensor(floats("", &[4], values(4, 16)).1))]),
                    node("Conv", &["x", "w", "b"], "y", &[("pads", ints(&[1, 1, 1, 1]))]),
                ],
                vec![],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
        (
            "conv SAME_UPPER stride 2",
            graph(
                vec![node("Conv", &["x", "w"], "y", &[("strides", ints(&[2, 2])), ("auto_pad", text("SAME_UPPER"))])],
                vec![floats("w", &[4, 5, 3, 3], values(180, 11))],
                &["y"],
            ),
            vec![("x", x4.clone())],
        ),
    ];
    for (name, model, inputs) in cases {
        let Some(gpu) = gpu(
            "gpu::kernels::the_segmenters_kernels_equal_the_reference_on_odd_shapes: GPU kernels vs the reference executor",
        ) else {
            return;
        };
        let (d, stats) = compare(gpu, &model, &inputs);
        eprintln!("{name}: max |gpu - cpu| = {d:e} ({} dispatches)", stats.dispatches);
        assert!(d <= 1e-5, "{name}: {d}");
    }
}

#[test]
fn shapes_the_plan_cannot_take_are_errors() {
    let shape =
        ConvShape { input: [1, 6, 4, 4], kernel: [4, 3, 3], stride: [1, 1], pads: [0; 4], dilation: [1, 1], group: 4 };
    assert!(shape.output().is_err(), "6 channels in 4 groups");
    let big =
        ConvShape { input: [1, 1, 2, 2], kernel: [1, 5, 5], stride: [1, 1], pads: [0; 4], dilation: [1, 1], group: 1 };
    assert!(big.output().is_err());
    let Some(g) = gpu("gpu::kernels::shapes_the_plan_cannot_take_are_errors: GPU kernels vs the reference executor")
    else {
        return;
    };
    // A 5x5 kernel on a 2x2 input: the plan fails at load with the node named.
    let conv = graph(
        vec![node("Conv", &["x", "w"], "y", &[("kernel_shape", ints(&[5, 5]))])],
        vec![floats("w", &[1, 1, 5, 5], values(25, 1))],
        &["y"],
    );
    let e = GpuModel::with_inputs(g, &conv, &[("x", vec![1, 1, 2, 2])]).unwrap_err().to_string();
    assert!(e.contains("Conv_y") && e.contains("larger"), "{e}");
    // Add with a broadcast other than one value or one per channel is not on the GPU: named.
    let Some(g) = gpu("gpu::kernels::shapes_the_plan_cannot_take_are_errors: GPU kernels vs the reference executor")
    else {
        return;
    };
    let add = graph(vec![node("Add", &["a", "b"], "y", &[])], vec![], &["y"]);
    let e = GpuModel::with_inputs(g, &add, &[("a", vec![2, 3]), ("b", vec![1, 3])]).unwrap_err().to_string();
    assert!(e.contains("Add_y") && e.contains("broadcast"), "{e}");
    // A run with another input shape than planned.
    let Some(g) = gpu("gpu::kernels::shapes_the_plan_cannot_take_are_errors: GPU kernels vs the reference executor")
    else {
        return;
    };
    let sig = graph(vec![node("Sigmoid", &["x"], "y", &[])], vec![], &["y"]);
    let m = GpuModel::with_inputs(g, &sig, &[("x", vec![4])]).unwrap();
    let e = m.run(&[("x", Tensor::F32 { shape: vec![5], data: vec![0.0; 5] })]).unwrap_err().to_string();
    assert!(e.contains("planned for"), "{e}");
    // An op with no kernel.
    let Some(g) = gpu("gpu::kernels::shapes_the_plan_cannot_take_are_errors: GPU kernels vs the reference executor")
    else {
        return;
    };
    let lrn = graph(vec![node("LRN", &["x"], "y", &[])], vec![], &["y"]);
    let e = GpuModel::with_inputs(g, &lrn, &[("x", vec![1, 2, 3, 3])]).unwrap_err().to_string();
    assert!(e.contains("LRN") && e.contains("LRN_y"), "{e}");
}
