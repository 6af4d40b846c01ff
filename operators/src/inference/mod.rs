//! Neural-network inference, a thin wrapper over `dynaflow-infer`: `detect` (an ONNX
//! detector: YOLOX or FastestDet decoding, class-wise NMS) and `box_to_mask` (boxes and depth
//! to a mask, so mask-based culling runs with a detector), `segment` (an ONNX segmenter: class
//! per pixel, dilation, instances), `keyframe_gate` (MG-SLAM's key
//! segmentation frames: which frames go to inference).

mod box_mask;
mod classes;
mod detect;
mod gate;
mod runner;
mod segment;

pub use box_mask::BOX_TO_MASK;
pub use classes::{COCO80, ClassName, KNOWN_CLASSES, class_list};
pub use detect::{COCO_NAMES, DETECT, DecoderName, YOLOX_NANO};
pub use gate::KEYFRAME_GATE;
pub use runner::{Backend, Runner};
pub use segment::{InputRange, PP_HUMANSEG, SEGMENT, load as load_segmenter, segment_frame};
