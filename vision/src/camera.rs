//! The camera model: a pinhole with projection and unprojection, and Brown-Conrady lens
//! distortion (OpenCV's `[k1, k2, p1, p2, k3]`) as hooks applied to normalised coordinates.
//! Every crate that projects a point uses this one type.

use nalgebra::Point3;

/// A pinhole camera: focal lengths and principal point in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pinhole {
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
}

impl Pinhole {
    /// A camera.
    pub const fn new(fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self { fx, fy, cx, cy }
    }
    /// Pixel of a point in the camera frame (`None` behind the camera).
    pub fn project(&self, p: &Point3<f64>) -> Option<[f64; 2]> {
        (p.z > 1e-9).then(|| [self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy])
    }
    /// The point at depth `z` (along the optical axis) seen at pixel `uv`.
    pub fn unproject(&self, uv: [f64; 2], z: f64) -> Point3<f64> {
        let [x, y] = self.normalised(uv);
        Point3::new(x * z, y * z, z)
    }
    /// Normalised image coordinates of a pixel (`z = 1` plane).
    pub fn normalised(&self, uv: [f64; 2]) -> [f64; 2] {
        [(uv[0] - self.cx) / self.fx, (uv[1] - self.cy) / self.fy]
    }
    /// This camera for an image `sx` times as wide and `sy` times as high.
    pub fn scaled(&self, sx: f64, sy: f64) -> Self {
        Self { fx: self.fx * sx, fy: self.fy * sy, cx: self.cx * sx, cy: self.cy * sy }
    }
}

impl From<&dynaflow_msg::CameraInfo> for Pinhole {
    /// The projection of a camera-info message (its distortion is applied separately, by
    /// [`distort`] and [`undistort`] on normalised coordinates).
    fn from(k: &dynaflow_msg::CameraInfo) -> Self {
        Self::new(k.fx, k.fy, k.cx, k.cy)
    }
}

/// Brown-Conrady distortion of normalised coordinates, OpenCV's model and coefficient order
/// `[k1, k2, p1, p2, k3]`.
pub fn distort(k: &[f64; 5], xn: [f64; 2]) -> [f64; 2] {
    let [k1, k2, p1, p2, k3] = *k;
    let [x, y] = xn;
    let r2 = x * x + y * y;
    let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    [x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x), y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y]
}

/// The normalised coordinates that [`distort`] maps to `xd`, by the iteration OpenCV's
/// `undistortPoints` runs (its default: 5 rounds): remove the tangential term at the current
/// estimate, divide by the radial factor there. Compared with OpenCV in
/// `vision/tests/frontend.rs`.
pub fn undistort(k: &[f64; 5], xd: [f64; 2]) -> [f64; 2] {
    let [k1, k2, p1, p2, k3] = *k;
    let [mut x, mut y] = xd;
    for _ in 0..5 {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        x = (xd[0] - dx) / radial;
        y = (xd[1] - dy) / radial;
    }
    [x, y]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_and_unprojection_are_inverse() {
        let cam = Pinhole::new(535.4, 539.2, 320.1, 247.6);
        let p = cam.unproject([100.0, 400.0], 2.5);
        let uv = cam.project(&p).unwrap_or_default();
        assert!((uv[0] - 100.0).abs() < 1e-9 && (uv[1] - 400.0).abs() < 1e-9 && (p.z - 2.5).abs() < 1e-12);
        assert!(cam.project(&Point3::new(0.0, 0.0, -1.0)).is_none());
        assert_eq!(cam.scaled(0.5, 0.5), Pinhole::new(267.7, 269.6, 160.05, 123.8));
    }

    #[test]
    fn undistortion_inverts_distortion_for_a_kinect_lens() {
        // TUM fr1's published coefficients, at the image corner and the centre.
        let k = [0.2624, -0.9531, -0.0054, 0.0026, 1.1633];
        for xn in [[0.0, 0.0], [0.3, -0.2], [-0.55, 0.45]] {
            let back = undistort(&k, distort(&k, xn));
            // OpenCV's five rounds leave under 1e-5 (0.005 px at f = 500) at the image corner.
            assert!((back[0] - xn[0]).abs() < 1e-5 && (back[1] - xn[1]).abs() < 1e-5, "{xn:?} -> {back:?}");
        }
        assert_eq!(distort(&[0.0; 5], [0.3, 0.2]), [0.3, 0.2]);
    }
}
