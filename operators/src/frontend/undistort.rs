//! `undistort`.

use dynaflow_engine::msg::{CameraInfo, DepthImage, Image, LensModel};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::params;
use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::undistort::{Lens, RemapTable};

params! {
    struct Config {
        /// the pinhole's focal lengths as a multiple of the lens's (principal point kept, same image size): below 1 keeps more of a fisheye's periphery, at lower resolution
        focal_scale: f64 [0.05, 20.0] = 1.0,
    }
}

const IMAGE: In<Image> = In::required("image", "the camera's image (RGB8 or grey)");
const CAMERA_INFO: In<CameraInfo> =
    In::required("camera_info", "the camera's lens: Brown-Conrady or Kannala-Brandt (fisheye)");
const DEPTH: In<DepthImage> = In::optional("depth", "depth registered to the image, resampled by the nearest pixel");
const RIGHT: In<Image> =
    In::optional("right", "a stereo pair's right image, same lens and orientation (undistorted with the same table)");
const IMAGE_OUT: Out<Image> = Out::new("image", "the image an ideal pinhole sees (black where the lens saw nothing)");
const CAMERA_INFO_OUT: Out<CameraInfo> = Out::new("camera_info", "the pinhole: no distortion");
const DEPTH_OUT: Out<DepthImage> = Out::new("depth", "the depth on the pinhole's pixels (with `depth`)");
const RIGHT_OUT: Out<Image> = Out::new("right", "the right image on the pinhole's pixels (with `right`)");

/// The `undistort` operator (its doc: `dynaflow ops undistort`).
pub const UNDISTORT: OpSpec = OpSpec::transform(
    "undistort",
    "frontend",
    dynaflow_engine::op::doc_line(include_str!("docs/undistort.md")),
    |p: &Params| {
        let c = Config::from_params(p)?;
        Ok(Instance::Transform(Box::new(Undistort { focal_scale: c.focal_scale, table: None })))
    },
)
.inputs(&[IMAGE.spec, CAMERA_INFO.spec, DEPTH.spec, RIGHT.spec])
.outputs(&[IMAGE_OUT.spec, CAMERA_INFO_OUT.spec, DEPTH_OUT.spec, RIGHT_OUT.spec])
.params(Config::PARAMS)
.cpu_heavy();

struct Undistort {
    focal_scale: f64,
    /// The table and the camera it was built for (rebuilt when the camera changes).
    table: Option<(CameraInfo, CameraInfo, RemapTable)>,
}

impl Undistort {
    /// The table and the pinhole for `k`.
    fn table(&mut self, k: &CameraInfo) -> &(CameraInfo, CameraInfo, RemapTable) {
        if self.table.as_ref().is_none_or(|(built, ..)| built != k) {
            let s = self.focal_scale;
            let new = CameraInfo {
                fx: k.fx * s,
                fy: k.fy * s,
                distortion: [0.0; 5],
                model: LensModel::BrownConrady,
                ..k.clone()
            };
            let table = RemapTable::undistort_rectify(
                &Lens::from_camera_info(k),
                &nalgebra::Matrix3::identity(),
                &Pinhole::from(&new),
                k.width as usize,
                k.height as usize,
            );
            self.table = Some((k.clone(), new, table));
        }
        self.table.as_ref().unwrap_or_else(|| unreachable!("set above"))
    }
}

/// That the `what` input (`width` x `height`, `len` `unit`s, `per_pixel` a pixel) is the
/// camera's size.
fn check_size(
    what: &str,
    (width, height): (u32, u32),
    (len, unit): (usize, &str),
    per_pixel: usize,
    k: &CameraInfo,
) -> Result<(), OpError> {
    if (width, height) != (k.width, k.height) || len != width as usize * height as usize * per_pixel {
        return Err(OpError::Input(format!(
            "`{what}` is {width}x{height} with {len} {unit}; `camera_info` is {}x{}",
            k.width, k.height
        )));
    }
    Ok(())
}

/// `image` through `table`, checked against the camera's size.
fn remap(table: &RemapTable, image: &Image, k: &CameraInfo, what: &str) -> Result<Image, OpError> {
    let (w, h) = (image.width as usize, image.height as usize);
    let channels = image.format.channels();
    check_size(what, (image.width, image.height), (image.data.len(), "bytes"), channels, k)?;
    let mut data = Vec::new();
    table.remap_u8(&image.data, w, h, channels, &mut data);
    Ok(Image { width: image.width, height: image.height, format: image.format, data })
}

impl Operator for Undistort {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, image) = IMAGE.require(inputs)?;
        let (_, k) = CAMERA_INFO.require(inputs)?;
        let (_, new, table) = self.table(k);
        let header = msg.header.clone();
        let mut out = Outputs::new().send(&IMAGE_OUT, header.clone(), remap(table, image, k, "image")?).send(
            &CAMERA_INFO_OUT,
            header.clone(),
            new.clone(),
        );
        if let Some(depth) = DEPTH.get(inputs)? {
            check_size("depth", (depth.width, depth.height), (depth.data.len(), "values"), 1, k)?;
            let (w, h) = (depth.width as usize, depth.height as usize);
            let mut data = Vec::new();
            table.remap_nearest(&depth.data, w, h, &mut data);
            out = out.send(&DEPTH_OUT, header.clone(), DepthImage { width: depth.width, height: depth.height, data });
        }
        if let Some(right) = RIGHT.get(inputs)? {
            out = out.send(&RIGHT_OUT, header, remap(table, right, k, "right")?);
        }
        Ok(out)
    }
}
