//! Every kernel against `dynaflow-infer`'s reference executor on odd shapes, on whatever
//! adapter there is (Mesa's lavapipe in CI, which sets `DYNAFLOW_REQUIRE_GPU`).
#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::BTreeMap;

use dynaflow_gpu::{Activation, BinaryOp, Conv2d, ConvShape, Gpu};
use dynaflow_infer::cpu::{Tensor, run};
use dynaflow_infer::onnx::{Attribute, Model, Node, ValueInfo};

fn gpu() -> Option<Gpu> {
    match Gpu::new() {
        Ok(g) => {
            eprintln!("adapter: {}", g.adapter);
            Some(g)
        }
        Err(e) => {
            assert!(std::env::var_os("DYNAFLOW_REQUIRE_GPU").is_none(), "GPU required: {e}");
            eprintln!("note: {e}; skipping (CI runs it on lavapipe)");
            None
        }
    }
}

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

fn one_node(op: &str, inputs: &[&str], attributes: BTreeMap<String, Attribute>) -> Model {
    Model {
        ir_version: 7,
        opset: 11,
        producer: String::new(),
        nodes: vec![Node {
            name: "n".into(),
            op_type: op.into(),
            domain: String::new(),
            inputs: inputs.iter().map(|s| (*s).to_string()).collect(),
            outputs: vec!["y".into()],
            attributes,
        }],
        initializers: BTreeMap::new(),
        inputs: vec![],
        outputs: vec![ValueInfo { name: "y".into(), elem_type: 1, shape: vec![] }],
    }
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn conv2d_equals_the_reference_on_odd_shapes() {
    let Some(gpu) = gpu() else { return };
    let conv = Conv2d::new(&gpu);
    // (input, kernel m/kh/kw, stride, pads, dilation, group, activation): dense 3x3 stride 2,
    // depthwise 3x3, 1x1 pointwise, a 5x5 with dilation, odd sizes everywhere.
    let cases = [
        ([1, 6, 13, 11], [4, 3, 3], [2, 2], [1, 1, 1, 1], [1, 1], 2, Activation::Silu),
        ([1, 5, 9, 7], [5, 3, 3], [1, 1], [1, 1, 1, 1], [1, 1], 5, Activation::Identity),
        ([2, 7, 5, 9], [3, 1, 1], [1, 1], [0, 0, 0, 0], [1, 1], 1, Activation::Sigmoid),
        ([1, 3, 17, 15], [2, 5, 5], [1, 2], [2, 1, 2, 3], [2, 1], 1, Activation::Relu),
    ];
    for (k, (input, kernel, stride, pads, dilation, group, act)) in cases.into_iter().enumerate() {
        let shape = ConvShape { input, kernel, stride, pads, dilation, group };
        let (oh, ow) = shape.output().unwrap();
        let cg = input[1] / group;
        let x = values(input.iter().product(), 3 * k as u64 + 1);
        let w = values(kernel[0] * cg * kernel[1] * kernel[2], 3 * k as u64 + 2);
        let b = values(kernel[0], 3 * k as u64 + 3);
        let (bx, bw, bb) = (gpu.upload(&x), gpu.upload(&w), gpu.upload(&b));
        let n_out = input[0] * kernel[0] * oh * ow;
        let by = gpu.storage(n_out);
        conv.run(&gpu, &shape, &bx, &bw, &bb, &by, act).unwrap();
        let ours = gpu.download(&by, n_out).unwrap();

        let mut attrs = BTreeMap::new();
        attrs.insert("kernel_shape".into(), Attribute::Ints(vec![kernel[1] as i64, kernel[2] as i64]));
        attrs.insert("strides".into(), Attribute::Ints(stride.iter().map(|&v| v as i64).collect()));
        attrs.insert("pads".into(), Attribute::Ints(pads.iter().map(|&v| v as i64).collect()));
        attrs.insert("dilations".into(), Attribute::Ints(dilation.iter().map(|&v| v as i64).collect()));
        attrs.insert("group".into(), Attribute::Int(group as i64));
        let t = |shape: Vec<usize>, data: Vec<f32>| Tensor::F32 { shape, data };
        let r = run(
            &one_node("Conv", &["x", "w", "b"], attrs),
            &[
                ("x", t(input.to_vec(), x)),
                ("w", t(vec![kernel[0], cg, kernel[1], kernel[2]], w)),
                ("b", t(vec![kernel[0]], b)),
            ],
        )
        .unwrap();
        let mut want = r[0].floats();
        for v in &mut want {
            *v = match act {
                Activation::Identity => *v,
                Activation::Silu => *v / (1.0 + (-*v).exp()),
                Activation::Sigmoid => 1.0 / (1.0 + (-*v).exp()),
                Activation::Relu => v.max(0.0),
            };
        }
        let d = max_diff(&ours, &want);
        eprintln!("conv case {k} {input:?} -> {:?}: max |gpu - cpu| = {d:e}", [input[0], kernel[0], oh, ow]);
        assert!(d <= 1e-4, "case {k}: {d}");
    }
}

#[test]
fn binary_ops_equal_the_reference() {
    let Some(gpu) = gpu() else { return };
    let pipeline = BinaryOp::pipeline(&gpu);
    let n = 1000 * 67 + 13; // more than one row of workgroups' worth, not a multiple of 64
    let (a, b) = (values(n, 7), values(n, 8));
    for (op, name) in [(BinaryOp::Add, "Add"), (BinaryOp::Mul, "Mul")] {
        let (ba, bb, by) = (gpu.upload(&a), gpu.upload(&b), gpu.storage(n));
        op.run(&gpu, &pipeline, &ba, &bb, &by, n).unwrap();
        let ours = gpu.download(&by, n).unwrap();
        let t = |d: &Vec<f32>| Tensor::F32 { shape: vec![n], data: d.clone() };
        let want = run(&one_node(name, &["a", "b"], BTreeMap::new()), &[("a", t(&a)), ("b", t(&b))]).unwrap();
        assert_eq!(max_diff(&ours, &want[0].floats()), 0.0, "{name}");
    }
}

#[test]
fn bad_conv_shapes_are_errors() {
    let shape =
        ConvShape { input: [1, 6, 4, 4], kernel: [4, 3, 3], stride: [1, 1], pads: [0; 4], dilation: [1, 1], group: 4 };
    assert!(shape.output().is_err(), "6 channels in 4 groups");
    let big =
        ConvShape { input: [1, 1, 2, 2], kernel: [1, 5, 5], stride: [1, 1], pads: [0; 4], dilation: [1, 1], group: 1 };
    assert!(big.output().is_err());
}
