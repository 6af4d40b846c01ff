//! dynaflow's OctoMap: a probabilistic occupancy octree faithful to OctoMap 1.9, as a plain
//! library with no engine dependency (the `octomap` operator is a thin wrapper).
//!
//! - [`key`]: voxel keys (`floor(x / res) + 32768`, depth 16) and OctoMap's 3-D DDA ray
//!   traversal, precision for precision.
//! - [`tree`]: [`OcTree`], log-odds hit/miss updates with clamping, batch scan insertion
//!   (`insertPointCloud`: each voxel updated once per scan, end points win over free space),
//!   pruning and expansion, colour and class per voxel, queries (occupancy at a point, ray
//!   cast), leaves.
//! - [`io`]: OctoMap's `.bt` (binary: two bits per child, maximum likelihood) and `.ot`
//!   (full: log-odds per node, colour for ColorOcTree) files, read and written byte for byte
//!   as OctoMap does; corrupt or truncated files are errors, never panics.
//! - [`Error`]: the crate's one error type (parameters, memory budget, files).

#![warn(missing_docs)]

mod error;
pub mod io;
pub mod key;
pub mod tree;

pub use error::Error;
pub use io::{read, write_bt, write_ot};
pub use key::{Grid, Key};
pub use tree::{Label, Leaf, Node, OcTree, Params, RayHit, logodds, probability};
