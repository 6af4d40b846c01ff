//! dynaflow's geometric front-end: ORB features, descriptor matching and pyramidal
//! Lucas-Kanade optical flow, as plain functions and structs on grey image buffers.
//!
//! - [`camera`]: the camera model (pinhole projection and unprojection, lens distortion).
//! - [`image`]: the grey image buffer, RGB conversion, resampling.
//! - [`orb`]: ORB-SLAM-style extraction (pyramid, FAST per cell, quadtree distribution,
//!   intensity-centroid orientation, rotated BRIEF with the learned pattern).
//! - [`matching`]: Hamming brute force (ratio test, cross-check, rotation histogram) and a
//!   guided window search.
//! - [`flow`]: pyramidal LK (Scharr gradients, minimum-eigenvalue rejection,
//!   forward-backward check) and a corner detector for re-seeding tracks.
//! - [`stereo`]: ORB-SLAM2's sparse stereo matching of ORB keypoints on a rectified pair.
//! - [`undistort`]: whole-image undistortion and rectification (OpenCV's
//!   `initUndistortRectifyMap` and `remap`), pinhole or fisheye lens to an ideal pinhole.
//! - [`geometry`]: the fundamental matrix (7- and 8-point solvers, LO-RANSAC) and epipolar
//!   distances, for culling points that move.
//!
//! No engine, tokio or image-codec dependency (nalgebra for the small linear algebra): a user can call it directly, and the
//! benchmarks call exactly what dynaflow's operators call.

#![warn(missing_docs)]

pub mod camera;
pub mod flow;
pub mod geometry;
pub mod image;
pub mod matching;
pub mod orb;
pub mod stereo;
pub mod undistort;

pub use image::GrayImage;
