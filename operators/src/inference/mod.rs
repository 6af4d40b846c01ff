//! Neural-network inference, a thin wrapper over `dynaflow-infer`: `detect` (an ONNX
//! detector: YOLOX or FastestDet decoding, class-wise NMS).

mod detect;

pub use detect::DETECT;
