//! Tracking and local mapping, thin wrappers over `dynaflow-slam`:
//!
//! - `track_rgbd`, `track_stereo`, `track_mono`: ORB-SLAM2's tracking against the local map
//!   (projection search from a constant-velocity model, P3P RANSAC fallback and relocalisation,
//!   motion-only BA), key-frame decisions, trajectory files and ATE against ground truth; one
//!   tracker behind three operators, each requiring what its sensor needs.
//! - `local_map`: ORB-SLAM's local mapping (covisibility window, local BA, culling), fed by
//!   the tracker's key frames and feeding its refined map back over a `delay: 1` edge.
//!
//! - `loop_close`: ORB-SLAM2's loop closing (BoW detection, SE(3) verification, fusion, the
//!   essential graph), its corrected map fed back to both over `delay: 1` edges.
//!

mod evaluation;
mod local_map;
mod loop_close;
mod track;

pub use local_map::LOCAL_MAP;
pub use loop_close::LOOP_CLOSE;
pub use track::{PNP_TRACK_MIGRATION, TRACK_MONO, TRACK_RGBD, TRACK_STEREO};

use std::path::Path;
use std::sync::Arc;

use dynaflow_engine::msg::{Message, StereoRig};
use dynaflow_engine::op::{In, OpError};
use dynaflow_slam::bow::Vocabulary;

/// The stereo rig, as `local_map` and `loop_close` read it (its baseline weighs their depth
/// terms in place of their `baseline` param).
const STEREO_RIG: In<StereoRig> =
    In::optional("stereo", "the stereo rig: with `track_stereo`, its baseline replaces `baseline`");

/// A map batch on a `latest`-joined feedback input, the first time it is seen: a `latest` join
/// repeats the last message every frame, and a batch must be applied once. `last` remembers it.
fn fresh<'a, T>(found: Option<(&'a Arc<Message>, &'a T)>, last: &mut Option<Arc<Message>>) -> Option<&'a T> {
    let (m, t) = found?;
    if last.as_ref().is_some_and(|l| Arc::ptr_eq(l, m)) {
        return None;
    }
    *last = Some(m.clone());
    Some(t)
}

/// The default vocabulary (k 10, L 5), trained by `scripts/train_vocabulary.sh`: see
/// `slam/vocabulary/SOURCE.md` for what it was trained on.
pub const DEFAULT_VOCABULARY: &[u8] = include_bytes!("../../../slam/vocabulary/default.voc");

/// A vocabulary file, or the embedded default for an empty path; with its name for reports and
/// the milliseconds loading took. A damaged file is an error naming it.
fn load_vocabulary(path: &Path) -> Result<(Arc<Vocabulary>, String, f64), OpError> {
    let t0 = std::time::Instant::now();
    let (v, name) = if path.as_os_str().is_empty() {
        let v =
            Vocabulary::from_bytes(DEFAULT_VOCABULARY, "the embedded default vocabulary").map_err(OpError::library)?;
        (v, "default".to_owned())
    } else {
        (Vocabulary::load(path).map_err(OpError::library)?, path.display().to_string())
    };
    Ok((Arc::new(v), name, t0.elapsed().as_secs_f64() * 1e3))
}

#[cfg(test)]
mod tests {
    use dynaflow_engine::op::ParamType;

    /// `dynaflow run --save-map/--load-map/--localise` reach a tracker through the parameters
    /// its `map_store` names: each must exist with the type the flag gives it.
    #[test]
    fn every_map_store_names_parameters_of_the_right_type() {
        let registry = crate::registry();
        let keepers: Vec<_> = registry.iter().filter(|op| op.map_store.is_some()).collect();
        assert_eq!(keepers.len(), 3, "the three trackers keep maps");
        for op in keepers {
            let Some(m) = op.map_store else { continue };
            let ty = |name: &str| op.param(name).map(|p| p.ty);
            assert!(matches!(ty(m.save), Some(ParamType::Path)), "{}: `{}`", op.name, m.save);
            assert!(matches!(ty(m.load), Some(ParamType::Path)), "{}: `{}`", op.name, m.load);
            assert!(matches!(ty(m.mapping), Some(ParamType::Bool)), "{}: `{}`", op.name, m.mapping);
        }
    }
}
