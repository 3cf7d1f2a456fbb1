//! The thread pool tract's kernels run one enhancement on: a scope's thread count (one by
//! default), one pool a count, made once.

/// The executor for tract's kernels: the cores of [`with_threads`]' scope, one by default.
pub(super) static POOLS: std::sync::Mutex<Vec<(usize, tract_linalg::multithread::Executor)>> =
    std::sync::Mutex::new(Vec::new());

thread_local! {
    static THREADS: std::cell::Cell<usize> = const { std::cell::Cell::new(1) };
}

/// Runs `f` with every enhancer it calls spreading one image's convolutions over `n`
/// threads (one pool a thread count, made once). For one frame at a time (video); images
/// processed in parallel are better left at one thread each.
pub fn with_threads<R>(n: usize, f: impl FnOnce() -> R) -> R {
    let before = THREADS.with(|t| t.replace(n.max(1)));
    let r = f();
    THREADS.with(|t| t.set(before));
    r
}

pub(super) fn in_scope<R>(f: impl FnOnce() -> R) -> R {
    let n = THREADS.with(|t| t.get());
    if n <= 1 {
        return f();
    }
    let executor = {
        let mut pools = POOLS.lock().unwrap_or_else(|p| p.into_inner());
        match pools.iter().find(|(k, _)| *k == n) {
            Some((_, e)) => e.clone(),
            None => {
                let e = tract_linalg::multithread::Executor::multithread_with_name(n, "campro-enhancer");
                pools.push((n, e.clone()));
                e
            }
        }
    };
    tract_linalg::multithread::multithread_tract_scope(executor, f)
}
