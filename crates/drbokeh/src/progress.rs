//! Progress reports from long computations (renders, gradients, traces, evaluations).

/// Receives progress reports (units of work finished) from long computations. Must be
/// cheap.
pub trait Progress: Sync {
    /// Called once before work starts with the number of units (rows).
    fn start(&self, _total: u64) {}
    /// Called as units finish, from any thread.
    fn advance(&self, _units: u64) {}
}

/// A [`Progress`] that ignores everything.
pub struct NoProgress;
impl Progress for NoProgress {}
