//! Tensors and the shape arithmetic every executor shares (the reference executor, the GPU
//! planner, the rten bridge).

use crate::Error;

use crate::onnx::TensorData;

/// A tensor: float data or integer data (shapes, indices), row-major.
#[derive(Clone, Debug, PartialEq)]
pub enum Tensor {
    /// Float tensor.
    F32 {
        /// Shape.
        shape: Vec<usize>,
        /// Values.
        data: Vec<f32>,
    },
    /// Integer tensor.
    I64 {
        /// Shape.
        shape: Vec<usize>,
        /// Values.
        data: Vec<i64>,
    },
}

impl Tensor {
    /// The shape.
    pub fn shape(&self) -> &[usize] {
        match self {
            Tensor::F32 { shape, .. } | Tensor::I64 { shape, .. } => shape,
        }
    }
    /// A tensor holding an initializer's or constant's values.
    pub fn from_data(t: &TensorData) -> Self {
        let shape = t.dims.iter().map(|&d| d as usize).collect();
        if t.floats.is_empty() && !t.ints.is_empty() {
            Tensor::I64 { shape, data: t.ints.clone() }
        } else {
            Tensor::F32 { shape, data: t.floats.clone() }
        }
    }
    /// Values as floats.
    pub fn floats(&self) -> Vec<f32> {
        match self {
            Tensor::F32 { data, .. } => data.clone(),
            Tensor::I64 { data, .. } => data.iter().map(|&v| v as f32).collect(),
        }
    }
    /// Values as integers.
    pub fn ints(&self) -> Vec<i64> {
        match self {
            Tensor::F32 { data, .. } => data.iter().map(|&v| v as i64).collect(),
            Tensor::I64 { data, .. } => data.clone(),
        }
    }
}

/// Row-major strides of `shape`.
pub fn strides(shape: &[usize]) -> Vec<usize> {
    let mut s = vec![1; shape.len()];
    for i in (0..shape.len().saturating_sub(1)).rev() {
        s[i] = s[i + 1] * shape[i + 1];
    }
    s
}

/// An ONNX axis (negative counts from the end) as an index, checked against `rank`.
pub fn norm_axis(a: i64, rank: usize) -> Result<usize, Error> {
    let r = rank as i64;
    let v = if a < 0 { a + r } else { a };
    if (0..r).contains(&v) {
        Ok(v as usize)
    } else {
        Err(Error::Shape(format!("axis {a} out of range for rank {rank}")))
    }
}
/// The output shape of ONNX `Reshape` of `input` to `spec` (`0` copies a dimension, `-1`
/// takes what is left).
pub fn reshape_shape(input: &[usize], spec: &[i64]) -> Result<Vec<usize>, Error> {
    reshape_shape_msg(input, spec).map_err(Error::Shape)
}

fn reshape_shape_msg(input: &[usize], spec: &[i64]) -> Result<Vec<usize>, String> {
    let total: usize = input.iter().product();
    let mut shape: Vec<usize> = Vec::new();
    let mut infer = None;
    for (i, &d) in spec.iter().enumerate() {
        match d {
            0 => shape.push(*input.get(i).ok_or("0 in shape beyond the input's rank")?),
            -1 => {
                infer = Some(i);
                shape.push(1);
            }
            d if d > 0 => shape.push(d as usize),
            d => return Err(format!("bad dimension {d} in shape")),
        }
    }
    if let Some(i) = infer {
        let known: usize = shape.iter().product();
        if known == 0 || !total.is_multiple_of(known) {
            return Err(format!("cannot reshape {input:?} to {spec:?}"));
        }
        shape[i] = total / known;
    }
    if shape.iter().product::<usize>() != total {
        return Err(format!("cannot reshape {input:?} to {spec:?}"));
    }
    Ok(shape)
}
