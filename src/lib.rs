//! The `dynaflow` package: the CLI binary (`src/main.rs`) and this small library that wires
//! the crates together, so tests and benches see exactly the operators the CLI sees.

#![warn(missing_docs)]

use dynaflow_engine::op::Registry;

pub mod cli;
pub mod summary;

/// Every operator dynaflow ships: the `dynaflow-operators` families plus the recording-backed
/// sources of `dynaflow-recordings` (`mcap_replay`).
pub fn registry() -> Registry {
    let mut r = dynaflow_operators::registry();
    dynaflow_recordings::register(&mut r);
    r.register(dynaflow_python::PYTHON);
    r
}

/// The allocator of every program built on this library (the CLI, its tests and benches):
/// jemalloc, configured by [`JEMALLOC_CONF`].
///
/// A recorded run allocates and frees image-sized buffers (300 KB-1.2 MB a port a frame) on
/// a dozen threads. glibc's malloc kept that in bounded memory only with its mmap threshold
/// pinned (each such buffer a fresh, page-by-page zero-filled mapping: recording then cost
/// 1.20x the run without it) and `malloc_trim` once a second (the free pages between live
/// blocks of its arenas otherwise stayed resident and grew with the run). jemalloc hands
/// back unused pages itself, from a background thread, and reuses size classes without that
/// cost; measured when chosen (docs/recordings.md, "Long runs in bounded memory"). Not on MSVC, which jemalloc does
/// not build for, and not in the Python package (feature `jemalloc` off: the host's allocator).
#[cfg(all(feature = "jemalloc", not(target_env = "msvc")))]
#[global_allocator]
static GLOBAL: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

/// jemalloc's options (read before `main`; `_RJEM_MALLOC_CONF` in the environment overrides
/// them): purge from a background thread rather than on the threads that free, and hand
/// dirty pages back after 100 ms instead of jemalloc's default 10 s. With the default, the
/// pages freed over 10 s of a run (10 s of image buffers) stay resident: 280 MB peak at 1 000
/// recorded frames, against 235 MB with 100 ms; purging at once (0 ms) on the freeing threads
/// made the run 35 % slower.
#[cfg(all(feature = "jemalloc", not(target_env = "msvc")))]
#[allow(unsafe_code)]
// SAFETY: jemalloc reads this symbol as a `const char *` to a NUL-terminated string, which
// `Option<&c_char>` has the layout of; the string is static.
#[unsafe(export_name = "_rjem_malloc_conf")]
pub static JEMALLOC_CONF: Option<&'static std::ffi::c_char> =
    Some(unsafe { &*c"background_thread:true,dirty_decay_ms:100".as_ptr() });
