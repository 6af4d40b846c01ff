//! Class names a graph may name: those of the label sets the shipped models and the seed
//! papers use (COCO-80 for the detectors, PASCAL VOC for PSPNet-SLAM's segmenter), so a
//! misspelt class is an error when the graph is built, not a culling step that never fires.

use dynaflow_engine::diag::did_you_mean;
use dynaflow_engine::op::OpError;

use super::COCO_NAMES;

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

/// The comma-separated class names of parameter `key`, each checked against the known label
/// sets (empty entries are skipped: an empty list names no class).
pub fn known_classes(key: &str, list: &str) -> Result<Vec<String>, OpError> {
    let known = || COCO_NAMES.lines().map(str::trim).chain(VOC_NAMES.iter().copied());
    list.split(',')
        .map(str::trim)
        .filter(|c| !c.is_empty())
        .map(|c| {
            if known().any(|k| k == c) {
                Ok(c.to_owned())
            } else {
                let hint = did_you_mean(c, known()).map_or_else(String::new, |h| format!("; {h}"));
                Err(OpError::Config {
                    key: key.to_owned(),
                    message: format!(
                        "`{c}` is no class of the COCO-80 (detectors) or PASCAL VOC (segmenters) label sets{hint}"
                    ),
                })
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::known_classes;

    #[test]
    fn class_lists_are_checked_with_a_suggestion() {
        assert_eq!(known_classes("classes", " person, chair ,").unwrap(), ["person", "chair"]);
        assert_eq!(known_classes("classes", "tvmonitor").unwrap(), ["tvmonitor"]);
        assert!(known_classes("classes", "").unwrap().is_empty());
        let e = known_classes("classes", "person,persn").unwrap_err().to_string();
        assert!(e.contains("`persn`") && e.contains("did you mean `person`?"), "{e}");
    }
}
