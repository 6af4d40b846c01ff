//! `match_descriptors`.

use dynaflow_engine::msg::{Keypoints, Track, Tracks};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::params;
use dynaflow_vision::matching::{MatchConfig, match_brute_force};

params! {
    struct Config {
        /// best distance must be below ratio x second best (1 disables); ORB-SLAM's initialiser uses 0.9
        ratio: f64 [0.0, 1.0] = 0.9,
        /// largest Hamming distance accepted (ORB-SLAM's TH_HIGH)
        max_distance: u64 [0, 256] = 100,
        /// keep mutual best matches only
        cross_check: bool = true,
        /// keep matches in the three fullest rotation bins (of 30)
        check_orientation: bool = true,
    }
}

const CURRENT: In<Keypoints> = In::required("current", "this frame's keypoints with descriptors");
const PREVIOUS: In<Keypoints> = In::optional("previous", "the previous frame's keypoints (`delay: 1`)");
const TRACKS: Out<Tracks> =
    Out::new("tracks", "one per match: track id, previous and current position, Hamming distance as `error`");

const MATCH_DESCRIPTORS_DOC: &str = "Matches this frame's ORB keypoints to the previous frame's (wire `previous` with `delay: 1`): Hamming brute force with Lowe's ratio test, cross-check and ORB-SLAM's rotation-consistency histogram. A keypoint matched to a tracked one keeps its track id; others start new tracks.";

/// The `match_descriptors` operator (its doc: `dynaflow ops match_descriptors`).
pub const MATCH_DESCRIPTORS: OpSpec =
    OpSpec::transform("match_descriptors", "matching", MATCH_DESCRIPTORS_DOC, |p: &Params| {
        let c = Config::from_params(p)?;
        let config = MatchConfig {
            max_distance: c.max_distance as u32,
            ratio: c.ratio as f32,
            cross_check: c.cross_check,
            check_orientation: c.check_orientation,
        };
        Ok(Instance::Transform(Box::new(MatchOp { config, last: None, next_id: 0 })))
    })
    .inputs(&[CURRENT.spec, PREVIOUS.spec])
    .outputs(&[TRACKS.spec])
    .params(Config::PARAMS)
    .cpu_heavy();

struct MatchOp {
    config: MatchConfig,
    /// The previous call's keypoint count and the track id of each of its keypoints.
    last: Option<(u64, Vec<u64>)>,
    next_id: u64,
}

fn descriptors(k: &Keypoints) -> Vec<[u8; 32]> {
    match &k.descriptors {
        Some(d) if d.bytes_per == 32 => {
            d.data.chunks_exact(32).map(|c| <[u8; 32]>::try_from(c).unwrap_or([0; 32])).collect()
        }
        _ => Vec::new(),
    }
}

impl Operator for MatchOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (cur_msg, cur) = CURRENT.require(inputs)?;
        let cur_desc = descriptors(cur);
        let mut ids: Vec<Option<u64>> = vec![None; cur.points.len()];
        let mut tracks = Vec::new();
        let mut prev_seq = cur_msg.header.seq;
        if let Some((prev_msg, prev)) = PREVIOUS.find(inputs)? {
            prev_seq = prev_msg.header.seq;
            let prev_desc = descriptors(prev);
            // Ids of the previous keypoints, if this node saw that frame.
            let prev_ids = self.last.take().filter(|(seq, ids)| *seq == prev_seq && ids.len() == prev.points.len());
            let q_angles: Vec<f32> = cur.points.iter().map(|p| p.angle).collect();
            let t_angles: Vec<f32> = prev.points.iter().map(|p| p.angle).collect();
            let matches = match_brute_force(&cur_desc, &prev_desc, Some((&q_angles, &t_angles)), &self.config);
            for m in matches {
                let (Some(c), Some(p)) = (cur.points.get(m.query as usize), prev.points.get(m.train as usize)) else {
                    continue;
                };
                let id = match prev_ids.as_ref().and_then(|(_, ids)| ids.get(m.train as usize)) {
                    Some(&id) => id,
                    None => {
                        self.next_id += 1;
                        self.next_id
                    }
                };
                ids[m.query as usize] = Some(id);
                tracks.push(Track { id, prev: [p.x, p.y], cur: [c.x, c.y], error: m.distance as f32 });
            }
        }
        let ids = ids
            .into_iter()
            .map(|id| {
                id.unwrap_or_else(|| {
                    self.next_id += 1;
                    self.next_id
                })
            })
            .collect();
        self.last = Some((cur_msg.header.seq, ids));
        Ok(Outputs::new().send(&TRACKS, cur_msg.header.clone(), Tracks { prev_seq, tracks }))
    }
}
