//! Class names a graph may name: those of the label sets the shipped models and the seed
//! papers use (COCO-80 for the detectors, PASCAL VOC for PSPNet-SLAM's segmenter), so a
//! misspelt class is an error when the graph is built, not a culling step that never fires.

use dynaflow_engine::op::{Param, ParamType, Params};

/// COCO-80's class names in the vendored detectors' order (index 0 = person): the lines of
/// `models/yolox_nano/coco.names` (a test keeps the two equal).
pub const COCO80: [&str; 80] = [
    "person",
    "bicycle",
    "car",
    "motorbike",
    "aeroplane",
    "bus",
    "train",
    "truck",
    "boat",
    "traffic light",
    "fire hydrant",
    "stop sign",
    "parking meter",
    "bench",
    "bird",
    "cat",
    "dog",
    "horse",
    "sheep",
    "cow",
    "elephant",
    "bear",
    "zebra",
    "giraffe",
    "backpack",
    "umbrella",
    "handbag",
    "tie",
    "suitcase",
    "frisbee",
    "skis",
    "snowboard",
    "sports ball",
    "kite",
    "baseball bat",
    "baseball glove",
    "skateboard",
    "surfboard",
    "tennis racket",
    "bottle",
    "wine glass",
    "cup",
    "fork",
    "knife",
    "spoon",
    "bowl",
    "banana",
    "apple",
    "sandwich",
    "orange",
    "broccoli",
    "carrot",
    "hot dog",
    "pizza",
    "donut",
    "cake",
    "chair",
    "sofa",
    "pottedplant",
    "bed",
    "diningtable",
    "toilet",
    "tvmonitor",
    "laptop",
    "mouse",
    "remote",
    "keyboard",
    "cell phone",
    "microwave",
    "oven",
    "toaster",
    "sink",
    "refrigerator",
    "book",
    "clock",
    "vase",
    "scissors",
    "teddy bear",
    "hair drier",
    "toothbrush",
];

/// PASCAL VOC's 20 object classes (the segmenters' label set besides `background`).
const VOC_NAMES: &[&str] = &[
    "aeroplane",
    "bicycle",
    "bird",
    "boat",
    "bottle",
    "bus",
    "car",
    "cat",
    "chair",
    "cow",
    "diningtable",
    "dog",
    "horse",
    "motorbike",
    "person",
    "pottedplant",
    "sheep",
    "sofa",
    "train",
    "tvmonitor",
];

/// Every name a graph may give a class: COCO-80's, then PASCAL VOC's (which repeat some).
pub const KNOWN_CLASSES: [&str; 100] = {
    let mut all = [""; 100];
    let mut i = 0;
    while i < 80 {
        all[i] = COCO80[i];
        i += 1;
    }
    while i < 100 {
        all[i] = VOC_NAMES[i - 80];
        i += 1;
    }
    all
};

/// A class name of the COCO-80 (detectors) or PASCAL VOC (segmenters) label sets, checked
/// where the graph names it (a misspelt class is a located error, not a culling step that
/// never fires).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct ClassName(pub String);

impl ClassName {
    /// The name.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl Param for ClassName {
    const TYPE: ParamType = ParamType::Enum { values: &KNOWN_CLASSES };
    fn from_json(value: &serde_json::Value, _: &Params) -> Result<Self, String> {
        match value.as_str() {
            Some(s) if KNOWN_CLASSES.contains(&s) => Ok(ClassName(s.to_owned())),
            _ => Err(format!("{value} is no class of the COCO-80 (detectors) or PASCAL VOC (segmenters) label sets")),
        }
    }
    fn to_json(&self) -> serde_json::Value {
        serde_json::Value::String(self.0.clone())
    }
}

/// Class names as a list parameter's default.
pub fn class_list(names: &[&str]) -> Vec<ClassName> {
    names.iter().map(|n| ClassName((*n).to_owned())).collect()
}

#[cfg(test)]
mod tests {
    use super::{COCO80, KNOWN_CLASSES};

    #[test]
    fn the_coco_table_is_the_model_files_class_list() {
        let file: Vec<&str> = super::super::COCO_NAMES.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
        assert_eq!(file, COCO80);
        assert!(KNOWN_CLASSES.contains(&"tvmonitor") && KNOWN_CLASSES.contains(&"pottedplant"));
        assert!(!KNOWN_CLASSES.contains(&""));
    }
}
