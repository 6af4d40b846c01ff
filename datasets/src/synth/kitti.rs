//! Writing a generated stereo sequence in the KITTI odometry layout, read back by
//! `kitti_odometry` (and by any KITTI tool): `ROOT/sequences/00/` with `image_2/` and
//! `image_3/` (the left and right colour cameras, `000000.png` ...), `calib.txt` (`P0`..`P3`,
//! rectified projection matrices whose right ones carry `-fx * baseline`), `times.txt`
//! (seconds from the first frame), and `ROOT/poses/00.txt` (per frame the left camera's pose in the first left
//! camera's frame, a row-major 3x4 matrix). The generator's exact depth and masks are not part
//! of KITTI odometry and are not written (write the TUM layout for those).

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use image::ExtendedColorType;

use super::Generator;
use super::tum::png;
use crate::Error;

/// What to write.
#[derive(Clone, Debug)]
pub struct KittiWriteOptions {
    /// Number of frames.
    pub frames: u64,
    /// Stereo baseline, metres (the right camera sits this far to the left camera's right).
    pub baseline: f64,
}

/// Write `opts.frames` stereo frames of `generator` under `root` in the KITTI odometry layout;
/// returns the sequence folder (`root/sequences/00`, what `--input` takes).
pub fn write_kitti(generator: &Generator, root: &Path, opts: &KittiWriteOptions) -> Result<PathBuf, Error> {
    if !(opts.baseline > 0.0 && opts.baseline.is_finite()) {
        return Err(Error::file(root, format!("a stereo baseline must be positive, not {}", opts.baseline)));
    }
    let c = generator.config();
    let k = &c.intrinsics;
    if k.model == dynaflow_msg::LensModel::KannalaBrandt {
        return Err(Error::file(
            root,
            "the KITTI layout holds rectified pinhole images; a fisheye sequence is written as `tum` or `euroc`",
        ));
    }
    let seq = root.join("sequences").join("00");
    for sub in ["image_2", "image_3"] {
        fs::create_dir_all(seq.join(sub)).map_err(|e| Error::file(&seq.join(sub), e))?;
    }
    let poses_dir = root.join("poses");
    fs::create_dir_all(&poses_dir).map_err(|e| Error::file(&poses_dir, e))?;
    let (mut times, mut poses) = (String::new(), String::new());
    let mut first_from_world = None;
    let mut first_stamp = None;
    for i in 0..opts.frames {
        let f = generator.frame(i, false);
        let right = generator.right(&f, opts.baseline).unwrap_or_default();
        let name = format!("{i:06}.png");
        png(&seq.join("image_2").join(&name), &f.rgb, k.width, k.height, ExtendedColorType::Rgb8)?;
        png(&seq.join("image_3").join(&name), &right, k.width, k.height, ExtendedColorType::Rgb8)?;
        // KITTI's times count from the first frame.
        let _ = writeln!(times, "{:.6e}", f.stamp - *first_stamp.get_or_insert(f.stamp));
        let inv = *first_from_world.get_or_insert_with(|| f.world_from_cam.inverse());
        let p = inv * f.world_from_cam;
        let (r, t) = (p.rotation.to_rotation_matrix(), p.translation.vector);
        let m = r.matrix();
        let _ = writeln!(
            poses,
            "{:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e} {:.9e}",
            m[(0, 0)],
            m[(0, 1)],
            m[(0, 2)],
            t.x,
            m[(1, 0)],
            m[(1, 1)],
            m[(1, 2)],
            t.y,
            m[(2, 0)],
            m[(2, 1)],
            m[(2, 2)],
            t.z
        );
    }
    // KITTI's calib.txt: P0/P1 grey, P2/P3 colour; here both pairs are the same cameras.
    let p = |tx: f64| format!("{:.12e} 0 {:.12e} {:.12e} 0 {:.12e} {:.12e} 0 0 0 1 0", k.fx, k.cx, tx, k.fy, k.cy);
    let right_tx = -k.fx * opts.baseline;
    let calib = format!(
        "P0: {}\nP1: {}\nP2: {}\nP3: {}\nTr: 1 0 0 0 0 1 0 0 0 0 1 0\n",
        p(0.0),
        p(right_tx),
        p(0.0),
        p(right_tx)
    );
    for (path, text) in
        [(seq.join("calib.txt"), calib), (seq.join("times.txt"), times), (poses_dir.join("00.txt"), poses)]
    {
        fs::write(&path, text).map_err(|e| Error::file(&path, e))?;
    }
    Ok(seq)
}
