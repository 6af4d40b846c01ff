//! `lk_flow`.

use dynaflow_engine::msg::{Image, Keypoints, Track, Tracks};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::params;
use dynaflow_vision::flow::{LkConfig, LkTracker, Pyramid, seed_corners};

params! {
    struct Config {
        /// window side, pixels
        window: u64 [3, 101] = 21,
        /// coarsest pyramid level (OpenCV's maxLevel: 3 = four levels)
        max_level: u64 [0, 8] = 3,
        /// iterations per level at most
        iterations: u64 [1, 1000] = 30,
        /// stop when a step is shorter, pixels
        epsilon: f64 [0.0, 10.0] = 0.01,
        /// minimum-eigenvalue threshold (OpenCV's minEigThreshold)
        min_eig: f64 [0.0, 1.0] = 1e-4,
        /// forward-backward check: a point must return within this many pixels (0 = off)
        fb_threshold: f64 [0.0, 100.0] = 1.0,
        /// points tracked at most
        max_points: u64 [1, 100_000] = 1000,
        /// add new points when fewer are tracked
        min_points: u64 [0, 100_000] = 500,
        /// pixels between tracked points
        min_distance: f64 [0.0, 1000.0] = 10.0,
        /// FAST threshold of new corners
        fast_threshold: u64 [1, 254] = 20,
    }
}

const IMAGE: In<Image> = In::required("image", "RGB8 or grey image");
const POINTS: In<Keypoints> = In::optional("points", "candidate points for new tracks");
const TRACKS: Out<Tracks> = Out::new(
    "tracks",
    "tracked points: id, previous and current position, LK error (mean absolute intensity difference)",
);

/// The `lk_flow` operator (its doc: `dynaflow ops lk_flow`).
pub const LK_FLOW: OpSpec = OpSpec::transform(
    "lk_flow",
    "flow",
    dynaflow_engine::op::doc_line(include_str!("docs/lk_flow.md")),
    |p: &Params| {
        let c = Config::from_params(p)?;
        let lk = LkConfig {
            window: c.window as usize,
            max_level: c.max_level as usize,
            max_iterations: c.iterations as usize,
            epsilon: c.epsilon as f32,
            min_eig_threshold: c.min_eig as f32,
            fb_threshold: (c.fb_threshold > 0.0).then_some(c.fb_threshold as f32),
        };
        Ok(Instance::Transform(Box::new(LkOp {
            tracker: LkTracker::new(lk),
            max_level: c.max_level as usize,
            prev: Pyramid::default(),
            cur: Pyramid::default(),
            prev_seq: None,
            points: Vec::new(),
            next_id: 0,
            config: c,
        })))
    },
)
.inputs(&[IMAGE.spec, POINTS.spec])
.outputs(&[TRACKS.spec])
.params(Config::PARAMS)
.cpu_heavy();

struct LkOp {
    tracker: LkTracker,
    max_level: usize,
    prev: Pyramid,
    cur: Pyramid,
    prev_seq: Option<u64>,
    /// Tracked points of the previous frame: id and position.
    points: Vec<(u64, [f32; 2])>,
    next_id: u64,
    config: Config,
}

impl Operator for LkOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, image) = IMAGE.require(inputs)?;
        let img = super::gray(image)?;
        self.cur.build(&img, self.max_level);
        let mut tracks = Vec::new();
        let mut kept: Vec<(u64, [f32; 2])> = Vec::new();
        if self.prev_seq.is_some() && !self.points.is_empty() {
            let pts: Vec<[f32; 2]> = self.points.iter().map(|(_, p)| *p).collect();
            for ((id, p), r) in self.points.iter().zip(self.tracker.track(&self.prev, &self.cur, &pts)) {
                if r.found {
                    tracks.push(Track { id: *id, prev: *p, cur: r.point, error: r.error });
                    kept.push((*id, r.point));
                }
            }
        }
        // Re-seed when tracks thin out.
        let max = self.config.max_points as usize;
        if kept.len() < self.config.min_points as usize && kept.len() < max {
            let existing: Vec<[f32; 2]> = kept.iter().map(|(_, p)| *p).collect();
            let want = max - kept.len();
            let fresh = match POINTS.get(inputs)? {
                Some(k) => {
                    let mut cands: Vec<&dynaflow_engine::msg::Keypoint> = k.points.iter().collect();
                    cands.sort_by(|a, b| b.response.total_cmp(&a.response));
                    let mut chosen: Vec<[f32; 2]> = Vec::new();
                    let d2 = (self.config.min_distance * self.config.min_distance) as f32;
                    for c in cands {
                        let p = [c.x, c.y];
                        let far = |q: &[f32; 2]| (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) >= d2;
                        if existing.iter().all(far) && chosen.iter().all(far) {
                            chosen.push(p);
                            if chosen.len() >= want {
                                break;
                            }
                        }
                    }
                    chosen
                }
                None => seed_corners(
                    &img,
                    want,
                    self.config.fast_threshold.min(254) as u8,
                    self.config.min_distance as f32,
                    (self.config.window as usize / 2).max(3),
                    &existing,
                ),
            };
            for p in fresh {
                self.next_id += 1;
                kept.push((self.next_id, p));
            }
        }
        self.points = kept;
        std::mem::swap(&mut self.prev, &mut self.cur);
        let prev_seq = self.prev_seq.replace(msg.header.seq).unwrap_or(msg.header.seq);
        Ok(Outputs::new().send(&TRACKS, msg.header.clone(), Tracks { prev_seq, tracks }))
    }
}
