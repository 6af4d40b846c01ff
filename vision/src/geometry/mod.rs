//! Two-view geometry for culling dynamic points: the fundamental matrix from point
//! correspondences and its robust estimation.
//!
//! - `fundamental`: Hartley normalisation, the 8-point and 7-point solvers, epipolar
//!   distances.
//! - `homography`: the 4-point normalised DLT, fitted by PROSAC (samples from the
//!   best-ranked correspondences first), for camera-motion compensation.
//! - `p3p`: the minimal absolute-pose solver (Lambda Twist's construction), up to four poses.
//! - `pose`: PnP (P3P inside RANSAC, 6-point DLT for refits) and motion-only bundle adjustment
//!   (Levenberg-Marquardt on SE(3), Huber kernel, ORB-SLAM's four re-classification rounds).
//! - `ransac`: the one RANSAC driver ([`Estimator`], [`Sampler`]: uniform or PROSAC,
//!   [`RansacConfig`], [`Consensus`]): MSAC-scored LO-RANSAC with the adaptive stopping rule,
//!   deterministic from a seed; F, H, P3P (and loop closing's SE(3)) are its estimators.

mod fundamental;
mod homography;
mod model_selection;
mod p3p;
mod pose;
mod ransac;
mod two_view;

pub use fundamental::{
    FundamentalEstimator, FundamentalFit, eight_point, epipolar_distance, epipolar_error, fit_fundamental, seven_point,
};
pub use homography::{
    HomographyEstimator, HomographyFit, fit_homography_prosac, homography_dlt, transfer, transfer_error,
};
pub use model_selection::{
    CHI2_1DOF, CHI2_2DOF, HOMOGRAPHY_RATIO, fundamental_score, homography_ratio, homography_score,
};
pub use p3p::p3p;
pub use pose::{
    CHI2_2DOF_95, CHI2_3DOF_95, LmDamping, PoseFit, PoseObservation, bearing, compose, exp_se3, huber,
    observation_jacobian, optimize_pose, p3p_ransac, pnp_dlt, pnp_ransac, refine_pose, renormalised,
};
pub use ransac::{Consensus, Estimator, Prosac, RansacConfig, Sampler, SplitMix64, needed, ransac};
pub use two_view::{
    InitFailure, TwoViewConfig, TwoViewInit, TwoViewModel, decompose_essential, decompose_homography, initialise,
    triangulate,
};

/// A 3x3 matrix, row-major, `x2^T F x1 = 0` for homogeneous pixel coordinates.
pub type Mat3 = nalgebra::Matrix3<f64>;
