//! The rerun recorder: every recorded port becomes entity `/<node>/<port>` logged as its
//! natural archetype, on the `frame` (sequence number) timeline, with provenance as recording
//! properties and a default blueprint. (Each message's sensor time is its MCAP `log_time` and
//! the timestamp column of the trajectory files; a second timeline here would add a column per
//! component to the footer manifest kept in memory, see below.)
//!
//! Why one file of this size: `record` is one `match` over every port type, each arm that
//! type's archetype (the table below); then its unit tests (change-only logging, path
//! segments, shared encodings). The `.rrd` writer itself is `file.rs`.
//!
//! | port type | entity | archetype |
//! |---|---|---|
//! | image | `/<node>/<port>` | `EncodedImage` (JPEG/PNG), `Image` with `--image-format raw` |
//! | depth | `/<node>/<port>` | `DepthImage` (raw 16-bit millimetres) |
//! | camera_info | (none of its own) | the intrinsics of the `Pinhole` of each pose stream seen through it (`RunInfo::cameras`) |
//! | keypoints | `/<node>/<port>` | `Points2D` coloured by octave |
//! | tracks | `/<node>/<port>` | `Arrows2D` |
//! | detections | `/<node>/<port>` | `Boxes2D` with class labels |
//! | mask | `/<node>/<port>` | `SegmentationImage` (8-bit ids when they fit) + `AnnotationContext` (static, re-logged when the class names change) |
//! | point_labels | `/<node>/<port>` | `Points2D` red = dynamic, green = static |
//! | pose | `/world/<node>/<port>` | `Transform3D` (+ a static `Pinhole` once the intrinsics are known, re-logged if they change); path so far at `…_path/<k>` (`LineStrips3D`, 100 poses per segment) |
//! | trajectory | `/world/<node>/<port>` | `LineStrips3D` |
//! | point_cloud | `/world/<node>/<port>` | `Points3D` |
//! | octree_update | `/world/<node>/<port>` | `Boxes3D` |
//! | scalars | `/metrics/<node>/<port>` | `Scalars`, one series per name (`SeriesLines` names) |
//!
//! Long runs in bounded memory. The file's footer manifest has a row per chunk, held until the
//! file closes; [`file`] keeps it per entity (a row carries that entity's components only,
//! about 0.2 KB, not the SDK's dense ~2 KB), and the file recorder makes few chunks: every
//! entity's rows are cut once per [`CUT_EVERY_FRAMES`] frames or at 4 MiB, one timeline (no
//! `log_time`, no second clock), one entity per scalar port, pose paths in segments. What
//! waits to be written is bounded in bytes at every stage: rows per entity in the batcher and
//! the batcher's in-flight budget; the file writer encodes and writes each chunk as it comes,
//! with no queue of its own.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;

use dynaflow_engine::msg::{Body, CameraInfo, Message, PixelFormat, PortType};
use dynaflow_engine::sink::{PortReport, RunInfo, Sink, SinkError, SinkReport};
use rerun::blueprint::{
    Blueprint, BlueprintActivation, ContainerLike, Horizontal, Spatial2DView, Spatial3DView, TimeSeriesView, Vertical,
};

use crate::encode::{self, EncodeCache, ImageCodec};

mod file;
use file::{RrdFile, SharedFile};

/// Where a [`RrdSink`] sends its stream.
#[derive(Clone, Debug)]
pub enum Target {
    /// An `.rrd` file.
    File(PathBuf),
    /// A running rerun viewer or server (`rerun+http://host:port/proxy`).
    Grpc(String),
}

impl std::fmt::Display for Target {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::File(p) => write!(f, "{}", p.display()),
            Self::Grpc(url) => write!(f, "{url}"),
        }
    }
}

/// Writes `<out>/<graph>.rrd` (or streams the same to a viewer: see `live`).
pub struct RrdSink {
    target: Target,
    rec: Option<rerun::RecordingStream>,
    codec: ImageCodec,
    /// The latest intrinsics on each camera-info port (`node/port`).
    intrinsics: HashMap<String, CameraInfo>,
    /// The camera-info port each pose port is seen through (the run's `RunInfo::cameras`).
    cameras: BTreeMap<String, String>,
    /// Positions of each pose stream so far, drawn as a path.
    trails: HashMap<String, Vec<[f32; 3]>>,
    cache: EncodeCache,
    /// The last `frame / CUT_EVERY_FRAMES` at which the file's pending rows were cut.
    cut: u64,
    /// Series names of each scalar port, in first-seen order (the `Scalars` instance index).
    series: HashMap<String, Vec<std::sync::Arc<str>>>,
    /// Messages and pixel bytes per `node/port`.
    ports: std::collections::BTreeMap<String, PortReport>,
    /// The `.rrd` file's writer (file targets), to finish it and read its error.
    file: Option<std::sync::Arc<SharedFile>>,
    /// Per entity, what was last logged of what rarely changes (a mask's class names, a pose's
    /// intrinsics). It is logged static, again only when it changes: a viewer keeps static data
    /// whatever older frames it drops to stay within its memory limit, and logged with every
    /// message, each became a chunk of its own at every cut (a component set is its own
    /// chunk), a quarter of the file's chunks on the default graph.
    logged_classes: HashMap<String, Vec<std::sync::Arc<str>>>,
    logged_pinholes: HashMap<String, CameraInfo>,
}

/// Batching of the live stream: a 50 ms tick, so a viewer shows each frame within a
/// twentieth of a second, in a few chunks per frame rather than one per entity and row (the
/// SDK's low-latency 8 ms tick cost 1.14x the file-only run's wall time on the default graph
/// against a local receiver, docs/benchmarks.md).
const LIVE_BATCHING: rerun::log::ChunkBatcherConfig = rerun::log::ChunkBatcherConfig {
    flush_tick: std::time::Duration::from_millis(50),
    ..rerun::log::ChunkBatcherConfig::DEFAULT
};

/// How the file recorder batches rows into chunks. Two costs pull apart: every chunk costs a
/// manifest row in memory until the file closes (a few hundred bytes, see [`file`]), and every chunk passes through the SDK as several transient copies of its size
/// (concatenated rows, Arrow IPC, LZ4 output, the framed message: heaptrack at the peak of a
/// 600-frame run held about 5x the chunk size there). So an entity's rows are cut at 4 MiB
/// (about 6 frames of 640x480 depth) or by the recorder every [`CUT_EVERY_FRAMES`] frames, not
/// on the SDK's 0.2 s tick / 2 MiB; 16 MiB in flight between the recorder, the batcher and the
/// writer (the SDK's default is 100 MiB). The file is not watched live; a killed run's `.rrd`
/// lacks the rows since the last cut (the MCAP recorder writes its own chunks). Measured on
/// the default graph: docs/benchmarks.md.
const BATCHING: rerun::log::ChunkBatcherConfig = rerun::log::ChunkBatcherConfig {
    flush_tick: std::time::Duration::MAX,
    flush_num_bytes: 4 << 20,
    max_bytes_in_flight: 16 << 20,
    ..rerun::log::ChunkBatcherConfig::DEFAULT
};

/// `config`, overridden by the rerun SDK's documented environment variables
/// (`RERUN_FLUSH_NUM_BYTES`, `RERUN_FLUSH_NUM_ROWS`, `RERUN_FLUSH_TICK_SECS`), which the SDK
/// applies only when no configuration is given. An unreadable value keeps `config`, with a warning.
fn with_env(config: rerun::log::ChunkBatcherConfig) -> rerun::log::ChunkBatcherConfig {
    config.apply_env().unwrap_or_else(|e| {
        tracing::warn!("ignoring the rerun batching environment: {e}");
        config
    })
}

/// A pose stream's path is drawn as segments of this many poses, each its own entity
/// `…_path/<k>` (so every log carries at most one segment, and the file grows linearly with
/// the run, not quadratically), re-logged every [`TRAIL_EVERY`] poses.
const TRAIL_SEGMENT: usize = 100;

/// How often the current segment of a pose stream's path is re-logged, in poses.
const TRAIL_EVERY: usize = 10;

/// The file recorder cuts every entity's pending rows into chunks once per this many frames
/// (by frame number, so the cut points do not depend on the machine's speed). The SDK's own
/// tick is off for the file: it skips a tick after any entity was cut by size, which with
/// images cut every second starved the small entities, which then grew to the size limit.
/// The small entities (scalars, poses, keypoints) are what this cuts: 500 frames (17 s at
/// 30 Hz) keeps their chunks to one per 500 frames each, at the price of what a killed run's
/// `.rrd` loses (the MCAP file loses at most a second).
const CUT_EVERY_FRAMES: u64 = 500;

impl RrdSink {
    /// A recorder writing to `path`, colour images as JPEG (q 90).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self::to(Target::File(path.into()))
    }

    /// A recorder streaming to `target`, colour images as JPEG (q 90).
    pub fn to(target: Target) -> Self {
        Self {
            target,
            rec: None,
            codec: ImageCodec::Jpeg(90),
            intrinsics: HashMap::new(),
            cameras: BTreeMap::new(),
            trails: HashMap::new(),
            cache: EncodeCache::default(),
            series: HashMap::new(),
            cut: 0,
            ports: std::collections::BTreeMap::new(),
            file: None,
            logged_classes: HashMap::new(),
            logged_pinholes: HashMap::new(),
        }
    }

    /// Share image encodings with other recorders (the MCAP recorder).
    #[must_use]
    pub fn with_cache(mut self, cache: EncodeCache) -> Self {
        self.cache = cache;
        self
    }

    /// How colour images are stored.
    #[must_use]
    pub fn with_codec(mut self, codec: ImageCodec) -> Self {
        self.codec = codec;
        self
    }

    fn err(&self, e: impl std::fmt::Display) -> SinkError {
        SinkError::new("rerun", format!("{}: {e}", self.target))
    }

    /// Named values as one entity per port, one series per name: a name not seen before on
    /// this port becomes a new series (its names re-logged); a name missing from a message is
    /// NaN there (a gap in the plot).
    fn log_series(
        &mut self,
        rec: &rerun::RecordingStream,
        node: &str,
        port: &str,
        path: &str,
        named: &[(std::sync::Arc<str>, f64)],
    ) -> rerun::RecordingStreamResult<()> {
        let entity = format!("metrics/{node}/{port}");
        let names = self.series.entry(path.to_owned()).or_default();
        let known = names.len();
        for (name, _) in named {
            if !names.contains(name) {
                names.push(name.clone());
            }
        }
        let values: Vec<f64> =
            names.iter().map(|n| named.iter().find(|(name, _)| name == n).map_or(f64::NAN, |(_, v)| *v)).collect();
        if names.len() != known {
            rec.log_static(
                entity.as_str(),
                &rerun::SeriesLines::new().with_names(names.iter().map(|n| n.to_string())),
            )?;
        }
        rec.log(entity, &rerun::Scalars::new(values))
    }
}

/// The default layout: the camera image with what tracking decides drawn on it (points in red
/// where dynamic, green where static, the deciding rule and its measure on hover; estimated
/// masks with a transparent background), each other image on its own, the 3-D world and the
/// metrics over time. Overlays sit on one image only: every point set of a frame on every
/// image hid which points were dynamic.
fn blueprint(info: &RunInfo) -> Blueprint {
    let of = |ty: PortType| info.ports.iter().filter(move |(_, t)| **t == ty).map(|(p, _)| p.clone());
    let labels: Vec<String> =
        if info.decisions.is_empty() { of(PortType::PointLabels).collect() } else { info.decisions.clone() };
    let masks: Vec<String> = of(PortType::Mask).filter(|p| !info.ground_truth_ports.contains(p)).collect();
    let overlays: Vec<String> = masks.iter().chain(&labels).map(|p| format!("/{p}")).collect();
    // The camera image: the first colour image that no other node derived (a source's).
    let images: Vec<String> = of(PortType::Image).collect();
    let camera = camera_of(&images).cloned();
    let mut views: Vec<ContainerLike> = Vec::new();
    if let Some(cam) = &camera {
        let mut contents = vec![format!("/{cam}")];
        contents.extend(overlays.iter().cloned());
        views.push(
            Spatial2DView::new(format!("{cam}: dynamic (red) / static (green)"))
                .with_origin("/")
                .with_contents(contents)
                .into(),
        );
    } else if !overlays.is_empty() {
        views.push(Spatial2DView::new("image space").with_origin("/").with_contents(overlays).into());
    }
    for p in info
        .ports
        .iter()
        .filter(|(p, ty)| matches!(ty, PortType::Image | PortType::Depth) && Some(*p) != camera.as_ref())
        .map(|(p, _)| p)
    {
        views.push(Spatial2DView::new(p.clone()).with_origin("/").with_contents([format!("/{p}")]).into());
    }
    let right: Vec<ContainerLike> = vec![
        Spatial3DView::new("world").with_origin("/world").into(),
        TimeSeriesView::new("metrics").with_origin("/metrics").into(),
    ];
    let mut columns: Vec<ContainerLike> = Vec::new();
    if !views.is_empty() {
        // The camera with the decisions gets as much height as the other images together.
        let others = (views.len() - 1).max(1) as f32;
        let shares: Vec<f32> =
            (0..views.len()).map(|i| if i == 0 && camera.is_some() { others } else { 1.0 }).collect();
        columns.push(Vertical::new(views).with_row_shares(shares).into());
    }
    columns.push(Vertical::new(right).into());
    Blueprint::new(Horizontal::new(columns))
}

/// Point labels as every dynaflow recording draws them (`(point, dynamic, hover text)`): red
/// where dynamic, green where static, the text shown on hover, radii in UI points so the
/// points stay visible at any zoom of the image.
pub(crate) fn label_points(labels: impl IntoIterator<Item = ([f32; 2], bool, String)>) -> rerun::Points2D {
    let (mut xy, mut colors, mut texts) = (Vec::new(), Vec::new(), Vec::new());
    for (at, dynamic, text) in labels {
        xy.push(at);
        colors.push(if dynamic { rerun::Color::from_rgb(230, 40, 40) } else { rerun::Color::from_rgb(40, 200, 60) });
        texts.push(text);
    }
    rerun::Points2D::new(xy)
        .with_colors(colors)
        .with_radii([rerun::Radius::new_ui_points(2.5)])
        .with_labels(texts)
        .with_show_labels(false)
}

/// The camera among colour image ports or topics: a source's `…/rgb` or `…/left`, else the
/// first.
pub(crate) fn camera_of<S: AsRef<str>>(names: &[S]) -> Option<&S> {
    names.iter().find(|p| p.as_ref().ends_with("/rgb") || p.as_ref().ends_with("/left")).or(names.first())
}

/// Segment `k` of a path: poses `k * TRAIL_SEGMENT ..= (k + 1) * TRAIL_SEGMENT` (it shares
/// its last pose with the next segment's first, so the drawn path has no gaps), as far as the
/// path goes.
fn trail_segment(trail: &[[f32; 3]], k: usize) -> Vec<[f32; 3]> {
    let start = k * TRAIL_SEGMENT;
    trail[start.min(trail.len())..((k + 1) * TRAIL_SEGMENT + 1).min(trail.len())].to_vec()
}

/// Logs segment `k` of the path of pose entity `world` as `<world>_path/<k>`.
fn log_trail_segment(
    rec: &rerun::RecordingStream,
    world: &str,
    trail: &[[f32; 3]],
    k: usize,
) -> rerun::RecordingStreamResult<()> {
    rec.log(format!("{world}_path/{k}"), &rerun::LineStrips3D::new([trail_segment(trail, k)]))
}

/// Whether `value` differs from what `last` holds for `key` (or is its first), recording it:
/// what is logged static is logged again only when it changes.
fn changed<T: PartialEq + Clone>(last: &mut HashMap<String, T>, key: &str, value: &T) -> bool {
    if last.get(key) == Some(value) {
        return false;
    }
    last.insert(key.to_owned(), value.clone());
    true
}

fn octave_color(octave: u8) -> rerun::Color {
    const PALETTE: [[u8; 3]; 8] = [
        [230, 25, 75],
        [60, 180, 75],
        [255, 225, 25],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
    ];
    let [r, g, b] = PALETTE[usize::from(octave) % PALETTE.len()];
    rerun::Color::from_rgb(r, g, b)
}

fn class_color(id: u16) -> rerun::Color {
    let [r, g, b] = dynaflow_engine::msg::class_rgb(id);
    rerun::Color::from_rgb(r, g, b)
}

impl Sink for RrdSink {
    fn name(&self) -> &str {
        "rerun"
    }

    fn open(&mut self, info: &RunInfo) -> Result<(), SinkError> {
        let builder = rerun::RecordingStreamBuilder::new("dynaflow");
        let rec = match &self.target {
            Target::File(path) => {
                let state = std::sync::Arc::new(SharedFile::create(path).map_err(|e| self.err(e))?);
                self.file = Some(state.clone());
                builder
                    .batcher_config(with_env(BATCHING))
                    .buffered()
                    .inspect(|rec| rec.set_sink(Box::new(RrdFile { state })))
            }
            Target::Grpc(url) => builder.batcher_config(with_env(LIVE_BATCHING)).connect_grpc_opts(url.clone()),
        }
        .map_err(|e| self.err(e))?;
        // Wall-clock log time is not a dynaflow timeline (`frame` is), and each timeline adds
        // a column per component to every chunk's manifest row.
        rec.set_log_time_enabled(false);
        self.cameras.clone_from(&info.cameras);
        let name = match &info.variant {
            Some(v) => format!("{} ({v})", info.graph),
            None => info.graph.clone(),
        };
        rec.send_recording_name(name).map_err(|e| self.err(e))?;
        let props = rerun::AnyValues::default()
            .with_component_from_data(
                "graph",
                std::sync::Arc::new(rerun::external::arrow::array::StringArray::from(vec![info.graph.clone()])),
            )
            .with_component_from_data(
                "variant",
                std::sync::Arc::new(rerun::external::arrow::array::StringArray::from(vec![
                    info.variant.clone().unwrap_or_default(),
                ])),
            )
            .with_component_from_data(
                "seed",
                std::sync::Arc::new(rerun::external::arrow::array::UInt64Array::from(vec![info.seed])),
            )
            .with_component_from_data(
                "dynaflow_version",
                std::sync::Arc::new(rerun::external::arrow::array::StringArray::from(vec![info.version.clone()])),
            )
            .with_component_from_data(
                "git_commit",
                std::sync::Arc::new(rerun::external::arrow::array::StringArray::from(vec![info.git_commit.clone()])),
            );
        rec.send_property("dynaflow", &props).map_err(|e| self.err(e))?;
        let params = serde_json::to_string_pretty(&info.params).unwrap_or_default();
        let doc = format!(
            "# {}\n\n- variant: `{}`\n- seed: `{}`\n- dynaflow {} (commit `{}`)\n- realtime: `{}`\n\n## Graph\n\n```yaml\n{}\n```\n\n## Resolved parameters\n\n```json\n{}\n```\n",
            info.graph,
            info.variant.as_deref().unwrap_or("-"),
            info.seed,
            info.version,
            info.git_commit,
            info.realtime,
            info.graph_yaml.trim_end(),
            params
        );
        rec.log_static("provenance", &rerun::TextDocument::new(doc).with_media_type(rerun::MediaType::markdown()))
            .map_err(|e| self.err(e))?;
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP()).map_err(|e| self.err(e))?;
        blueprint(info)
            .send(&rec, BlueprintActivation { make_active: true, make_default: true })
            .map_err(|e| self.err(e))?;
        self.rec = Some(rec);
        Ok(())
    }

    /// A `TextLog` at `parameters/<node>` on the frame the change took effect.
    fn parameter_change(
        &mut self,
        node: &str,
        change: &dynaflow_engine::runtime::ParameterChange,
        _stamp: f64,
    ) -> Result<(), SinkError> {
        let Some(rec) = self.rec.clone() else { return Err(self.err("not open")) };
        rec.set_time_sequence("frame", change.frame as i64);
        let text = format!("{}: {} -> {}", change.param, change.old, change.new);
        rec.log(format!("parameters/{node}"), &rerun::TextLog::new(text).with_level(rerun::TextLogLevel::INFO))
            .map_err(|e| self.err(e))
    }

    fn record(&mut self, node: &str, port: &str, msg: &Message) -> Result<(), SinkError> {
        let Some(rec) = self.rec.clone() else { return Err(self.err("not open")) };
        if let Some(e) = self.file.as_ref().and_then(|f| f.failed()) {
            return Err(self.err(e));
        }
        rec.set_time_sequence("frame", msg.header.seq as i64);
        // The entity path, also the key of the per-port counts and series names.
        let path = format!("{node}/{port}");
        let world = format!("world/{node}/{port}");
        let mut pixel_bytes = 0;
        let r = match &msg.body {
            Body::Image(img) if self.codec == ImageCodec::Raw => {
                pixel_bytes = img.data.len();
                let image = match img.format {
                    PixelFormat::Rgb8 => rerun::Image::from_rgb24(img.data.clone(), [img.width, img.height]),
                    PixelFormat::Gray8 => rerun::Image::from_l8(img.data.clone(), [img.width, img.height]),
                };
                rec.log(path.as_str(), &image)
            }
            Body::Image(img) => {
                let codec = self.codec;
                let e = self.cache.get_or_encode(msg, 0, || encode::image(img, codec)).map_err(|e| self.err(e))?;
                pixel_bytes = e.bytes.len();
                let media = if e.format == "jpeg" { rerun::MediaType::jpeg() } else { rerun::MediaType::png() };
                rec.log(path.as_str(), &rerun::EncodedImage::from_file_contents(e.bytes.clone()).with_media_type(media))
            }
            Body::Depth(d) => {
                // Raw 16-bit millimetres (the viewer's depth, half the bytes of f32), compressed
                // by the file sink; bit-exact depth is the MCAP recording's `32FC1`.
                let mm = encode::depth_mm_le(d);
                pixel_bytes = mm.len();
                rec.log(
                    path.as_str(),
                    &rerun::DepthImage::from_data_type_and_bytes(mm, [d.width, d.height], rerun::ChannelDatatype::U16)
                        .with_meter(1000.0),
                )
            }
            Body::CameraInfo(c) => {
                self.intrinsics.insert(path.clone(), c.clone());
                Ok(())
            }
            Body::Keypoints(k) => {
                let xy: Vec<[f32; 2]> = k.points.iter().map(|p| [p.x, p.y]).collect();
                rec.log(
                    path.as_str(),
                    &rerun::Points2D::new(xy)
                        .with_colors(k.points.iter().map(|p| octave_color(p.octave)))
                        .with_radii([2.0]),
                )
            }
            Body::Tracks(t) => {
                let origins: Vec<[f32; 2]> = t.tracks.iter().map(|t| t.prev).collect();
                let vectors: Vec<[f32; 2]> =
                    t.tracks.iter().map(|t| [t.cur[0] - t.prev[0], t.cur[1] - t.prev[1]]).collect();
                rec.log(path.as_str(), &rerun::Arrows2D::from_vectors(vectors).with_origins(origins))
            }
            Body::Detections(d) => {
                let mins: Vec<[f32; 2]> = d.detections.iter().map(|b| [b.bbox[0], b.bbox[1]]).collect();
                let sizes: Vec<[f32; 2]> =
                    d.detections.iter().map(|b| [b.bbox[2] - b.bbox[0], b.bbox[3] - b.bbox[1]]).collect();
                let labels: Vec<String> = d.detections.iter().map(|b| format!("{} {:.2}", b.label, b.score)).collect();
                let ids: Vec<u16> = d.detections.iter().map(|b| b.class_id as u16).collect();
                rec.log(
                    path.as_str(),
                    &rerun::Boxes2D::from_mins_and_sizes(mins, sizes).with_labels(labels).with_class_ids(ids),
                )
            }
            Body::Mask(m) => {
                if changed(&mut self.logged_classes, &path, &m.class_names) {
                    // Class 0 is the background: transparent, so only the classes a rule
                    // looks for tint the image.
                    let ctx = rerun::AnnotationContext::new(m.class_names.iter().enumerate().map(|(i, n)| {
                        let color = if i == 0 {
                            rerun::Color::from_unmultiplied_rgba(0, 0, 0, 0)
                        } else {
                            class_color(i as u16)
                        };
                        (i as u16, n.as_ref(), color.0)
                    }));
                    rec.log_static(path.as_str(), &ctx).map_err(|e| self.err(e))?;
                }
                let (bytes, encoding, _) = encode::mask_raw(m);
                pixel_bytes = bytes.len();
                let datatype =
                    if encoding == "mono8" { rerun::ChannelDatatype::U8 } else { rerun::ChannelDatatype::U16 };
                let format = rerun::datatypes::ImageFormat::segmentation([m.width, m.height], datatype);
                rec.log(path.as_str(), &rerun::SegmentationImage::new(bytes, format).with_opacity(0.5))
            }
            Body::PointLabels(l) => {
                // Each label at its own point (a replayed label of unknown place is left out),
                // the deciding rule and its measure shown on hover.
                let points = l.labels.iter().filter(|l| l.at.iter().all(|v| v.is_finite())).map(|lab| {
                    let reason = serde_json::to_value(lab.reason).ok();
                    let reason = reason.as_ref().and_then(|v| v.as_str()).unwrap_or("?").to_owned();
                    (lab.at, lab.dynamic, format!("{reason} {:.2}", lab.score))
                });
                rec.log(path.as_str(), &label_points(points))
            }
            Body::Pose(p) => {
                let t = p.world_from_cam.translation.vector;
                let q = p.world_from_cam.rotation.coords;
                let tf = rerun::Transform3D::from_translation_rotation(
                    [t.x as f32, t.y as f32, t.z as f32],
                    rerun::Quaternion::from_xyzw([q.x as f32, q.y as f32, q.z as f32, q.w as f32]),
                );
                rec.log(world.clone(), &tf).map_err(|e| self.err(e))?;
                let trail = self.trails.entry(world.clone()).or_default();
                trail.push([t.x as f32, t.y as f32, t.z as f32]);
                let newest = trail.len() - 1;
                if newest.is_multiple_of(TRAIL_EVERY) {
                    let segment = newest / TRAIL_SEGMENT;
                    // A segment's first pose closes the previous one (its last stretch).
                    let first = if newest.is_multiple_of(TRAIL_SEGMENT) { segment.saturating_sub(1) } else { segment };
                    let logged = (first..=segment).try_for_each(|k| log_trail_segment(&rec, &world, trail, k));
                    logged.map_err(|e| self.err(e))?;
                }
                // The pinhole of this pose stream's own camera (a graph may hold several).
                let camera = self.cameras.get(&path).and_then(|c| self.intrinsics.get(c));
                match camera {
                    Some(c) if changed(&mut self.logged_pinholes, &world, c) => rec.log_static(
                        world,
                        &rerun::Pinhole::from_focal_length_and_resolution(
                            [c.fx as f32, c.fy as f32],
                            [c.width as f32, c.height as f32],
                        )
                        .with_principal_point([c.cx as f32, c.cy as f32])
                        .with_image_plane_distance(0.3),
                    ),
                    _ => Ok(()),
                }
            }
            Body::Trajectory(tr) => {
                let strip: Vec<[f32; 3]> = tr
                    .poses
                    .iter()
                    .map(|p| {
                        let t = p.world_from_cam.translation.vector;
                        [t.x as f32, t.y as f32, t.z as f32]
                    })
                    .collect();
                rec.log(world, &rerun::LineStrips3D::new([strip]))
            }
            Body::PointCloud(c) => {
                let mut pts = rerun::Points3D::new(c.points.iter().copied());
                if let Some(colors) = &c.colors {
                    pts = pts.with_colors(colors.iter().map(|[r, g, b]| rerun::Color::from_rgb(*r, *g, *b)));
                }
                rec.log(world, &pts)
            }
            Body::Map(m) => rec.log(world, &rerun::Points3D::new(crate::mcap::schemas::map_cloud(m).points)),
            Body::OctreeUpdate(o) => {
                let h = o.resolution / 2.0;
                let centers: Vec<[f32; 3]> = o.occupied.iter().map(|(p, _)| *p).collect();
                let colors: Vec<rerun::Color> = o.occupied.iter().map(|(_, c)| class_color(*c)).collect();
                rec.log(world, &rerun::Boxes3D::from_centers_and_half_sizes(centers, [[h, h, h]]).with_colors(colors))
            }
            Body::Scalars(s) => self.log_series(&rec, node, port, &path, &s.values),
            // The rig as one series (`baseline_m`), beside the metrics.
            Body::StereoRig(r) => {
                self.log_series(&rec, node, port, &path, &[(std::sync::Arc::from("baseline_m"), r.baseline)])
            }
            // The frame's mean angular rate and specific force per axis, and its sample count.
            Body::Imu(b) => {
                let n = b.samples.len().max(1) as f64;
                let gyro = b.samples.iter().map(|s| s.gyro).sum::<nalgebra::Vector3<f64>>() / n;
                let accel = b.samples.iter().map(|s| s.accel).sum::<nalgebra::Vector3<f64>>() / n;
                let named: Vec<(std::sync::Arc<str>, f64)> =
                    ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
                        .iter()
                        .zip(gyro.iter().chain(accel.iter()))
                        .map(|(k, v)| (std::sync::Arc::from(*k), *v))
                        .chain(std::iter::once((std::sync::Arc::from("samples"), b.samples.len() as f64)))
                        .collect();
                self.log_series(&rec, node, port, &path, &named)
            }
            _ => Ok(()),
        };
        let entry = self.ports.entry(path).or_default();
        entry.messages += 1;
        entry.bytes += pixel_bytes as u64;
        if matches!(self.target, Target::File(_)) && msg.header.seq / CUT_EVERY_FRAMES > self.cut {
            self.cut = msg.header.seq / CUT_EVERY_FRAMES;
            rec.flush_async().map_err(|e| self.err(e))?;
        }
        r.map_err(|e| self.err(e))
    }

    fn close(&mut self) -> Result<(), SinkError> {
        let Some(rec) = self.rec.take() else { return Ok(()) };
        // Each path's current segment as it ended (it is re-logged every few poses only).
        for (world, trail) in &self.trails {
            if let Some(newest) = trail.len().checked_sub(1) {
                log_trail_segment(&rec, world, trail, newest / TRAIL_SEGMENT).map_err(|e| self.err(e))?;
            }
        }
        match self.target {
            Target::File(_) => rec.flush_blocking().map_err(|e| self.err(e))?,
            // A viewer that went away must not hold the run's end.
            Target::Grpc(_) => rec.flush_with_timeout(std::time::Duration::from_secs(3)).map_err(|e| self.err(e))?,
        }
        drop(rec);
        match self.file.take() {
            Some(file) => file.finish().map_err(|e| self.err(e)),
            None => Ok(()),
        }
    }

    fn report(&self) -> SinkReport {
        let path = match &self.target {
            Target::File(p) => Some(p),
            Target::Grpc(_) => None,
        };
        SinkReport {
            path: path.map(|p| p.display().to_string()),
            file_bytes: path.and_then(|p| std::fs::metadata(p).ok()).map(|m| m.len()),
            ports: self.ports.clone(),
            ..SinkReport::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::{BTreeMap, HashMap};
    use std::sync::Arc;

    use dynaflow_engine::msg::{Body, DepthImage, Header, Image, Message, PixelFormat};
    use dynaflow_engine::sink::{RunInfo, Sink};

    use super::RrdSink;
    use crate::{EncodeCache, McapSink};

    #[test]
    fn what_rarely_changes_is_logged_again_only_when_it_changes_per_entity() {
        let mut last = HashMap::new();
        assert!(super::changed(&mut last, "a", &1));
        assert!(!super::changed(&mut last, "a", &1));
        assert!(super::changed(&mut last, "b", &1));
        assert!(super::changed(&mut last, "a", &2));
        assert!(!super::changed(&mut last, "a", &2));
        assert!(!super::changed(&mut last, "b", &1));
    }

    #[test]
    fn path_segments_cover_the_path_and_join_end_to_start() {
        let path: Vec<[f32; 3]> = (0..250).map(|i| [i as f32, 0.0, 0.0]).collect();
        let segments: Vec<_> = (0..3).map(|k| super::trail_segment(&path, k)).collect();
        assert_eq!(segments.iter().map(Vec::len).collect::<Vec<_>>(), [101, 101, 50]);
        // Each segment starts where the previous one ended; together they are the path.
        let mut joined = segments[0].clone();
        for s in &segments[1..] {
            assert_eq!(s[0], *joined.last().unwrap());
            joined.extend_from_slice(&s[1..]);
        }
        assert_eq!(joined, path);
        assert!(super::trail_segment(&path, 3).is_empty());
    }

    #[test]
    fn both_recorders_take_each_shared_encoding_so_none_stays_pinned() {
        let dir = std::env::temp_dir().join(format!("dynaflow-rrd-cache-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let info = RunInfo {
            graph: "t".into(),
            variant: None,
            oracle: None,
            seed: 0,
            graph_yaml: String::new(),
            params: BTreeMap::new(),
            version: String::new(),
            git_commit: String::new(),
            realtime: false,
            ports: BTreeMap::new(),
            ground_truth_ports: Default::default(),
            cameras: BTreeMap::new(),
            machine: None,
            graph_digest: String::new(),
            decisions: Vec::new(),
            estimates: Vec::new(),
        };
        let cache = EncodeCache::new(2);
        let mut rrd = RrdSink::new(dir.join("t.rrd")).with_cache(cache.clone());
        let mut mcap = McapSink::new(dir.join("t.mcap")).with_cache(cache.clone());
        rrd.open(&info).unwrap();
        mcap.open(&info).unwrap();
        for seq in 0..3 {
            let header = Header { seq, stamp: seq as f64 / 30.0, frame_id: Arc::from("camera") };
            let depth = Arc::new(Message::new(
                header.clone(),
                Body::Depth(DepthImage { width: 4, height: 2, data: vec![1.25; 8] }),
            ));
            let rgb = Arc::new(Message::new(
                header,
                Body::Image(Image { width: 4, height: 2, format: PixelFormat::Rgb8, data: vec![90; 24] }),
            ));
            for m in [&depth, &rgb] {
                rrd.record("camera", "x", m).unwrap();
                mcap.record("camera", "x", m).unwrap();
            }
        }
        assert_eq!(cache.pending(), 0, "an encoding one recorder made was never taken by the other");
        rrd.close().unwrap();
        mcap.close().unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
