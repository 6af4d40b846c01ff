//! Messages to Python and back.
//!
//! To Python: `image` is a read-only `uint8` array `(H, W, 3)` (RGB) or `(H, W)` (grey) and
//! `depth` a read-only `float32` `(H, W)` in metres, both views of the message itself (no copy:
//! the array keeps the message alive); `mask` is a dict with `classes` (a read-only `uint16`
//! view `(H, W)`), `instances` (a copy, or `None`) and `class_names`; `camera_info` a dict
//! (`width`, `height`, `fx`, `fy`, `cx`, `cy`, `distortion`, `model`); `keypoints` a dict of
//! arrays (`xy` `(N, 2)`, `size`, `angle`, `response` `float32`, `octave` `uint8`,
//! `descriptors` `(N, B)` `uint8` or `None`); `tracks` a dict (`prev_seq`, `id` `uint64`,
//! `prev` and `cur` `(N, 2)` `float32`, `error` `float32`); `point_labels` a dict (`index`
//! `uint32`, `dynamic` `bool`, `reason` `uint8` codes into `REASONS`, `score` `float32`, `at`
//! `(N, 2)` `float32`); `pose` the `(4, 4)` `float64` `world_from_cam`; `scalars` a dict of
//! name to float. Back from Python the same shapes, checked: a wrong dtype, shape, missing
//! field or value out of range is an error naming the port and the field.

// The one unsafe block of the workspace's Python seam: a read-only buffer over a message's
// pixels, so numpy reads the image without copying it (see `View`).
#![allow(unsafe_code)]

use std::ffi::{CStr, c_char, c_int, c_void};
use std::sync::Arc;

use dynaflow_engine::msg::{
    Body, CameraInfo, DepthImage, Descriptors, Image, Keypoint, Keypoints, LabelReason, LensModel, Message,
    PixelFormat, PointLabel, PointLabels, PortType, Pose, Scalars, SegmentationMask, Track, Tracks,
};
use pyo3::buffer::{Element, PyBuffer};
use pyo3::exceptions::PyBufferError;
use pyo3::ffi;
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyDict};

/// The port types Python operators take and emit.
pub(crate) const SUPPORTED: &[PortType] = &[
    PortType::Image,
    PortType::Depth,
    PortType::Mask,
    PortType::CameraInfo,
    PortType::Keypoints,
    PortType::Tracks,
    PortType::PointLabels,
    PortType::Pose,
    PortType::Scalars,
];

/// `point_labels`' reason codes, in the message's order.
pub(crate) const REASONS: [&str; 5] = ["static", "epipolar", "semantic", "flow", "depth"];

fn reason_code(r: LabelReason) -> u8 {
    match r {
        LabelReason::Static => 0,
        LabelReason::Epipolar => 1,
        LabelReason::Semantic => 2,
        LabelReason::Flow => 3,
        LabelReason::Depth => 4,
        // A reason added to the vocabulary after this table: outside `REASONS`.
        _ => u8::MAX,
    }
}

fn reason_of(code: u8) -> Option<LabelReason> {
    Some(match code {
        0 => LabelReason::Static,
        1 => LabelReason::Epipolar,
        2 => LabelReason::Semantic,
        3 => LabelReason::Flow,
        4 => LabelReason::Depth,
        _ => return None,
    })
}

/// A read-only buffer over the pixels of a message, which it keeps alive: what numpy's
/// `asarray` wraps without copying.
#[pyclass(frozen)]
struct View {
    /// Owns the pixels `ptr` points into (never mutated while shared).
    _msg: Arc<Message>,
    ptr: usize,
    len: usize,
    itemsize: isize,
    format: &'static CStr,
    ndim: usize,
    shape: [isize; 3],
    strides: [isize; 3],
}

impl View {
    /// A C-contiguous view of `data` (inside `msg`'s body) with `shape`.
    fn new<T>(msg: &Arc<Message>, data: &[T], format: &'static CStr, shape: &[usize]) -> Self {
        let itemsize = std::mem::size_of::<T>() as isize;
        let mut s = [0isize; 3];
        let mut st = [0isize; 3];
        let mut stride = itemsize;
        for i in (0..shape.len()).rev() {
            s[i] = shape[i] as isize;
            st[i] = stride;
            stride *= shape[i] as isize;
        }
        Self {
            _msg: Arc::clone(msg),
            ptr: data.as_ptr() as usize,
            len: std::mem::size_of_val(data),
            itemsize,
            format,
            ndim: shape.len(),
            shape: s,
            strides: st,
        }
    }
}

#[pymethods]
impl View {
    /// The buffer protocol: a read-only, C-contiguous view (a writable request is refused).
    ///
    /// # Safety
    /// Python calls it with a valid `Py_buffer`; the pointers handed out stay valid while
    /// `view.obj` (a reference to this object, which owns the message) is held.
    #[allow(clippy::needless_pass_by_value)] // PyO3's signature for the buffer protocol
    unsafe fn __getbuffer__(slf: Bound<'_, Self>, view: *mut ffi::Py_buffer, flags: c_int) -> PyResult<()> {
        if view.is_null() {
            return Err(PyBufferError::new_err("no view to fill"));
        }
        if flags & ffi::PyBUF_WRITABLE == ffi::PyBUF_WRITABLE {
            return Err(PyBufferError::new_err("a dynaflow message is read-only (copy it to change it)"));
        }
        let this = slf.get();
        // SAFETY: `view` is non-null and Python's to fill; the buffer, shape and strides live
        // in `this` (and the message it holds), which `obj` keeps alive until release.
        unsafe {
            (*view).obj = slf.clone().into_any().into_ptr();
            (*view).buf = this.ptr as *mut c_void;
            (*view).len = this.len as isize;
            (*view).readonly = 1;
            (*view).itemsize = this.itemsize;
            (*view).format = if flags & ffi::PyBUF_FORMAT == ffi::PyBUF_FORMAT {
                this.format.as_ptr().cast_mut()
            } else {
                std::ptr::null_mut::<c_char>()
            };
            (*view).ndim = this.ndim as c_int;
            (*view).shape = if flags & ffi::PyBUF_ND == ffi::PyBUF_ND {
                this.shape.as_ptr().cast_mut()
            } else {
                std::ptr::null_mut()
            };
            (*view).strides = if flags & ffi::PyBUF_STRIDES == ffi::PyBUF_STRIDES {
                this.strides.as_ptr().cast_mut()
            } else {
                std::ptr::null_mut()
            };
            (*view).suboffsets = std::ptr::null_mut();
            (*view).internal = std::ptr::null_mut();
        }
        Ok(())
    }

    /// Nothing to release: the view borrows the message `obj` holds.
    ///
    /// # Safety
    /// Called by Python with the view it was given.
    unsafe fn __releasebuffer__(&self, _view: *mut ffi::Py_buffer) {}
}

/// A writable numpy array of `data` (copied) with `shape`.
fn array<'py, T: Copy>(
    np: &Bound<'py, PyModule>,
    data: &[T],
    bytes: impl Fn(T) -> Vec<u8>,
    dtype: &str,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    let raw: Vec<u8> = data.iter().flat_map(|&v| bytes(v)).collect();
    let buf = PyByteArray::new(np.py(), &raw);
    np.call_method1("frombuffer", (buf, dtype))?.call_method1("reshape", (shape.to_vec(),))
}

fn f32s<'py>(np: &Bound<'py, PyModule>, v: &[f32], shape: &[usize]) -> PyResult<Bound<'py, PyAny>> {
    array(np, v, |x| x.to_ne_bytes().to_vec(), "float32", shape)
}

/// A message as the Python object its port type reaches Python as (module doc).
pub(crate) fn to_py<'py>(np: &Bound<'py, PyModule>, msg: &Arc<Message>) -> PyResult<Bound<'py, PyAny>> {
    let py = np.py();
    let view = |v: View| -> PyResult<Bound<'py, PyAny>> { np.call_method1("asarray", (Bound::new(py, v)?,)) };
    let d = PyDict::new(py);
    match &msg.body {
        Body::Image(img) => {
            let (h, w) = (img.height as usize, img.width as usize);
            let shape: &[usize] = match img.format {
                PixelFormat::Rgb8 => &[h, w, 3],
                PixelFormat::Gray8 => &[h, w],
            };
            view(View::new(msg, &img.data, c"B", shape))
        }
        Body::Depth(depth) => view(View::new(msg, &depth.data, c"f", &[depth.height as usize, depth.width as usize])),
        Body::Mask(m) => {
            let shape = [m.height as usize, m.width as usize];
            d.set_item("classes", view(View::new(msg, &m.classes, c"H", &shape))?)?;
            match &m.instances {
                Some(i) => d.set_item("instances", array(np, i, |x| x.to_ne_bytes().to_vec(), "uint16", &shape)?)?,
                None => d.set_item("instances", py.None())?,
            }
            d.set_item("class_names", m.class_names.iter().map(|n| n.to_string()).collect::<Vec<_>>())?;
            Ok(d.into_any())
        }
        Body::CameraInfo(k) => {
            d.set_item("width", k.width)?;
            d.set_item("height", k.height)?;
            for (key, v) in [("fx", k.fx), ("fy", k.fy), ("cx", k.cx), ("cy", k.cy)] {
                d.set_item(key, v)?;
            }
            d.set_item("distortion", k.distortion.to_vec())?;
            d.set_item("model", if k.model == LensModel::KannalaBrandt { "kannala_brandt" } else { "brown_conrady" })?;
            Ok(d.into_any())
        }
        Body::Keypoints(k) => {
            let n = k.points.len();
            let xy: Vec<f32> = k.points.iter().flat_map(|p| [p.x, p.y]).collect();
            d.set_item("xy", f32s(np, &xy, &[n, 2])?)?;
            for (key, f) in [
                ("size", (|p: &Keypoint| p.size) as fn(&Keypoint) -> f32),
                ("angle", |p| p.angle),
                ("response", |p| p.response),
            ] {
                d.set_item(key, f32s(np, &k.points.iter().map(f).collect::<Vec<_>>(), &[n])?)?;
            }
            let octave: Vec<u8> = k.points.iter().map(|p| p.octave).collect();
            d.set_item("octave", array(np, &octave, |x| vec![x], "uint8", &[n])?)?;
            match &k.descriptors {
                Some(desc) => {
                    d.set_item("descriptors", array(np, &desc.data, |x| vec![x], "uint8", &[n, desc.bytes_per])?)?
                }
                None => d.set_item("descriptors", py.None())?,
            }
            Ok(d.into_any())
        }
        Body::Tracks(t) => {
            let n = t.tracks.len();
            d.set_item("prev_seq", t.prev_seq)?;
            let ids: Vec<u64> = t.tracks.iter().map(|t| t.id).collect();
            d.set_item("id", array(np, &ids, |x| x.to_ne_bytes().to_vec(), "uint64", &[n])?)?;
            let prev: Vec<f32> = t.tracks.iter().flat_map(|t| t.prev).collect();
            let cur: Vec<f32> = t.tracks.iter().flat_map(|t| t.cur).collect();
            d.set_item("prev", f32s(np, &prev, &[n, 2])?)?;
            d.set_item("cur", f32s(np, &cur, &[n, 2])?)?;
            d.set_item("error", f32s(np, &t.tracks.iter().map(|t| t.error).collect::<Vec<_>>(), &[n])?)?;
            Ok(d.into_any())
        }
        Body::PointLabels(l) => {
            let n = l.labels.len();
            let index: Vec<u32> = l.labels.iter().map(|l| l.index).collect();
            d.set_item("index", array(np, &index, |x| x.to_ne_bytes().to_vec(), "uint32", &[n])?)?;
            let dynamic: Vec<u8> = l.labels.iter().map(|l| u8::from(l.dynamic)).collect();
            d.set_item("dynamic", array(np, &dynamic, |x| vec![x], "bool", &[n])?)?;
            let reason: Vec<u8> = l.labels.iter().map(|l| reason_code(l.reason)).collect();
            d.set_item("reason", array(np, &reason, |x| vec![x], "uint8", &[n])?)?;
            d.set_item("score", f32s(np, &l.labels.iter().map(|l| l.score).collect::<Vec<_>>(), &[n])?)?;
            d.set_item("at", f32s(np, &l.labels.iter().flat_map(|l| l.at).collect::<Vec<_>>(), &[n, 2])?)?;
            Ok(d.into_any())
        }
        Body::Pose(p) => {
            let m = p.world_from_cam.to_homogeneous();
            let rows: Vec<f64> = (0..4).flat_map(|r| (0..4).map(move |c| m[(r, c)])).collect();
            array(np, &rows, |x| x.to_ne_bytes().to_vec(), "float64", &[4, 4])
        }
        Body::Scalars(s) => {
            for (k, v) in &s.values {
                d.set_item(k.as_ref(), *v)?;
            }
            Ok(d.into_any())
        }
        other => Err(pyo3::exceptions::PyTypeError::new_err(format!(
            "a `{}` message does not reach Python operators",
            other.port_type().name()
        ))),
    }
}

/// What a value is, for errors: a numpy array's dtype and shape, else its Python type.
fn describe(v: &Bound<'_, PyAny>) -> String {
    match (v.getattr("dtype"), v.getattr("shape")) {
        (Ok(dt), Ok(shape)) => format!("a {dt} array of shape {shape}"),
        _ => format!("a {}", v.get_type().name().map_or_else(|_| "value".into(), |n| n.to_string())),
    }
}

/// The contents and shape of a numpy array (any strides) of element type `T` (`dtype` for
/// the error).
fn read<T: Element + Copy>(v: &Bound<'_, PyAny>, what: &str, dtype: &str) -> Result<(Vec<T>, Vec<usize>), String> {
    let buf =
        PyBuffer::<T>::get(v).map_err(|_| format!("{what}: expected a {dtype} numpy array, got {}", describe(v)))?;
    let data = buf.to_vec(v.py()).map_err(|e| format!("{what}: {e}"))?;
    Ok((data, buf.shape().to_vec()))
}

/// [`read`] with the shape checked: `n` rows (any when `None`) of `cols` (`None`: a vector).
fn read_rows<T: Element + Copy>(
    v: &Bound<'_, PyAny>,
    what: &str,
    dtype: &str,
    n: Option<usize>,
    cols: Option<usize>,
) -> Result<Vec<T>, String> {
    let (data, shape) = read::<T>(v, what, dtype)?;
    let ok = match cols {
        None => shape.len() == 1,
        Some(c) => shape.len() == 2 && shape[1] == c,
    } && n.is_none_or(|n| shape.first() == Some(&n));
    if !ok {
        let want = match (n, cols) {
            (Some(n), Some(c)) => format!("({n}, {c})"),
            (None, Some(c)) => format!("(N, {c})"),
            (Some(n), None) => format!("({n},)"),
            (None, None) => "(N,)".into(),
        };
        return Err(format!("{what}: expected shape {want}, got {shape:?}"));
    }
    Ok(data)
}

/// A numpy `bool` vector (read through its bytes: numpy's bools are one byte, 0 or 1).
fn bools(v: &Bound<'_, PyAny>, what: &str) -> Result<Vec<bool>, String> {
    let is_bool =
        v.getattr("dtype").and_then(|d| d.getattr("kind")).and_then(|k| k.extract::<String>()).is_ok_and(|k| k == "b");
    if !is_bool {
        return Err(format!("{what}: expected a bool numpy array, got {}", describe(v)));
    }
    let bytes = v.call_method1("view", ("uint8",)).map_err(|e| format!("{what}: {e}"))?;
    Ok(read_rows::<u8>(&bytes, what, "bool", None, None)?.into_iter().map(|b| b != 0).collect())
}

/// The dict's `key`, unless absent or `None` (an optional field left out).
fn optional<'py>(d: &Bound<'py, PyDict>, key: &str) -> Option<Bound<'py, PyAny>> {
    d.get_item(key).ok().flatten().filter(|x| !x.is_none())
}

fn field<'py>(d: &Bound<'py, PyDict>, port: &str, key: &str) -> Result<Bound<'py, PyAny>, String> {
    d.get_item(key).ok().flatten().ok_or_else(|| format!("`{port}`: the dict has no `{key}` field"))
}

fn dict<'a, 'py>(v: &'a Bound<'py, PyAny>, port: &str, ty: &str) -> Result<&'a Bound<'py, PyDict>, String> {
    v.cast::<PyDict>().map_err(|_| format!("`{port}`: a `{ty}` is returned as a dict, got {}", describe(v)))
}

fn number<T: for<'a, 'py> FromPyObject<'a, 'py>>(
    d: &Bound<'_, PyDict>,
    port: &str,
    key: &str,
    what: &str,
) -> Result<T, String> {
    field(d, port, key)?.extract::<T>().map_err(|_| format!("`{port}`.{key}: expected {what}"))
}

/// A value returned on a port of type `ty`, checked and made a message body.
pub(crate) fn from_py(ty: PortType, port: &str, v: &Bound<'_, PyAny>) -> Result<Body, String> {
    Ok(match ty {
        PortType::Image => {
            let (data, shape) = read::<u8>(v, &format!("`{port}`"), "uint8")?;
            let format = match shape.as_slice() {
                [_, _, 3] => PixelFormat::Rgb8,
                [_, _] => PixelFormat::Gray8,
                _ => return Err(format!("`{port}`: expected shape (H, W, 3) or (H, W), got {shape:?}")),
            };
            let (height, width) = dims(port, shape[0], shape[1])?;
            Body::Image(Image { width, height, format, data })
        }
        PortType::Depth => {
            let (data, shape) = read::<f32>(v, &format!("`{port}`"), "float32")?;
            let [h, w] = shape.as_slice() else {
                return Err(format!("`{port}`: expected shape (H, W), got {shape:?}"));
            };
            if let Some(bad) = data.iter().find(|z| !(z.is_finite() && **z >= 0.0)) {
                return Err(format!("`{port}`: depth {bad}: metres, finite and >= 0 (0 = no measurement)"));
            }
            let (height, width) = dims(port, *h, *w)?;
            Body::Depth(DepthImage { width, height, data })
        }
        PortType::Mask => {
            let d = dict(v, port, "mask")?;
            let (classes, shape) = read::<u16>(&field(d, port, "classes")?, &format!("`{port}`.classes"), "uint16")?;
            let [h, w] = shape.as_slice() else {
                return Err(format!("`{port}`.classes: expected shape (H, W), got {shape:?}"));
            };
            let instances = match optional(d, "instances") {
                Some(i) => {
                    let (data, s) = read::<u16>(&i, &format!("`{port}`.instances"), "uint16")?;
                    if s != shape {
                        return Err(format!("`{port}`.instances: shape {s:?}, but `classes` is {shape:?}"));
                    }
                    Some(data)
                }
                None => None,
            };
            let names: Vec<String> = match d.get_item("class_names").ok().flatten() {
                Some(n) => n.extract().map_err(|_| format!("`{port}`.class_names: expected a list of str"))?,
                None => Vec::new(),
            };
            if let Some(c) = classes.iter().find(|&&c| usize::from(c) >= names.len().max(1) && !names.is_empty()) {
                return Err(format!("`{port}`.classes: class {c}, but `class_names` has {}", names.len()));
            }
            let (height, width) = dims(port, *h, *w)?;
            Body::Mask(SegmentationMask {
                width,
                height,
                classes,
                instances,
                class_names: names.into_iter().map(Arc::from).collect(),
            })
        }
        PortType::CameraInfo => {
            let d = dict(v, port, "camera_info")?;
            let width: u32 = number(d, port, "width", "a positive int")?;
            let height: u32 = number(d, port, "height", "a positive int")?;
            let [fx, fy, cx, cy] = ["fx", "fy", "cx", "cy"].map(|k| number::<f64>(d, port, k, "a number"));
            let (fx, fy, cx, cy) = (fx?, fy?, cx?, cy?);
            if !(fx > 0.0 && fy > 0.0 && fx.is_finite() && fy.is_finite() && cx.is_finite() && cy.is_finite()) {
                return Err(format!("`{port}`: focal lengths must be positive and everything finite"));
            }
            let distortion: Vec<f64> = match d.get_item("distortion").ok().flatten() {
                Some(x) => x.extract().map_err(|_| format!("`{port}`.distortion: expected up to 5 numbers"))?,
                None => Vec::new(),
            };
            if distortion.len() > 5 {
                return Err(format!("`{port}`.distortion: {} coefficients, at most 5", distortion.len()));
            }
            let mut dist = [0.0; 5];
            dist[..distortion.len()].copy_from_slice(&distortion);
            let model = match d.get_item("model").ok().flatten().map(|m| m.extract::<String>()) {
                None => LensModel::BrownConrady,
                Some(Ok(m)) if m == "brown_conrady" => LensModel::BrownConrady,
                Some(Ok(m)) if m == "kannala_brandt" => LensModel::KannalaBrandt,
                Some(_) => return Err(format!("`{port}`.model: `brown_conrady` or `kannala_brandt`")),
            };
            Body::CameraInfo(CameraInfo { width, height, fx, fy, cx, cy, distortion: dist, model })
        }
        PortType::Keypoints => {
            let d = dict(v, port, "keypoints")?;
            let w = |k: &str| format!("`{port}`.{k}");
            let xy = read_rows::<f32>(&field(d, port, "xy")?, &w("xy"), "float32", None, Some(2))?;
            let n = xy.len() / 2;
            let opt = |k: &str, default: f32| -> Result<Vec<f32>, String> {
                match optional(d, k) {
                    Some(x) => read_rows::<f32>(&x, &w(k), "float32", Some(n), None),
                    None => Ok(vec![default; n]),
                }
            };
            let (size, angle, response) = (opt("size", 31.0)?, opt("angle", -1.0)?, opt("response", 0.0)?);
            let octave = match optional(d, "octave") {
                Some(x) => read_rows::<u8>(&x, &w("octave"), "uint8", Some(n), None)?,
                None => vec![0; n],
            };
            let descriptors = match optional(d, "descriptors") {
                Some(x) => {
                    let (data, shape) = read::<u8>(&x, &w("descriptors"), "uint8")?;
                    if shape.len() != 2 || shape[0] != n {
                        return Err(format!("{}: expected shape ({n}, B), got {shape:?}", w("descriptors")));
                    }
                    Some(Descriptors { bytes_per: shape[1], data })
                }
                None => None,
            };
            let points = (0..n)
                .map(|i| Keypoint {
                    x: xy[2 * i],
                    y: xy[2 * i + 1],
                    size: size[i],
                    angle: angle[i],
                    response: response[i],
                    octave: octave[i],
                })
                .collect();
            Body::Keypoints(Keypoints { points, descriptors })
        }
        PortType::Tracks => {
            let d = dict(v, port, "tracks")?;
            let w = |k: &str| format!("`{port}`.{k}");
            let prev_seq: u64 = number(d, port, "prev_seq", "a frame number (int >= 0)")?;
            let ids = read_rows::<u64>(&field(d, port, "id")?, &w("id"), "uint64", None, None)?;
            let n = ids.len();
            let prev = read_rows::<f32>(&field(d, port, "prev")?, &w("prev"), "float32", Some(n), Some(2))?;
            let cur = read_rows::<f32>(&field(d, port, "cur")?, &w("cur"), "float32", Some(n), Some(2))?;
            let error = match optional(d, "error") {
                Some(x) => read_rows::<f32>(&x, &w("error"), "float32", Some(n), None)?,
                None => vec![0.0; n],
            };
            let tracks = (0..n)
                .map(|i| Track {
                    id: ids[i],
                    prev: [prev[2 * i], prev[2 * i + 1]],
                    cur: [cur[2 * i], cur[2 * i + 1]],
                    error: error[i],
                })
                .collect();
            Body::Tracks(Tracks { prev_seq, tracks })
        }
        PortType::PointLabels => {
            let d = dict(v, port, "point_labels")?;
            let w = |k: &str| format!("`{port}`.{k}");
            let dynamic = bools(&field(d, port, "dynamic")?, &w("dynamic"))?;
            let n = dynamic.len();
            let index = match optional(d, "index") {
                Some(x) => read_rows::<u32>(&x, &w("index"), "uint32", Some(n), None)?,
                None => (0..n as u32).collect(),
            };
            let reason = read_rows::<u8>(&field(d, port, "reason")?, &w("reason"), "uint8", Some(n), None)?;
            let reason = reason
                .iter()
                .map(|&c| {
                    reason_of(c)
                        .ok_or_else(|| format!("{}: code {c}, not one of 0..=4 ({})", w("reason"), REASONS.join(", ")))
                })
                .collect::<Result<Vec<_>, _>>()?;
            let score = read_rows::<f32>(&field(d, port, "score")?, &w("score"), "float32", Some(n), None)?;
            let at = match optional(d, "at") {
                Some(x) => read_rows::<f32>(&x, &w("at"), "float32", Some(n), Some(2))?,
                None => vec![f32::NAN; 2 * n],
            };
            let labels = (0..n)
                .map(|i| PointLabel {
                    index: index[i],
                    dynamic: dynamic[i],
                    reason: reason[i],
                    score: score[i],
                    at: [at[2 * i], at[2 * i + 1]],
                })
                .collect();
            Body::PointLabels(PointLabels { labels })
        }
        PortType::Pose => {
            let m = read_rows::<f64>(v, &format!("`{port}`"), "float64", Some(4), Some(4))?;
            let m = nalgebra::Matrix4::from_row_slice(&m);
            let r = m.fixed_view::<3, 3>(0, 0).into_owned();
            let orthonormal =
                (r.transpose() * r - nalgebra::Matrix3::identity()).amax() < 1e-6 && r.determinant() > 0.0;
            let last_row = (m.fixed_view::<1, 4>(3, 0) - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0)).amax() < 1e-12;
            if !(orthonormal && last_row && m.iter().all(|x| x.is_finite())) {
                return Err(format!(
                    "`{port}`: not a rigid transform (the rotation must be orthonormal to 1e-6 with determinant 1, the last row 0 0 0 1)"
                ));
            }
            let rotation =
                nalgebra::UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r));
            let translation = nalgebra::Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
            Body::Pose(Pose { world_from_cam: nalgebra::Isometry3::from_parts(translation, rotation) })
        }
        PortType::Scalars => {
            let d = dict(v, port, "scalars")?;
            let values = d
                .iter()
                .map(|(k, x)| {
                    let k: String = k.extract().map_err(|_| format!("`{port}`: a key that is not a str"))?;
                    let x: f64 =
                        x.extract().map_err(|_| format!("`{port}`.{k}: expected a number, got {}", describe(&x)))?;
                    Ok((Arc::from(k.as_str()), x))
                })
                .collect::<Result<Vec<_>, String>>()?;
            Body::Scalars(Scalars { values })
        }
        other => return Err(format!("`{port}`: `{}` does not come from Python operators", other.name())),
    })
}

/// Image dimensions as the message's `u32`s.
fn dims(port: &str, h: usize, w: usize) -> Result<(u32, u32), String> {
    match (u32::try_from(h), u32::try_from(w)) {
        (Ok(h), Ok(w)) if h > 0 && w > 0 => Ok((h, w)),
        _ => Err(format!("`{port}`: an image of {h} x {w}")),
    }
}
