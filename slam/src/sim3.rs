//! Similarity transforms (rotation, translation and scale): what a monocular map's loop
//! correction needs, as its scale drifts (ORB-SLAM2's `g2o::Sim3`).

use std::ops::Mul;

use nalgebra::{Isometry3, Point3, SVector, Translation3, UnitQuaternion, Vector3};

/// `x -> scale * rotation * x + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sim3 {
    /// Rotation.
    pub rotation: UnitQuaternion<f64>,
    /// Translation (the image of the origin).
    pub translation: Vector3<f64>,
    /// Scale, > 0.
    pub scale: f64,
}

impl Sim3 {
    /// The identity.
    pub fn identity() -> Self {
        Self { rotation: UnitQuaternion::identity(), translation: Vector3::zeros(), scale: 1.0 }
    }

    /// A rigid transform, scale 1.
    pub fn from_isometry(t: &Isometry3<f64>) -> Self {
        Self { rotation: t.rotation, translation: t.translation.vector, scale: 1.0 }
    }

    /// The rigid part (rotation and translation; the scale dropped).
    pub fn rigid(&self) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(self.translation), self.rotation)
    }

    /// Apply to a point.
    pub fn transform_point(&self, p: &Point3<f64>) -> Point3<f64> {
        Point3::from(self.scale * (self.rotation * p.coords) + self.translation)
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Self {
        let rotation = self.rotation.inverse();
        let scale = 1.0 / self.scale;
        Self { rotation, translation: -(scale * (rotation * self.translation)), scale }
    }

    /// `(translation, rotation vector, ln scale)`: zero at the identity (the residual of a
    /// pose-graph edge, as [`crate::pose_graph`]'s SE(3) one with the scale's logarithm added).
    pub fn log7(&self) -> SVector<f64, 7> {
        let (t, r) = (self.translation, self.rotation.scaled_axis());
        SVector::<f64, 7>::from_column_slice(&[t.x, t.y, t.z, r.x, r.y, r.z, self.scale.ln()])
    }

    /// The increment `(translation, rotation vector, ln scale)` as a transform (the inverse of
    /// [`Sim3::log7`]).
    pub fn exp7(d: &SVector<f64, 7>) -> Self {
        Self {
            rotation: UnitQuaternion::from_scaled_axis(Vector3::new(d[3], d[4], d[5])),
            translation: Vector3::new(d[0], d[1], d[2]),
            scale: d[6].exp(),
        }
    }
}

impl Mul for Sim3 {
    type Output = Sim3;
    /// `(a * b)(x) = a(b(x))`.
    fn mul(self, b: Sim3) -> Sim3 {
        let mut rotation = self.rotation * b.rotation;
        rotation.renormalize();
        Sim3 {
            rotation,
            translation: self.scale * (self.rotation * b.translation) + self.translation,
            scale: self.scale * b.scale,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Sim3 {
        Sim3 {
            rotation: UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1),
            translation: Vector3::new(0.5, -1.0, 2.0),
            scale: 1.7,
        }
    }

    #[test]
    fn composition_inverse_and_log_agree_with_their_definitions() {
        let (a, b) = (sample(), Sim3 { scale: 0.6, ..Sim3::from_isometry(&Isometry3::translation(1.0, 2.0, 3.0)) });
        let p = Point3::new(0.2, -0.4, 1.5);
        let direct = a.transform_point(&b.transform_point(&p));
        assert!(((a * b).transform_point(&p) - direct).norm() < 1e-12);
        assert!(((a.inverse() * a).transform_point(&p) - p).norm() < 1e-12);
        assert!((a.inverse().transform_point(&a.transform_point(&p)) - p).norm() < 1e-12);
        let back = Sim3::exp7(&a.log7());
        assert!((back.transform_point(&p) - a.transform_point(&p)).norm() < 1e-12);
        assert!(Sim3::identity().log7().norm() == 0.0);
        // The rigid part is the transform at scale 1.
        let r = a.rigid();
        assert!(((r * p) - Sim3 { scale: 1.0, ..a }.transform_point(&p)).norm() < 1e-12);
    }
}
