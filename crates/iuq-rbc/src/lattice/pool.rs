//! Running a time loop on one of rayon's worker threads, so that its sweeps keep their rows on
//! the same cores.

/// Run `work` on a rayon worker thread (directly if already on one), so that the sweeps of a
/// time loop inside it keep their rows on the same cores from step to step (see the
/// [`lattice`](super) module docs). Results do not depend on it.
pub fn on_pool_worker<R: Send>(work: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() {
        work()
    } else {
        rayon::scope(|_| work())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pool_work_runs_on_a_worker_thread() {
        assert_eq!(rayon::current_thread_index(), None);
        let (outer, inner) = on_pool_worker(|| {
            let outer = rayon::current_thread_index();
            (outer, on_pool_worker(rayon::current_thread_index))
        });
        assert!(outer.is_some());
        assert_eq!(outer, inner, "nested work stays on its thread");
    }
}
