//! `threads=N`: work runs on a rayon pool of N workers (kept for reuse), `None` on rayon's
//! global pool (all cores). Output never depends on the thread count.

use crate::errors::value_error;
use pyo3::PyResult;
use rayon::{ThreadPool, ThreadPoolBuilder};
use std::sync::{Arc, Mutex};

/// The most workers a pool may have (the CLI's `--threads` limit).
const MAX_THREADS: usize = 1024;

/// Pools made so far, by worker count.
static POOLS: Mutex<Vec<(usize, Arc<ThreadPool>)>> = Mutex::new(Vec::new());

/// Where to run: rayon's global pool or a pool of a given size.
#[derive(Clone)]
pub struct Workers(Option<Arc<ThreadPool>>);

impl Workers {
    /// The pool for `threads` (validated as the CLI's `--threads`).
    pub fn new(threads: Option<usize>) -> PyResult<Self> {
        let Some(n) = threads else {
            return Ok(Workers(None));
        };
        if n == 0 || n > MAX_THREADS {
            return Err(value_error(format!(
                "invalid parameter threads: must be between 1 and {MAX_THREADS}, got {n}"
            )));
        }
        let mut pools = POOLS.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((_, p)) = pools.iter().find(|(k, _)| *k == n) {
            return Ok(Workers(Some(p.clone())));
        }
        let pool = ThreadPoolBuilder::new()
            .num_threads(n)
            .thread_name(|i| format!("drbokeh-{i}"))
            .build()
            .map_err(|e| value_error(format!("cannot start the thread pool: {e}")))?;
        let pool = Arc::new(pool);
        pools.push((n, pool.clone()));
        Ok(Workers(Some(pool)))
    }

    /// Runs `f` on these workers (its parallel loops use them).
    pub fn run<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        match &self.0 {
            Some(pool) => pool.install(f),
            None => f(),
        }
    }
}
