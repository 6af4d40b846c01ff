//! Multi-view depth consistency: a point's measured depth against where its anchored 3-D
//! position says it should be.

use super::*;

/// YOEC-DSLAM's multi-view depth check: each point of a key frame, back-projected with its
/// depth and moved into the current camera frame (`predicted[i]`, `None` when it had no depth),
/// is projected into the current image; where the depth measured there (`depth_cur`, metres,
/// 0 or NaN: none) differs from the predicted depth by more than `threshold` metres, the point
/// did not stay where the camera motion alone would put it: dynamic. A walking person's point
/// lands where the person was, on the background now. Points that cannot be judged (no depth,
/// behind the camera, outside the image) stay static with score NaN.
pub fn depth_consistency(
    predicted: &[Option<nalgebra::Point3<f64>>],
    camera: Pinhole,
    depth_cur: impl Fn(f32, f32) -> f32,
    threshold: f32,
) -> Vec<Decision> {
    predicted
        .iter()
        .map(|x| {
            let Some(x) = x.filter(|x| x.z > 1e-6) else {
                return Decision::keep(LabelReason::Static, f32::NAN);
            };
            let [u, v] = camera.project(&x).map_or([f32::NAN; 2], |uv| uv.map(|c| c as f32));
            let z2 = depth_cur(u, v);
            // No measurement (0, or NaN from outside the image).
            if z2.is_nan() || z2 <= 0.0 {
                return Decision::keep(LabelReason::Static, f32::NAN);
            }
            let r = (x.z as f32 - z2).abs();
            let dynamic = exceeds(r, threshold);
            Decision { dynamic, reason: if dynamic { LabelReason::Depth } else { LabelReason::Static }, score: r }
        })
        .collect()
}

/// YOEC-DSLAM's depth check over a sequence: the anchoring state of [`depth_consistency`].
/// Each track is anchored in the world when first seen (at its previous position, with the
/// previous frame's depth and pose); each frame predicts every anchored track's point in the
/// current view and compares its depth with the measured one. Tracks that end are forgotten.
#[derive(Debug, Default)]
pub struct DepthAnchors {
    anchors: std::collections::HashMap<u64, nalgebra::Point3<f64>>,
}

/// One track for [`DepthAnchors`]: its id and its previous and current pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackedPoint {
    /// Stable track id.
    pub id: u64,
    /// Pixel in the previous frame.
    pub prev: [f32; 2],
    /// Pixel in this frame.
    pub cur: [f32; 2],
}

impl DepthAnchors {
    /// No anchors.
    pub fn new() -> Self {
        Self::default()
    }

    /// Label this frame's tracks. `previous`: the previous frame's depth lookup (metres, 0:
    /// none) and `world_from_cam`, when this node saw it; `current`: this frame's.
    pub fn label(
        &mut self,
        tracks: &[TrackedPoint],
        camera: Pinhole,
        previous: Option<(impl Fn(f32, f32) -> f32, nalgebra::Isometry3<f64>)>,
        current: (impl Fn(f32, f32) -> f32, nalgebra::Isometry3<f64>),
        threshold: f32,
    ) -> Vec<Decision> {
        let ids: std::collections::HashSet<u64> = tracks.iter().map(|t| t.id).collect();
        self.anchors.retain(|id, _| ids.contains(id));
        if let Some((prev_depth, world_from_prev)) = previous {
            for t in tracks {
                let z = prev_depth(t.prev[0], t.prev[1]);
                if z > 0.0 && !self.anchors.contains_key(&t.id) {
                    self.anchors.insert(
                        t.id,
                        world_from_prev * camera.unproject([f64::from(t.prev[0]), f64::from(t.prev[1])], f64::from(z)),
                    );
                }
            }
        }
        let (cur_depth, world_from_cur) = current;
        let cur_from_world = world_from_cur.inverse();
        let predicted: Vec<Option<nalgebra::Point3<f64>>> =
            tracks.iter().map(|t| self.anchors.get(&t.id).map(|x| cur_from_world * x)).collect();
        depth_consistency(&predicted, camera, cur_depth, threshold)
    }

    /// Tracks anchored.
    pub fn len(&self) -> usize {
        self.anchors.len()
    }

    /// Whether no track is anchored.
    pub fn is_empty(&self) -> bool {
        self.anchors.is_empty()
    }
}
