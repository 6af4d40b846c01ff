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

/// An image's pixels as RGB8: colour as it is, grey replicated into three channels (the
/// networks take RGB).
pub(crate) fn rgb_pixels(img: &dynaflow_engine::msg::Image) -> std::borrow::Cow<'_, [u8]> {
    match img.format {
        dynaflow_engine::msg::PixelFormat::Rgb8 => std::borrow::Cow::Borrowed(&img.data),
        dynaflow_engine::msg::PixelFormat::Gray8 => {
            std::borrow::Cow::Owned(img.data.iter().flat_map(|&v| [v, v, v]).collect())
        }
    }
}
