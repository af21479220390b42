//! Concurrent evaluations of one model grouped into batches, with at most `parallel` model
//! calls at once.
//!
//! UM-Bridge sends one point per `/Evaluate`, but an iuq model evaluates batches, and for a
//! cheap model a batch costs little more than one point (a GP bank predicts 8 points for about
//! the price of one). So requests that wait for the same model may be evaluated together: the
//! thread of a waiting request that finds a free call slot takes its own point and the oldest
//! waiting points of that model, up to the model's batch limit, calls the model once and hands
//! every request its outcome. With a batch limit of 1 (the default) every call is one point,
//! so `parallel` is the number of points evaluated at once. A request never leads a batch that
//! does not hold its own point, so it is answered as soon as its point is done.
//!
//! Batching does not change results: a [`iuq_core::Model`] evaluates every point of a batch
//! independently (per-point outcomes).

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

/// Locks a mutex, ignoring poisoning (the protected data stay consistent: every critical
/// section here is a few assignments that cannot panic half-way).
pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// A point waiting for its outcome.
struct Job<R> {
    x: Vec<f64>,
    result: Mutex<Option<R>>,
}

struct State<R> {
    /// Model calls that may start now.
    free: usize,
    /// Waiting points, per model.
    queues: Vec<VecDeque<Arc<Job<R>>>>,
}

/// The batching scheduler of a server (one queue per model, one set of call slots for all).
pub(crate) struct Scheduler<R> {
    state: Mutex<State<R>>,
    changed: Condvar,
}

impl<R> Scheduler<R> {
    /// A scheduler for `models` models with `parallel` model calls at once (at least 1).
    pub(crate) fn new(parallel: usize, models: usize) -> Self {
        Self {
            state: Mutex::new(State {
                free: parallel.max(1),
                queues: (0..models).map(|_| VecDeque::new()).collect(),
            }),
            changed: Condvar::new(),
        }
    }

    fn wait<'a>(&self, state: MutexGuard<'a, State<R>>) -> MutexGuard<'a, State<R>> {
        self.changed
            .wait(state)
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The outcome of model `model` at `x`; `run` evaluates a batch of points (this one and up
    /// to `batch_limit − 1` others waiting for the same model) and returns exactly one result
    /// per point, in order.
    pub(crate) fn evaluate(
        &self,
        model: usize,
        batch_limit: usize,
        x: Vec<f64>,
        run: impl Fn(&[Vec<f64>]) -> Vec<R>,
    ) -> R {
        let job = Arc::new(Job {
            x,
            result: Mutex::new(None),
        });
        let mut state = lock(&self.state);
        state.queues[model].push_back(Arc::clone(&job));
        loop {
            if let Some(result) = lock(&job.result).take() {
                return result;
            }
            let position = state.queues[model]
                .iter()
                .position(|j| Arc::ptr_eq(j, &job));
            let (Some(position), true) = (position, state.free > 0) else {
                state = self.wait(state);
                continue;
            };
            // Lead a batch: this point, then the oldest others of the model.
            state.free -= 1;
            let queue = &mut state.queues[model];
            let mut batch = Vec::with_capacity(batch_limit.clamp(1, queue.len()));
            if let Some(own) = queue.remove(position) {
                batch.push(own);
            }
            while batch.len() < batch_limit {
                match queue.pop_front() {
                    Some(other) => batch.push(other),
                    None => break,
                }
            }
            drop(state);

            let points: Vec<Vec<f64>> = batch.iter().map(|j| j.x.clone()).collect();
            let results = run(&points);
            for (j, r) in batch.iter().zip(results) {
                *lock(&j.result) = Some(r);
            }

            state = lock(&self.state);
            state.free += 1;
            self.changed.notify_all();
        }
    }

    /// Runs `call` holding one call slot (a derivative at one point).
    pub(crate) fn with_one<T>(&self, call: impl FnOnce() -> T) -> T {
        let mut state = lock(&self.state);
        while state.free == 0 {
            state = self.wait(state);
        }
        state.free -= 1;
        drop(state);
        struct Release<'a, R>(&'a Scheduler<R>);
        impl<R> Drop for Release<'_, R> {
            fn drop(&mut self) {
                lock(&self.0.state).free += 1;
                self.0.changed.notify_all();
            }
        }
        let _release = Release(self);
        call()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    #[test]
    fn concurrent_points_are_batched_within_the_limits_and_answered_in_order() {
        for (parallel, batch_limit) in [(2, 4), (3, 1)] {
            let scheduler = Scheduler::<f64>::new(parallel, 2);
            let (running, most_calls, biggest, calls) = (
                AtomicUsize::new(0),
                AtomicUsize::new(0),
                AtomicUsize::new(0),
                AtomicUsize::new(0),
            );
            let run = |points: &[Vec<f64>]| {
                calls.fetch_add(1, Ordering::SeqCst);
                let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                most_calls.fetch_max(now, Ordering::SeqCst);
                biggest.fetch_max(points.len(), Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(40));
                running.fetch_sub(1, Ordering::SeqCst);
                points.iter().map(|p| 10.0 * p[0]).collect::<Vec<_>>()
            };
            std::thread::scope(|s| {
                let handles: Vec<_> = (0..16)
                    .map(|i| {
                        let (scheduler, run) = (&scheduler, &run);
                        s.spawn(move || {
                            (
                                i,
                                scheduler.evaluate(i % 2, batch_limit, vec![i as f64], run),
                            )
                        })
                    })
                    .collect();
                for h in handles {
                    let (i, r) = h.join().unwrap();
                    assert_eq!(r, 10.0 * i as f64);
                }
            });
            assert!(most_calls.load(Ordering::SeqCst) <= parallel);
            assert!(biggest.load(Ordering::SeqCst) <= batch_limit);
            if batch_limit > 1 {
                // 16 points grouped into fewer calls.
                assert!(
                    calls.load(Ordering::SeqCst) < 16,
                    "{}",
                    calls.load(Ordering::SeqCst)
                );
            } else {
                assert_eq!(calls.load(Ordering::SeqCst), 16);
            }
            assert_eq!(scheduler.with_one(|| 7), 7);
            assert_eq!(lock(&scheduler.state).free, parallel);
        }
    }
}
