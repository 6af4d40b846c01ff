//! `octomap`: depth frames into a semantic OctoMap, a thin wrapper over `dynaflow-octomap`.

use std::time::Instant;

use dynaflow_engine::msg::{CameraInfo, DepthImage, Image, OctreeUpdate, PixelFormat, Pose, SegmentationMask};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::{param_enum, params};

use crate::inference::{ClassName, class_list};
use dynaflow_octomap::{Key, Label, OcTree, Params as TreeParams, io};

param_enum! {
    /// Where a voxel's colour comes from.
    enum Colour { Image = "image", Class = "class" }
}

params! {
    struct Config {
        /// voxel edge in metres (PSPNet-SLAM and DS-SLAM: 0.05)
        resolution: f64 [0.001, 10.0] = 0.05,
        /// depths beyond this clear their ray up to it and mark nothing (Kinect v1 depth noise grows with the square of range; 4 m keeps it under ~4 cm); -1: no limit
        max_range: f64 [-1.0, 1000.0] = 4.0,
        /// use every n-th pixel in x and y (4: 160x120 rays of a 640x480 frame; a 5 cm voxel at 2 m spans ~13 pixels)
        subsample: u64 [1, 64] = 4,
        /// OctoMap's hit probability
        prob_hit: f64 [0.5, 1.0] = 0.7,
        /// OctoMap's miss probability
        prob_miss: f64 [0.0, 0.5] = 0.4,
        /// lower clamping probability (OctoMap: 0.1192)
        clamp_min: f64 [0.0, 1.0] = 0.1192,
        /// upper clamping probability (OctoMap: 0.971)
        clamp_max: f64 [0.0, 1.0] = 0.971,
        /// mask classes never inserted
        dynamic_classes: Vec<ClassName> = class_list(&["person"]),
        /// voxel colour in the .ot file: the image's, or a colour per class (a semantic map)
        color: Colour = Colour::Image,
        /// frames between full-map outputs on `map` (0: only the last frame's)
        snapshot_every: u64 [0, 1_000_000] = 30,
        /// memory budget in MiB for the map's nodes plus one scan's scratch: a frame that would take them past it (a tiny `resolution` over a long `max_range`) ends the run with an error naming its need, before anything is allocated; the map of the frames before is written (a resource bound, not an OctoMap parameter)
        max_memory_mb: u64 [16, 1_048_576] = 4096,
    }
}

const DEPTH: In<DepthImage> = In::required("depth", "depth in metres");
const CAMERA_INFO: In<CameraInfo> = In::required("camera_info", "intrinsics");
const POSE: In<Pose> = In::required("pose", "world_from_cam: the tracker's estimate or the ground truth");
const IMAGE: In<Image> = In::optional("image", "RGB8 colours for the voxels");
const MASK: In<SegmentationMask> =
    In::optional("mask", "per-pixel classes: dynamic ones are skipped, the rest kept per voxel");
const UPDATES: Out<OctreeUpdate> =
    Out::new("updates", "voxels whose occupancy changed this frame (newly occupied with their class, newly freed)");
const MAP: Out<OctreeUpdate> = Out::new(
    "map",
    "every occupied voxel with its class, every `snapshot_every` frames (what the viewer shows as the map)",
);

/// The `octomap` operator (its doc: `dynaflow ops octomap`).
pub const OCTOMAP: OpSpec = OpSpec::transform(
    "octomap",
    "mapping",
    dynaflow_engine::op::doc_line(include_str!("docs/octomap.md")),
    |p: &Params| {
        let c = Config::from_params(p)?;
        let params = TreeParams {
            resolution: c.resolution,
            prob_hit: c.prob_hit,
            prob_miss: c.prob_miss,
            clamp_min: c.clamp_min,
            clamp_max: c.clamp_max,
            max_memory_bytes: c.max_memory_mb << 20,
            ..TreeParams::default()
        };
        let tree = OcTree::new(params, true).map_err(OpError::library)?;
        Ok(Instance::Transform(Box::new(Octomap { config: c, tree, insert_ms: Vec::new(), frames: 0, skipped: 0 })))
    },
)
.inputs(&[DEPTH.spec, CAMERA_INFO.spec, POSE.spec, IMAGE.spec, MASK.spec])
.outputs(&[UPDATES.spec, MAP.spec])
.params(Config::PARAMS)
.cpu_heavy();

struct Octomap {
    config: Config,
    tree: OcTree,
    insert_ms: Vec<f64>,
    frames: u64,
    /// Pixels left out as dynamic.
    skipped: u64,
}

/// A colour per class id: the recorders' palette, class 0 (background) grey.
fn class_color(c: u16) -> [u8; 3] {
    if c == 0 { [160, 160, 160] } else { dynaflow_engine::msg::class_rgb(c) }
}

impl Octomap {
    fn centre(&self, k: Key) -> [f32; 3] {
        let c = self.tree.grid().centre(k);
        [c[0] as f32, c[1] as f32, c[2] as f32]
    }

    /// Every occupied voxel at the finest level (pruned leaves expanded), with its class.
    fn snapshot(&self) -> OctreeUpdate {
        let mut occupied = Vec::new();
        for l in self.tree.occupied_leaves() {
            let s = l.size.min(64) as u16;
            for dz in 0..s {
                for dy in 0..s {
                    for dx in 0..s {
                        let k = Key([l.key.0[0] + dx, l.key.0[1] + dy, l.key.0[2] + dz]);
                        occupied.push((self.centre(k), l.node.class));
                    }
                }
            }
        }
        OctreeUpdate { resolution: self.config.resolution as f32, occupied, freed: Vec::new() }
    }
}

impl Operator for Octomap {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, depth) = DEPTH.require(inputs)?;
        let (_, k) = CAMERA_INFO.require(inputs)?;
        crate::frontend::pinhole_only(k, "the occupancy map's ray casting")?;
        let (_, pose) = POSE.require(inputs)?;
        // An image or mask of another size would be read at the wrong pixels: an error.
        let same_size = |what: &str, (w, h): (u32, u32)| {
            if (w, h) == (depth.width, depth.height) {
                Ok(())
            } else {
                Err(OpError::Input(format!(
                    "`{what}` is {w}x{h} but `depth` is {}x{}: it must cover the depth image pixel for pixel",
                    depth.width, depth.height
                )))
            }
        };
        let image = IMAGE.get(inputs)?;
        if let Some(i) = image {
            same_size("image", (i.width, i.height))?;
        }
        let mask = MASK.get(inputs)?;
        if let Some(m) = mask {
            same_size("mask", (m.width, m.height))?;
        }
        let dynamic: Vec<u16> = mask.map_or_else(Vec::new, |m| {
            m.class_names
                .iter()
                .enumerate()
                .filter(|(_, n)| self.config.dynamic_classes.iter().any(|c| c.as_str() == &***n))
                .map(|(i, _)| i as u16)
                .collect()
        });
        let (w, h) = (depth.width as usize, depth.height as usize);
        let step = self.config.subsample.max(1) as usize;
        let iso = pose.world_from_cam;
        let mut points = Vec::with_capacity((w / step + 1) * (h / step + 1));
        let mut labels = Vec::with_capacity(points.capacity());
        for v in (0..h).step_by(step) {
            for u in (0..w).step_by(step) {
                let i = v * w + u;
                let z = f64::from(depth.data[i]);
                if !(z.is_finite() && z > 0.0) {
                    continue;
                }
                let class = mask.and_then(|m| m.classes.get(i).copied()).unwrap_or(0);
                if dynamic.contains(&class) {
                    self.skipped += 1;
                    continue;
                }
                let p = nalgebra::Point3::new((u as f64 - k.cx) * z / k.fx, (v as f64 - k.cy) * z / k.fy, z);
                let q = iso * p;
                points.push([q.x as f32, q.y as f32, q.z as f32]);
                let color = match (self.config.color, image) {
                    (Colour::Class, _) => class_color(class),
                    (_, Some(img)) => match img.format {
                        PixelFormat::Rgb8 => [img.data[3 * i], img.data[3 * i + 1], img.data[3 * i + 2]],
                        PixelFormat::Gray8 => [img.data[i]; 3],
                    },
                    _ => [255, 255, 255],
                };
                labels.push(Label { color, class });
            }
        }
        let t = iso.translation.vector;
        let origin = [t.x as f32, t.y as f32, t.z as f32];
        let started = Instant::now();
        self.tree.insert_scan(&points, Some(&labels), origin, self.config.max_range).map_err(|e| {
            OpError::Input(format!(
                "frame {} ({} rays at resolution {} m, max_range {} m) refused: {e}; raise `resolution` or `subsample`, lower `max_range`, or raise `max_memory_mb`",
                msg.header.seq,
                points.len(),
                self.config.resolution,
                self.config.max_range
            ))
        })?;
        self.insert_ms.push(started.elapsed().as_secs_f64() * 1e3);
        self.frames += 1;
        let (mut occupied, mut freed) = (Vec::new(), Vec::new());
        for &(key, now) in self.tree.last_changes() {
            if now {
                let class = self.tree.search(key).map_or(0, |n| n.class);
                occupied.push((self.centre(key), class));
            } else {
                freed.push(self.centre(key));
            }
        }
        let update = OctreeUpdate { resolution: self.config.resolution as f32, occupied, freed };
        let mut out = Outputs::new().send(&UPDATES, msg.header.clone(), update);
        let every = self.config.snapshot_every;
        if every > 0 && self.frames.is_multiple_of(every) {
            out = out.send(&MAP, msg.header.clone(), self.snapshot());
        }
        Ok(out)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let leaves = self.tree.leaves();
        let mut report = crate::report::OctomapReport {
            frames: self.frames,
            insert_ms: crate::report::Timing::of(&self.insert_ms),
            nodes: self.tree.size(),
            leaves: leaves.len(),
            occupied_leaves: leaves.iter().filter(|l| self.tree.is_occupied(&l.node)).count(),
            memory_bytes: self.tree.memory_bytes(),
            dynamic_pixels_skipped: self.skipped,
            files: Vec::new(),
        };
        if let (Some(ot), Some(bt)) = (ctx.output_file("ot"), ctx.output_file("bt")) {
            let mut tree = self.tree.clone();
            if self.config.color == Colour::Class {
                tree.recolor(class_color);
            }
            for (path, bytes) in [(&ot, io::ot_bytes(&tree)), (&bt, io::bt_bytes(&tree))] {
                dynaflow_engine::files::write_atomic(path, &bytes)
                    .map_err(|source| OpError::Io { path: path.clone(), source })?;
            }
            report.files = vec![ot.display().to_string(), bt.display().to_string()];
        }
        ctx.report = Some(crate::report::NodeReport::from(report).to_json());
        Ok(())
    }
}
