//! The thread pools tract's kernels run one enhancement on: one pool a thread count, made
//! once and kept for the process.

/// The executors made so far, by thread count.
static POOLS: std::sync::Mutex<Vec<(usize, tract_linalg::multithread::Executor)>> = std::sync::Mutex::new(Vec::new());

/// Runs `f` with tract's kernels spreading over `threads` threads (1 or 0: the calling
/// thread alone, as for images processed in parallel).
pub(super) fn on_threads<R>(threads: usize, f: impl FnOnce() -> R) -> R {
    if threads <= 1 {
        return f();
    }
    let executor = {
        let mut pools = POOLS.lock().unwrap_or_else(|p| p.into_inner());
        match pools.iter().find(|(k, _)| *k == threads) {
            Some((_, e)) => e.clone(),
            None => {
                let e = tract_linalg::multithread::Executor::multithread_with_name(threads, "campro-enhancer");
                pools.push((threads, e.clone()));
                e
            }
        }
    };
    tract_linalg::multithread::multithread_tract_scope(executor, f)
}
