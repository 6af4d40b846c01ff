//! `lk_flow`.

use dynaflow_engine::msg::{Body, PortType, Track, Tracks};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};
use dynaflow_vision::flow::{LkConfig, LkTracker, Pyramid, seed_corners};

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    window: u64,
    max_level: u64,
    iterations: u64,
    epsilon: f64,
    min_eig: f64,
    fb_threshold: f64,
    max_points: u64,
    min_points: u64,
    min_distance: f64,
    fast_threshold: u64,
}

pub const LK_FLOW: OpSpec = OpSpec {
    name: "lk_flow",
    family: "flow",
    doc: "Pyramidal Lucas-Kanade tracking as OpenCV's calcOpticalFlowPyrLK (Scharr gradients, minimum-eigenvalue rejection, optional forward-backward check): tracks the previous frame's points into this frame with stable ids. When fewer than `min_points` remain it adds new points, from `points` when wired (e.g. ORB keypoints) or from FAST corners, at least `min_distance` from existing ones (as YG-SLAM re-detects).",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("image", PortType::Image, "RGB8 or grey image"),
        PortSpec::optional("points", PortType::Keypoints, "candidate points for new tracks"),
    ],
    outputs: &[PortSpec::output(
        "tracks",
        PortType::Tracks,
        "tracked points: id, previous and current position, LK error (mean absolute intensity difference)",
    )],
    params: &[
        ParamSpec {
            name: "window",
            ty: ParamType::Int { min: 3, max: 101 },
            default: Default::Int(21),
            doc: "window side, pixels",
        },
        ParamSpec {
            name: "max_level",
            ty: ParamType::Int { min: 0, max: 8 },
            default: Default::Int(3),
            doc: "coarsest pyramid level (OpenCV's maxLevel: 3 = four levels)",
        },
        ParamSpec {
            name: "iterations",
            ty: ParamType::Int { min: 1, max: 1000 },
            default: Default::Int(30),
            doc: "iterations per level at most",
        },
        ParamSpec {
            name: "epsilon",
            ty: ParamType::Float { min: 0.0, max: 10.0 },
            default: Default::Float(0.01),
            doc: "stop when a step is shorter, pixels",
        },
        ParamSpec {
            name: "min_eig",
            ty: ParamType::Float { min: 0.0, max: 1.0 },
            default: Default::Float(1e-4),
            doc: "minimum-eigenvalue threshold (OpenCV's minEigThreshold)",
        },
        ParamSpec {
            name: "fb_threshold",
            ty: ParamType::Float { min: 0.0, max: 100.0 },
            default: Default::Float(1.0),
            doc: "forward-backward check: a point must return within this many pixels (0 = off)",
        },
        ParamSpec {
            name: "max_points",
            ty: ParamType::Int { min: 1, max: 100_000 },
            default: Default::Int(1000),
            doc: "points tracked at most",
        },
        ParamSpec {
            name: "min_points",
            ty: ParamType::Int { min: 0, max: 100_000 },
            default: Default::Int(500),
            doc: "add new points when fewer are tracked",
        },
        ParamSpec {
            name: "min_distance",
            ty: ParamType::Float { min: 0.0, max: 1000.0 },
            default: Default::Float(10.0),
            doc: "pixels between tracked points",
        },
        ParamSpec {
            name: "fast_threshold",
            ty: ParamType::Int { min: 1, max: 254 },
            default: Default::Int(20),
            doc: "FAST threshold of new corners",
        },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| {
        let c: Config = p.parse()?;
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
};

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
        let msg = inputs.require("image")?;
        let img = super::gray(msg)?;
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
            let fresh = match inputs.get("points").map(|m| &m.body) {
                Some(Body::Keypoints(k)) => {
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
                _ => seed_corners(
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
        let body = Body::Tracks(Tracks { prev_seq, tracks });
        Ok(Outputs::new().with("tracks", msg.header.clone(), body))
    }
}
