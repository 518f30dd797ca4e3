//! What the whole-system benchmarks share: running on a given number of
//! threads, and reading a run's peak memory.

use anyhow::{Context, Result};
use std::path::PathBuf;
use std::sync::Arc;

/// How a whole-system benchmark repeats its runs and draws them
/// (`bite bench sim`, `bite bench team`).
#[derive(clap::Args, Debug)]
pub struct Scaling {
    /// Runs of each size and thread count (the same run: their spread is
    /// the machine's, not the mission's).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeat: u32,
    /// Thread counts to run each size on (default: rayon's, one per core);
    /// e.g. `--threads 1,2` to compare one core with two.
    #[arg(long, num_args = 1.., value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..))]
    pub threads: Vec<u32>,
    /// Also draw the real-time factor by team size, one curve per thread
    /// count through the median run with the run-to-run spread, to this SVG
    /// file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// One thread count of a benchmark: how many threads, and the pool of a
/// run's control tick (`None`: rayon's global pool).
pub struct Threads {
    /// Threads the runs use.
    pub count: usize,
    /// The pool to hand the runs (`RunOptions::pool`).
    pub pool: Option<Arc<rayon::ThreadPool>>,
    /// The curve's label in a figure.
    pub label: String,
}

impl Scaling {
    /// The thread counts asked for, each with its pool.
    pub fn thread_counts(&self) -> Result<Vec<Threads>> {
        let asked: Vec<Option<usize>> = if self.threads.is_empty() {
            vec![None]
        } else {
            self.threads.iter().map(|t| Some(*t as usize)).collect()
        };
        asked
            .into_iter()
            .map(|t| {
                Ok(Threads {
                    count: t.unwrap_or_else(rayon::current_num_threads),
                    pool: pool(t)?,
                    label: match t {
                        Some(1) => "one thread".to_string(),
                        Some(t) => format!("{t} threads"),
                        None => {
                            format!("{} threads (rayon's default)", rayon::current_num_threads())
                        }
                    },
                })
            })
            .collect()
    }
}

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
