//! The `dynaflow` package: the CLI binary (`src/main.rs`) and this small library that wires
//! the crates together, so tests and benches see exactly the operators the CLI sees.

use dynaflow_engine::op::Registry;

/// Every operator dynaflow ships: the `dynaflow-operators` families plus the recording-backed
/// sources of `dynaflow-recordings` (`mcap_replay`).
pub fn registry() -> Registry {
    let mut r = dynaflow_operators::registry();
    dynaflow_recordings::register(&mut r);
    r
}

/// Sets glibc's allocator for a long run of many threads: the mmap threshold pinned at its
/// default (128 KiB), and free pages handed back to the OS once a second. The CLI calls it
/// first thing; benches that compare runs call it too, so they run as the CLI does.
///
/// glibc otherwise raises the threshold after each freed large block, so the recorders'
/// per-frame image buffers (300 KB-1 MB, allocated and freed on several threads) come from the
/// heap arenas instead, which fragment: a recorded run's resident memory then grew by about
/// 100 KB per frame (measured: 233 MB at 1200 frames against 131 MB with the threshold pinned,
/// rrd recording; docs/benchmarks.md). Smaller blocks still come from the arenas, and glibc
/// returns an arena's free pages to the OS only from its top: the free pages between live
/// blocks stay resident. A 10 000-frame recorded run held 50-60 MB of them at frame 5 000 (one
/// `malloc_trim(0)` took its resident memory from 190-201 MB to 140 MB) and their share grew
/// with the run; `malloc_trim` releases the arenas' whole free pages. With it once a second the
/// median resident memory of that run rose 19 MB instead of 37, in no more time
/// (docs/benchmarks.md, "Third pass").
///
/// Call it before any other thread starts; later calls do nothing.
pub fn tune_allocator() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(tune_glibc);
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
fn tune_glibc() {
    unsafe extern "C" {
        fn mallopt(param: std::os::raw::c_int, value: std::os::raw::c_int) -> std::os::raw::c_int;
        fn malloc_trim(pad: usize) -> std::os::raw::c_int;
    }
    /// glibc's `M_MMAP_THRESHOLD` (malloc.h).
    const M_MMAP_THRESHOLD: std::os::raw::c_int = -3;
    // SAFETY: mallopt only sets an allocator parameter; it is called before any thread starts
    // and takes no pointers.
    unsafe {
        mallopt(M_MMAP_THRESHOLD, 128 * 1024);
    }
    // The thread ends with the process. If it cannot start, memory is only less tidy.
    let _ = std::thread::Builder::new().name("dynaflow-trim".into()).spawn(|| {
        loop {
            std::thread::sleep(std::time::Duration::from_secs(1));
            // SAFETY: malloc_trim takes no pointers and is thread-safe (it locks each arena).
            unsafe {
                malloc_trim(0);
            }
        }
    });
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn tune_glibc() {}
