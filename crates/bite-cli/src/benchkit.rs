//! What the whole-system benchmarks share: running on a given number of
//! threads, and reading a run's peak memory.

use anyhow::{Context, Result};
use std::sync::Arc;

/// A pool of `threads` threads for a run's control tick (`None`: rayon's
/// global pool, one thread per core unless `RAYON_NUM_THREADS` says
/// otherwise). The run stays on the caller's thread and hands its parallel
/// parts (sensing, the minds' ticks) to the pool (`RunOptions::pool`), so a
/// benchmark compares one core with two in one process. Results are the
/// same for any thread count.
pub fn pool(threads: Option<usize>) -> Result<Option<Arc<rayon::ThreadPool>>> {
    threads
        .map(|t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .map(Arc::new)
                .with_context(|| format!("starting {t} threads"))
        })
        .transpose()
}

/// Forget the process's peak resident memory so far, so that the next
/// [`peak_memory_kb`] is the peak of what runs in between (Linux: writing
/// 5 to `/proc/self/clear_refs`; elsewhere nothing happens).
pub fn reset_peak_memory() {
    // Best effort: without it the reading is the process's peak so far,
    // which the caller labels as such.
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// The peak resident memory since the last [`reset_peak_memory`], KB
/// (Linux: `VmHWM` of `/proc/self/status`; `None` elsewhere).
pub fn peak_memory_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pools_have_the_threads_asked_for() {
        let p = pool(Some(2)).expect("pool").expect("a pool");
        assert_eq!(p.current_num_threads(), 2);
        assert!(pool(None).expect("no pool").is_none());
    }

    #[test]
    fn peak_memory_is_read_where_the_system_tells_it() {
        reset_peak_memory();
        if cfg!(target_os = "linux") {
            assert!(peak_memory_kb().is_some_and(|kb| kb > 0));
        }
    }
}
