//! The crate's one error type: parameters that cannot make a tree, a scan the memory budget
//! refuses, an octree file that cannot be read or written.

/// What can go wrong building a tree, inserting a scan, or reading and writing a file.
#[derive(Clone, Debug, thiserror::Error, PartialEq)]
pub enum Error {
    /// Parameters that cannot make a tree ([`crate::Params::check`]).
    #[error("{0}")]
    Params(String),
    /// The scan would take the tree's nodes plus its own scratch past
    /// [`crate::Params::max_memory_bytes`]; the tree is as it was before the call.
    #[error(
        "the scan's rays cross up to {voxels} voxels and need {:.0} MiB on top of the map's {:.0} MiB, over the {:.0} MiB memory budget",
        mib(*scan_bytes), mib(*tree_bytes), mib(*budget)
    )]
    OverBudget {
        /// Upper bound on the voxels its rays cross (visits, before de-duplication).
        voxels: u64,
        /// Bytes the tree's nodes hold now.
        tree_bytes: u64,
        /// Bytes the scan needs: scratch, plus (when known) the nodes it would add.
        scan_bytes: u64,
        /// The budget.
        budget: u64,
    },
    /// The system refused memory within the budget; the tree is as it was before the call.
    #[error("the system refused {:.0} MiB for the scan", mib(*bytes))]
    Alloc {
        /// Bytes asked for.
        bytes: u64,
    },
    /// Cannot read or write the file.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        message: String,
    },
    /// Not an OctoMap file, or a corrupt or truncated one.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
}

fn mib(b: u64) -> f64 {
    b as f64 / (1u64 << 20) as f64
}
