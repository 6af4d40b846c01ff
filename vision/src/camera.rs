//! The camera model: a pinhole with projection and unprojection, Brown-Conrady lens
//! distortion (OpenCV's `[k1, k2, p1, p2, k3]`) as hooks applied to normalised coordinates, and
//! the Kannala-Brandt (equidistant) fisheye model ([`KannalaBrandt`]: OpenCV's `fisheye`
//! module, ORB-SLAM3's `KannalaBrandt8`). Every crate that projects a point uses these.

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

/// The Kannala-Brandt fisheye model with four coefficients (Kannala and Brandt, "A generic
/// camera model and calibration method for conventional, wide-angle, and fish-eye lenses",
/// TPAMI 2006; OpenCV's `fisheye` module and ROS's `equidistant` use the same
/// parameterisation): a ray at angle `theta` from the optical axis lands at distance
/// `theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)` from the
/// principal point in normalised units, in the ray's azimuth; `theta` is measured with
/// `atan2`, so rays past 90 degrees off the axis project (pixels unproject to at most 90).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KannalaBrandt {
    /// Focal lengths and principal point.
    pub pinhole: Pinhole,
    /// `[k1, k2, k3, k4]`.
    pub k: [f64; 4],
}

/// Newton steps [`KannalaBrandt::unproject_normalised`] takes at most, and the step below which
/// it stops: OpenCV's `fisheye::undistortPoints` defaults (`TermCriteria(COUNT + EPS, 10, 1e-8)`).
const KB_MAX_STEPS: usize = 10;
const KB_STEP_EPS: f64 = 1e-8;

impl KannalaBrandt {
    /// A camera.
    pub const fn new(pinhole: Pinhole, k: [f64; 4]) -> Self {
        Self { pinhole, k }
    }

    /// The fisheye a camera-info message describes (its first four coefficients), or `None`
    /// for another lens model.
    pub fn from_camera_info(k: &dynaflow_msg::CameraInfo) -> Option<Self> {
        let [k1, k2, k3, k4, _] = k.distortion;
        (k.model == dynaflow_msg::LensModel::KannalaBrandt).then(|| Self::new(Pinhole::from(k), [k1, k2, k3, k4]))
    }

    /// `theta_d` of `theta` and its derivative.
    fn radius(&self, theta: f64) -> (f64, f64) {
        let [k1, k2, k3, k4] = self.k;
        let t2 = theta * theta;
        let poly = 1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)));
        let dpoly = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)));
        (theta * poly, dpoly)
    }

    /// Pixel of a point in the camera frame (`None` on the optical axis behind the camera,
    /// where the azimuth is undefined).
    pub fn project(&self, p: &Point3<f64>) -> Option<[f64; 2]> {
        let r = p.x.hypot(p.y);
        let Pinhole { fx, fy, cx, cy } = self.pinhole;
        if r < 1e-12 {
            return (p.z > 0.0).then_some([cx, cy]);
        }
        let (theta_d, _) = self.radius(r.atan2(p.z));
        Some([fx * theta_d * p.x / r + cx, fy * theta_d * p.y / r + cy])
    }

    /// `d(u, v) / d(x, y, z)` of [`project`](Self::project) at `p` (rows u, v), for
    /// Gauss-Newton and BA.
    pub fn project_jacobian(&self, p: &Point3<f64>) -> [[f64; 3]; 2] {
        let Pinhole { fx, fy, .. } = self.pinhole;
        let (x, y, z) = (p.x, p.y, p.z);
        let r2 = x * x + y * y;
        let r = r2.sqrt();
        if r < 1e-12 {
            // On the axis the model is a pinhole to first order.
            return [[fx / z, 0.0, 0.0], [0.0, fy / z, 0.0]];
        }
        let (theta_d, dtheta_d) = self.radius(r.atan2(z));
        let rho2 = r2 + z * z;
        let (a, b) = (dtheta_d * z / (r2 * rho2), theta_d / (r2 * r));
        [
            [fx * (a * x * x + b * y * y), fx * (a - b) * x * y, -fx * dtheta_d * x / rho2],
            [fy * (a - b) * x * y, fy * (a * y * y + b * x * x), -fy * dtheta_d * y / rho2],
        ]
    }

    /// The normalised pinhole coordinates (`x / z`, `y / z`) of the ray seen at pixel `uv`:
    /// `theta` solved from `theta_d` by Newton's method as OpenCV's
    /// `fisheye::undistortPoints` does (at most 10 steps, stopping below 1e-8; `theta_d`
    /// clamped to pi/2, as OpenCV and ORB-SLAM3 clamp it: a pixel is unprojected to at most
    /// 90 degrees off the axis).
    pub fn unproject_normalised(&self, uv: [f64; 2]) -> [f64; 2] {
        let (theta, [dx, dy], theta_d) = self.solve(uv);
        if theta_d == 0.0 {
            return [dx, dy];
        }
        let scale = theta.tan() / theta_d;
        [dx * scale, dy * scale]
    }

    /// The unit ray seen at pixel `uv` (at most 90 degrees off the axis, as
    /// [`unproject_normalised`](Self::unproject_normalised)).
    pub fn bearing(&self, uv: [f64; 2]) -> nalgebra::Vector3<f64> {
        let (theta, [dx, dy], theta_d) = self.solve(uv);
        if theta_d == 0.0 {
            return nalgebra::Vector3::z();
        }
        let s = theta.sin() / theta_d;
        nalgebra::Vector3::new(dx * s, dy * s, theta.cos())
    }

    /// The point at depth `z` (along the optical axis) seen at pixel `uv`.
    pub fn unproject(&self, uv: [f64; 2], z: f64) -> Point3<f64> {
        let [x, y] = self.unproject_normalised(uv);
        Point3::new(x * z, y * z, z)
    }

    /// `(theta, distorted normalised point, theta_d)` of a pixel.
    fn solve(&self, uv: [f64; 2]) -> (f64, [f64; 2], f64) {
        let [dx, dy] = self.pinhole.normalised(uv);
        let theta_d = dx.hypot(dy).clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
        let mut theta = theta_d;
        if theta_d > KB_STEP_EPS {
            for _ in 0..KB_MAX_STEPS {
                let (f, df) = self.radius(theta);
                let step = (f - theta_d) / df;
                theta -= step;
                if step.abs() < KB_STEP_EPS {
                    break;
                }
            }
        }
        (theta, [dx, dy], theta_d)
    }
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

    #[test]
    fn kannala_brandt_round_trips_and_its_jacobian_is_the_derivative() {
        // TUM-VI cam0's published equidistant calibration (Schubert et al., IROS 2018).
        let cam = KannalaBrandt::new(
            Pinhole::new(190.978_477, 190.973_307, 254.931_706, 256.897_443),
            [0.003_482_389, 0.000_715_034, -0.002_053_236, 0.000_202_936],
        );
        for p in [
            Point3::new(0.3, -0.2, 1.0),
            Point3::new(-1.5, 0.8, 0.6),
            Point3::new(0.0, 0.0, 2.0),
            Point3::new(2.0, 1.0, -0.2),
        ] {
            let uv = cam.project(&p).unwrap_or_default();
            // Unprojection reaches 90 degrees (OpenCV's and ORB-SLAM3's clamp); projection
            // goes past it.
            if p.z > 0.0 {
                let b = cam.bearing(uv);
                assert!((b - p.coords.normalize()).norm() < 1e-9, "{p} -> {uv:?} -> {b}");
                let q = cam.unproject(uv, p.z);
                assert!((q - p).norm() < 1e-9, "{p} -> {q}");
            }
            let j = cam.project_jacobian(&p);
            for axis in 0..3 {
                let mut d = nalgebra::Vector3::zeros();
                d[axis] = 1e-6;
                let (a, b) = (cam.project(&(p + d)).unwrap_or_default(), cam.project(&(p - d)).unwrap_or_default());
                for row in 0..2 {
                    let numeric = (a[row] - b[row]) / 2e-6;
                    assert!(
                        (numeric - j[row][axis]).abs() < 1e-5 * (1.0 + numeric.abs()),
                        "{p} d{row}/d{axis}: {numeric} vs {}",
                        j[row][axis]
                    );
                }
            }
        }
        assert!(cam.project(&Point3::new(0.0, 0.0, -1.0)).is_none());
    }
}
