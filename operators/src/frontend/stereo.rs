//! `stereo_match`.

use dynaflow_engine::msg::{self, CameraInfo, DepthImage, Image, Keypoints, Scalars};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_vision::orb::OrbExtractor;
use dynaflow_vision::stereo::{StereoRig, StereoView, stereo_match};

// The right image is extracted with `orb_extract`'s own parameters, which must be those of
// the left keypoints' `orb_extract` (the octaves' scales are read from them).
use super::orb::{Config, orb_config};

const KEYPOINTS: In<Keypoints> =
    In::required("keypoints", "the left image's ORB keypoints with descriptors (`orb_extract`)");
const LEFT: In<Image> = In::required("left", "the left rectified image the keypoints come from");
// Must be wired (a disabled `stereo_match`, wired only in a graph's stereo variant so the graph
// still reads a TUM folder with `--input`, is not checked); a frame without them is an error
// that says why (a source with no right camera), not a silently skipped frame.
const RIGHT: In<Image> = In::wired("right", "the right rectified image, same size (a frame without one is an error)");
const CAMERA_INFO: In<CameraInfo> = In::required("camera_info", "the left camera's intrinsics (fx for bf)");
const STEREO: In<msg::StereoRig> =
    In::wired("stereo", "the rig, the source's `stereo` (a frame without it is an error)");
const DEPTH: Out<DepthImage> =
    Out::new("depth", "sparse depth: each matched keypoint's stereo depth at its pixel, metres (0 = none)");
const STATS: Out<Scalars> = Out::new(
    "stats",
    "`keypoints`, `matched`, `no_candidate`, `no_refinement`, `out_of_range`, `high_cost` (the matcher's rejections)",
);

/// The `stereo_match` operator (its doc: `dynaflow ops stereo_match`).
pub const STEREO_MATCH: OpSpec = OpSpec::transform(
    "stereo_match",
    "stereo",
    dynaflow_engine::op::doc_line(include_str!("docs/stereo_match.md")),
    |p: &Params| {
        let config = orb_config(&Config::from_params(p)?);
        Ok(Instance::Transform(Box::new(StereoOp {
            left: OrbExtractor::new(config.clone()),
            right: OrbExtractor::new(config),
        })))
    },
)
.inputs(&[KEYPOINTS.spec, LEFT.spec, RIGHT.spec, CAMERA_INFO.spec, STEREO.spec])
.outputs(&[DEPTH.spec, STATS.spec])
.params(Config::PARAMS)
.cpu_heavy();

struct StereoOp {
    /// Builds the left pyramid (the keypoints come from `orb_extract`).
    left: OrbExtractor,
    /// Extracts the right keypoints.
    right: OrbExtractor,
}

impl Operator for StereoOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, kp) = KEYPOINTS.require(inputs)?;
        let (_, left) = LEFT.require(inputs)?;
        let (_, k) = CAMERA_INFO.require(inputs)?;
        super::pinhole_only(k, "stereo matching")?;
        let (Some(right), Some(rig)) = (RIGHT.get(inputs)?, STEREO.get(inputs)?) else {
            return Err(OpError::Input(format!(
                "frame {} has no right image or no `stereo` rig: the source gives none (`synth`: set `stereo_baseline` > 0; a zero baseline has no disparity)",
                inputs.seq
            )));
        };
        let baseline = super::stereo_baseline(rig)?;
        let (l, r) = (super::gray(left)?, super::gray(right)?);
        let descriptors: Vec<[u8; 32]> =
            super::orb_descriptors(kp)?.chunks_exact(32).map(|c| c.try_into().unwrap_or([0; 32])).collect();
        let levels = self.left.config().levels;
        if let Some(p) = kp.points.iter().find(|p| usize::from(p.octave) >= levels) {
            return Err(OpError::Input(format!(
                "a keypoint of octave {} but `levels` is {levels}: set this node's `levels` and `scale_factor` to those of the keypoints' `orb_extract`",
                p.octave
            )));
        }
        let keypoints = &kp.points;
        let fr = self.right.extract(&r, None);
        let rl = self.right.pyramid(&r);
        let ll = self.left.build_pyramid(&l);
        let scale_factor = self.right.config().scale_factor;
        let m = stereo_match(
            &StereoView { keypoints, descriptors: &descriptors, levels: &ll },
            &StereoView { keypoints: &fr.keypoints, descriptors: &fr.descriptors, levels: &rl },
            &StereoRig { bf: k.fx * baseline, baseline, scale_factor },
        )
        .map_err(OpError::library)?;
        let mut depth = DepthImage { width: left.width, height: left.height, data: vec![0.0; l.width * l.height] };
        for (p, s) in kp.points.iter().zip(&m.matches) {
            let Some(s) = s else { continue };
            let (x, y) = (p.x.round(), p.y.round());
            if x >= 0.0 && y >= 0.0 && (x as usize) < l.width && (y as usize) < l.height {
                depth.data[y as usize * l.width + x as usize] = s.depth;
            }
        }
        let stats = vec![
            ("keypoints".into(), kp.points.len() as f64),
            ("matched".into(), m.matched() as f64),
            ("no_candidate".into(), m.no_candidate as f64),
            ("no_refinement".into(), m.no_refinement as f64),
            ("out_of_range".into(), m.out_of_range as f64),
            ("high_cost".into(), m.high_cost as f64),
        ];
        Ok(Outputs::new().send(&DEPTH, msg.header.clone(), depth).send(
            &STATS,
            msg.header.clone(),
            Scalars { values: stats },
        ))
    }
}
