//! Two-view geometry for culling dynamic points: the fundamental matrix from point
//! correspondences and its robust estimation.
//!
//! - `fundamental`: Hartley normalisation, the 8-point and 7-point solvers, epipolar
//!   distances.
//! - `homography`: the 4-point normalised DLT and PROSAC (samples from the best-ranked
//!   correspondences first), for camera-motion compensation.
//! - `p3p`: the minimal absolute-pose solver (Lambda Twist's construction), up to four poses.
//! - `pose`: PnP (P3P inside RANSAC, 6-point DLT for refits) and motion-only bundle adjustment
//!   (Levenberg-Marquardt on SE(3), Huber kernel, ORB-SLAM's four re-classification rounds).
//! - `ransac`: adaptive RANSAC over the 7-point solver with a local-optimisation step
//!   (LO-RANSAC: refit on the inliers of each new best model), deterministic from a seed.

mod fundamental;
mod homography;
mod model_selection;
mod p3p;
mod pose;
mod ransac;
mod two_view;

pub use fundamental::{eight_point, epipolar_distance, epipolar_error, seven_point};
pub use homography::{HomographyFit, fit_homography_prosac, homography_dlt, transfer, transfer_error};
pub use model_selection::{
    CHI2_1DOF, CHI2_2DOF, HOMOGRAPHY_RATIO, fundamental_score, homography_ratio, homography_score,
};
pub use p3p::p3p;
pub use pose::{
    CHI2_2DOF_95, CHI2_3DOF_95, PoseFit, PoseObservation, bearing, compose, exp_se3, observation_jacobian,
    optimize_pose, p3p_ransac, pnp_dlt, pnp_ransac, refine_pose, renormalised,
};
pub use ransac::{FundamentalFit, RansacConfig, SplitMix64, fit_fundamental};
pub use two_view::{
    InitFailure, TwoViewConfig, TwoViewInit, TwoViewModel, decompose_essential, decompose_homography, initialise,
    triangulate,
};

/// A 3x3 matrix, row-major, `x2^T F x1 = 0` for homogeneous pixel coordinates.
pub type Mat3 = nalgebra::Matrix3<f64>;
