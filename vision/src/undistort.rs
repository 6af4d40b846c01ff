//! Undistortion and rectification of whole images: a per-pixel lookup table from an ideal
//! pinhole camera into a distorted (Brown-Conrady) or fisheye (Kannala-Brandt) one, and the
//! resampling through it. What OpenCV's `initUndistortRectifyMap` /
//! `fisheye::initUndistortRectifyMap` and `remap` do, to their definitions: the table in
//! single-precision pixels (`CV_32FC1` maps), colour resampled bilinearly in single precision
//! as OpenCV 4.11 and later do (a constant black border), depth by the nearest pixel
//! (interpolating depth across an object's edge invents surfaces).
//! Compared with OpenCV in `vision/tests/frontend.rs`.
//!
//! ORB-SLAM2 runs on images rectified this way (its stereo examples remap EuRoC's pairs with
//! `cv::remap`); dynaflow's `undistort` operator puts a fisheye or distorted camera in front of
//! every operator that projects through a pinhole.

use nalgebra::{Matrix3, Point3};

use crate::camera::{KannalaBrandt, Pinhole, distort};

/// A real lens: where a ray in the camera frame lands in the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lens {
    /// A pinhole with OpenCV's Brown-Conrady distortion `[k1, k2, p1, p2, k3]`.
    BrownConrady {
        /// Focal lengths and principal point.
        pinhole: Pinhole,
        /// `[k1, k2, p1, p2, k3]`.
        k: [f64; 5],
    },
    /// A Kannala-Brandt (equidistant) fisheye.
    KannalaBrandt(KannalaBrandt),
}

impl Lens {
    /// The lens of a camera-info message.
    pub fn from_camera_info(k: &dynaflow_msg::CameraInfo) -> Self {
        KannalaBrandt::from_camera_info(k)
            .map_or_else(|| Self::BrownConrady { pinhole: Pinhole::from(k), k: k.distortion }, Self::KannalaBrandt)
    }

    /// Pixel of a point in the camera frame, as OpenCV's map builders compute it for a point
    /// in front of the camera (`None` behind it, or on the axis behind it for a fisheye).
    pub fn project(&self, p: &Point3<f64>) -> Option<[f64; 2]> {
        match self {
            Self::BrownConrady { pinhole, k } => {
                if p.z <= 0.0 {
                    return None;
                }
                let [x, y] = distort(k, [p.x / p.z, p.y / p.z]);
                Some([pinhole.fx * x + pinhole.cx, pinhole.fy * y + pinhole.cy])
            }
            Self::KannalaBrandt(kb) => kb.project(p),
        }
    }
}

/// Where each pixel of an ideal pinhole image comes from in the real camera's image.
#[derive(Clone, Debug, PartialEq)]
pub struct RemapTable {
    /// Output columns.
    pub width: usize,
    /// Output rows.
    pub height: usize,
    /// Source pixel `(x, y)` of each output pixel, row-major (NaN where the ray has no
    /// image: behind a fisheye's axis).
    pub map: Vec<[f32; 2]>,
}

impl RemapTable {
    /// The table of a `width` x `height` pinhole camera `new` whose frame is rotated by
    /// `rect_from_cam` from the real camera's (the identity to undistort only; a stereo
    /// rectification's rotation otherwise), looking through `lens`: OpenCV's
    /// `initUndistortRectifyMap(K, D, R, P)` and its fisheye twin with `P = new`,
    /// `R = rect_from_cam`.
    pub fn undistort_rectify(
        lens: &Lens,
        rect_from_cam: &Matrix3<f64>,
        new: &Pinhole,
        width: usize,
        height: usize,
    ) -> Self {
        let cam_from_rect = rect_from_cam.transpose();
        let mut map = Vec::with_capacity(width * height);
        for v in 0..height {
            for u in 0..width {
                let [x, y] = new.normalised([u as f64, v as f64]);
                let p = Point3::from(cam_from_rect * nalgebra::Vector3::new(x, y, 1.0));
                map.push(match lens.project(&p) {
                    Some([sx, sy]) => [sx as f32, sy as f32],
                    None => [f32::NAN; 2],
                });
            }
        }
        Self::from_map(width, height, map)
    }

    /// A table from explicit source coordinates (`map.len() == width * height`).
    pub fn from_map(width: usize, height: usize, map: Vec<[f32; 2]>) -> Self {
        Self { width, height, map }
    }

    /// Resample an interleaved 8-bit image of `channels` channels (`src_width` x `src_height`)
    /// bilinearly through the table into `dst` (resized to the table's size); source pixels
    /// outside the image count as black, as OpenCV's `BORDER_CONSTANT`. In single precision
    /// as OpenCV (since 4.11) interpolates: along the row, then between the rows, rounded
    /// half to even.
    pub fn remap_u8(&self, src: &[u8], src_width: usize, src_height: usize, channels: usize, dst: &mut Vec<u8>) {
        dst.clear();
        dst.resize(self.width * self.height * channels, 0);
        if src.len() < src_width * src_height * channels || channels == 0 {
            return;
        }
        let (sw, sh) = (src_width as i64, src_height as i64);
        let pixel = |x: i64, y: i64, c: usize| -> f32 {
            if (0..sw).contains(&x) && (0..sh).contains(&y) {
                f32::from(src[(y as usize * src_width + x as usize) * channels + c])
            } else {
                0.0
            }
        };
        for (i, &[mx, my]) in self.map.iter().enumerate() {
            if !(mx.is_finite() && my.is_finite()) {
                continue;
            }
            let (fx, fy) = (mx.floor(), my.floor());
            let (ax, ay) = (mx - fx, my - fy);
            // Far outside (and beyond any integer): black.
            if !(-2.0..=sw as f32 + 1.0).contains(&fx) || !(-2.0..=sh as f32 + 1.0).contains(&fy) {
                continue;
            }
            let (x, y) = (fx as i64, fy as i64);
            for c in 0..channels {
                let (p00, p01, p10, p11) =
                    (pixel(x, y, c), pixel(x + 1, y, c), pixel(x, y + 1, c), pixel(x + 1, y + 1, c));
                let top = p00 + ax * (p01 - p00);
                let bottom = p10 + ax * (p11 - p10);
                dst[i * channels + c] = (top + ay * (bottom - top)).round_ties_even().clamp(0.0, 255.0) as u8;
            }
        }
    }

    /// Resample a depth image by the nearest source pixel (0 outside it, and where the
    /// source has no measurement).
    pub fn remap_nearest(&self, src: &[f32], src_width: usize, src_height: usize, dst: &mut Vec<f32>) {
        dst.clear();
        dst.resize(self.width * self.height, 0.0);
        if src.len() < src_width * src_height {
            return;
        }
        for (d, &[x, y]) in dst.iter_mut().zip(&self.map) {
            // OpenCV's INTER_NEAREST: `saturate_cast<int>` of the coordinate (round half even).
            let (x, y) = (x.round_ties_even(), y.round_ties_even());
            if x >= 0.0 && y >= 0.0 && (x as usize) < src_width && (y as usize) < src_height {
                *d = src[y as usize * src_width + x as usize];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lens_without_distortion_maps_each_pixel_to_itself() {
        let pinhole = Pinhole::new(500.0, 480.0, 31.5, 23.5);
        let t = RemapTable::undistort_rectify(
            &Lens::BrownConrady { pinhole, k: [0.0; 5] },
            &Matrix3::identity(),
            &pinhole,
            64,
            48,
        );
        let src: Vec<u8> = (0..64 * 48 * 3).map(|i| (i * 7 % 251) as u8).collect();
        let mut dst = Vec::new();
        t.remap_u8(&src, 64, 48, 3, &mut dst);
        assert_eq!(dst, src);
        let depth: Vec<f32> = (0..64 * 48).map(|i| i as f32 * 0.01).collect();
        let mut out = Vec::new();
        t.remap_nearest(&depth, 64, 48, &mut out);
        assert_eq!(out, depth);
    }

    #[test]
    fn a_fisheye_table_inverts_the_lens() {
        // An undistorted pixel's source, unprojected through the fisheye, is the pinhole ray.
        let kb = KannalaBrandt::new(Pinhole::new(300.0, 300.0, 320.0, 240.0), [0.0035, 0.0007, -0.0021, 0.0002]);
        let new = Pinhole::new(300.0, 300.0, 320.0, 240.0);
        let t = RemapTable::undistort_rectify(&Lens::KannalaBrandt(kb), &Matrix3::identity(), &new, 640, 480);
        for (u, v) in [(0usize, 0usize), (639, 479), (100, 400), (320, 240)] {
            let [sx, sy] = t.map[v * 640 + u];
            let n = kb.unproject_normalised([f64::from(sx), f64::from(sy)]);
            let want = new.normalised([u as f64, v as f64]);
            assert!((n[0] - want[0]).abs() < 1e-4 && (n[1] - want[1]).abs() < 1e-4, "{u},{v}: {n:?} vs {want:?}");
        }
        // The bilinear weights interpolate: a horizontal ramp stays a ramp at the centre.
        let src: Vec<u8> = (0..640 * 480).map(|i| ((i % 640) / 3) as u8).collect();
        let mut dst = Vec::new();
        t.remap_u8(&src, 640, 480, 1, &mut dst);
        let [sx, _] = t.map[240 * 640 + 330];
        assert!((f32::from(dst[240 * 640 + 330]) - sx / 3.0).abs() <= 1.0);
    }
}
