//! `pnp_track`.

use std::io::Write;
use std::sync::Arc;

use dynaflow_engine::msg::{Body, DepthImage, PortType, Pose, Scalars};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};
use dynaflow_vision::geometry::{Camera, SplitMix64, pnp_ransac};
use nalgebra::{Isometry3, Point3};
use rand_core::Rng;

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    threshold: f64,
    min_inliers: u64,
    max_depth: f64,
}

pub const PNP_TRACK: OpSpec = OpSpec {
    name: "pnp_track",
    family: "pnp_ba",
    doc: "RGB-D odometry: the previous frame's tracked points, back-projected with its depth, are placed in the world with its pose; PnP RANSAC and motion-only bundle adjustment (LM on SE(3), Huber, four rounds) on their current pixels give the current pose. Points labelled dynamic never reach the solver. When too few inliers remain the pose follows a constant-velocity model and `lost` is 1. Writes `<out>/<node>.trajectory.txt` (TUM format) at the end.",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("tracks", PortType::Tracks, "previous -> current correspondences"),
        PortSpec::input("depth", PortType::Depth, "depth in metres, this frame (kept for the next)"),
        PortSpec::input("camera_info", PortType::CameraInfo, "intrinsics"),
        PortSpec::optional("labels", PortType::PointLabels, "per track: dynamic ones are left out"),
    ],
    outputs: &[
        PortSpec::output("pose", PortType::Pose, "world_from_cam of this frame (the first frame is the world)"),
        PortSpec::output("stats", PortType::Scalars, "`points`, `inliers`, `lost`"),
    ],
    params: &[
        ParamSpec {
            name: "threshold",
            ty: ParamType::Float { min: 0.1, max: 100.0 },
            default: Default::Float(3.0),
            doc: "RANSAC reprojection threshold, pixels",
        },
        ParamSpec {
            name: "min_inliers",
            ty: ParamType::Int { min: 6, max: 100_000 },
            default: Default::Int(15),
            doc: "fewer inliers than this: tracking lost for the frame",
        },
        ParamSpec {
            name: "max_depth",
            ty: ParamType::Float { min: 0.1, max: 1000.0 },
            default: Default::Float(6.0),
            doc: "depths beyond this (metres) are not used (Kinect noise grows with the square)",
        },
    ],
    cpu_heavy: true,
    build: |p: &Params| {
        Ok(Instance::Transform(Box::new(PnpTrack {
            config: p.parse()?,
            prev: None,
            velocity: Isometry3::identity(),
            trajectory: Vec::new(),
        })))
    },
};

struct PnpTrack {
    config: Config,
    /// The previous frame's depth and world_from_cam.
    prev: Option<(DepthImage, Isometry3<f64>)>,
    /// Last motion prev_from_cur, for the constant-velocity fallback.
    velocity: Isometry3<f64>,
    trajectory: Vec<(f64, Isometry3<f64>)>,
}

impl Operator for PnpTrack {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("tracks")?;
        let Body::Tracks(t) = &msg.body else { return Err(OpError::Input("`tracks` is not tracks".into())) };
        let Body::Depth(depth) = &inputs.require("depth")?.body else {
            return Err(OpError::Input("`depth` is not a depth image".into()));
        };
        let Body::CameraInfo(k) = &inputs.require("camera_info")?.body else {
            return Err(OpError::Input("`camera_info` is not camera info".into()));
        };
        let cam = Camera { fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy };
        let dynamic: Vec<bool> = match inputs.get("labels").map(|m| &m.body) {
            Some(Body::PointLabels(l)) => {
                let mut d = vec![false; t.tracks.len()];
                for lab in &l.labels {
                    if let Some(x) = d.get_mut(lab.index as usize) {
                        *x = lab.dynamic;
                    }
                }
                d
            }
            _ => vec![false; t.tracks.len()],
        };
        let seed = ctx.rng.next_u64();
        let (mut points, mut inliers, mut lost) = (0usize, 0usize, 0.0);
        let world_from_cur = match &self.prev {
            None => Isometry3::identity(),
            Some((prev_depth, world_from_prev)) => {
                let (mut world, mut pixels) = (Vec::new(), Vec::new());
                for (tr, dyn_) in t.tracks.iter().zip(&dynamic) {
                    let z = f64::from(prev_depth.at_nearest(tr.prev[0], tr.prev[1]));
                    if *dyn_ || !(z > 0.0 && z <= self.config.max_depth) {
                        continue;
                    }
                    let pc = Point3::new(
                        (f64::from(tr.prev[0]) - cam.cx) / cam.fx * z,
                        (f64::from(tr.prev[1]) - cam.cy) / cam.fy * z,
                        z,
                    );
                    world.push(world_from_prev * pc);
                    pixels.push([f64::from(tr.cur[0]), f64::from(tr.cur[1])]);
                }
                points = world.len();
                let fit = pnp_ransac(&world, &pixels, &cam, self.config.threshold, 500, &mut SplitMix64::new(seed));
                match fit {
                    Some(f) if f.inliers.iter().filter(|&&i| i).count() as u64 >= self.config.min_inliers => {
                        inliers = f.inliers.iter().filter(|&&i| i).count();
                        let world_from_cur = f.pose.inverse();
                        self.velocity = world_from_prev.inverse() * world_from_cur;
                        world_from_cur
                    }
                    _ => {
                        lost = 1.0;
                        world_from_prev * self.velocity
                    }
                }
            }
        };
        self.prev = Some((depth.clone(), world_from_cur));
        self.trajectory.push((msg.header.stamp, world_from_cur));
        let header = dynaflow_engine::msg::Header { frame_id: Arc::from("world"), ..msg.header.clone() };
        let stats = vec![("points".into(), points as f64), ("inliers".into(), inliers as f64), ("lost".into(), lost)];
        Ok(Outputs::new().with("pose", header.clone(), Body::Pose(Pose { world_from_cam: world_from_cur })).with(
            "stats",
            header,
            Body::Scalars(Scalars { values: stats }),
        ))
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let Some(dir) = &ctx.out_dir else { return Ok(()) };
        if self.trajectory.is_empty() {
            return Ok(());
        }
        let path = dir.join(format!("{}.trajectory.txt", ctx.node));
        let io = |source| OpError::Io { path: path.clone(), source };
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path).map_err(io)?);
        writeln!(f, "# timestamp tx ty tz qx qy qz qw (world_from_cam, dynaflow pnp_track)").map_err(io)?;
        for (t, p) in &self.trajectory {
            let (v, q) = (p.translation.vector, p.rotation.coords);
            writeln!(f, "{t:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}", v.x, v.y, v.z, q.x, q.y, q.z, q.w)
                .map_err(io)?;
        }
        f.flush().map_err(io)
    }
}
