//! The hand-off between the threads of a pipelined scan sequence
//! ([`OccupancyTree::insert_point_clouds`](crate::OccupancyTree::insert_point_clouds)):
//! which thread casts which scan, which applies the next cast scan to the
//! tree, and when a thread with nothing to do waits.
//!
//! Every field a waiting thread depends on lives in one [`State`] behind
//! one lock, and every change that may let a waiting thread go on bumps
//! [`State::epoch`] and wakes all waiters (through [`Pipeline::change`],
//! after releasing the lock, or, where the lock is kept, before). A
//! thread decides to wait only while holding that lock, after
//! checking everything; when it lets go of the lock to help with the pool's
//! work, it compares the epoch on its return and looks again if anything
//! changed meanwhile, so no change can fall between its last look and its
//! wait. The protocol is generic over its [`Monitor`] (a mutex and a
//! condition variable) so that the tests can model-check it with loom's
//! primitives; the engine uses [`StdMonitor`].

use std::collections::BTreeMap;
use std::iter::Fuse;
use std::ops::DerefMut;
use std::sync::{Condvar, Mutex, MutexGuard};

/// A mutex with a condition variable, the two primitives the hand-off
/// needs.
pub(super) trait Monitor {
    /// The guarded value.
    type Value;
    /// Access to the value while the lock is held.
    type Guard<'a>: DerefMut<Target = Self::Value>
    where
        Self: 'a;
    /// A monitor holding `value`.
    fn new(value: Self::Value) -> Self;
    /// Takes the lock.
    fn lock(&self) -> Self::Guard<'_>;
    /// Releases the lock, sleeps until notified, takes the lock again.
    fn wait<'a>(&'a self, guard: Self::Guard<'a>) -> Self::Guard<'a>;
    /// Wakes every waiting thread.
    fn notify_all(&self);
}

/// [`Monitor`] on the standard library's `Mutex` and `Condvar`. A thread
/// that panics stops the pipeline (see [`Pipeline::stop_on_panic`]) and
/// leaves the state consistent, so a poisoned lock is still used.
pub(super) struct StdMonitor<T> {
    value: Mutex<T>,
    changed: Condvar,
}

impl<T> Monitor for StdMonitor<T> {
    type Value = T;
    type Guard<'a>
        = MutexGuard<'a, T>
    where
        T: 'a;

    fn new(value: T) -> Self {
        StdMonitor { value: Mutex::new(value), changed: Condvar::new() }
    }

    fn lock(&self) -> MutexGuard<'_, T> {
        self.value.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn wait<'a>(&'a self, guard: MutexGuard<'a, T>) -> MutexGuard<'a, T> {
        self.changed.wait(guard).unwrap_or_else(|e| e.into_inner())
    }

    fn notify_all(&self) {
        self.changed.notify_all();
    }
}

/// What the threads share: scans `S` (numbered in order) to take, cast
/// results `R` (or a refusal `E`) waiting to be applied, and how far the
/// applying has come.
pub(super) struct State<S, R, E> {
    /// The caller's iterator, which may read and transform each scan (as
    /// `octolinear build` does): the thread taking the next scan takes it
    /// out, advances it without the lock (so that the others can hand
    /// work in and out meanwhile) and puts it back; `None` while it does.
    scans: Option<Fuse<S>>,
    /// Scans taken for casting (they are taken in order).
    taken: usize,
    /// Scans applied to the tree (they are applied in order).
    applied: usize,
    /// Whether a thread is applying scan `applied`.
    applying: bool,
    /// Whether `scans` has ended.
    exhausted: bool,
    /// Whether the pipeline stopped early (a refused scan or a panic).
    stopped: bool,
    /// The first scan refused, once it is the next to apply.
    refused: Option<(usize, E)>,
    /// Cast scans waiting to be applied, by position.
    cast: BTreeMap<usize, Result<R, E>>,
    /// Counts the changes to the fields above.
    epoch: u64,
}

/// A thread's next piece of work.
pub(super) enum Job<T, R> {
    /// Cast the scan at this position.
    Cast(usize, T),
    /// Apply the next scan's cast result; `true`: share the tree update
    /// with the other threads, the scan after being cast already (so the
    /// tree, not the casting, holds the pipeline up).
    Apply(R, bool),
}

/// The shared state of a pipelined scan sequence and its protocol.
pub(super) struct Pipeline<M> {
    monitor: M,
    /// At most this many scans are taken beyond the applied ones.
    lookahead: usize,
}

impl<S, T, R, E, M> Pipeline<M>
where
    S: Iterator<Item = (usize, T)>,
    M: Monitor<Value = State<S, R, E>>,
{
    /// A pipeline over `scans` (numbered from 0 in order) that casts at
    /// most `lookahead` scans ahead of the tree.
    pub(super) fn new(scans: S, lookahead: usize) -> Self {
        let state = State {
            scans: Some(scans.fuse()),
            taken: 0,
            applied: 0,
            applying: false,
            exhausted: false,
            stopped: false,
            refused: None,
            cast: BTreeMap::new(),
            epoch: 0,
        };
        Pipeline { monitor: M::new(state), lookahead: lookahead.max(1) }
    }

    /// Changes the state under the lock, then wakes every waiting thread.
    fn change<V>(&self, f: impl FnOnce(&mut State<S, R, E>) -> V) -> V {
        let mut s = self.monitor.lock();
        let v = f(&mut s);
        s.epoch += 1;
        drop(s);
        self.monitor.notify_all();
        v
    }

    /// The next job, waiting while there is none yet: applying the next
    /// scan when it has been cast and nobody applies, else casting the next
    /// scan when the look-ahead allows; `None` once every scan is applied,
    /// or the pipeline stopped. While another thread applies, `help` is
    /// called until it returns `false` (it runs the pool's pending work: the
    /// applying thread's shared tree update) before the thread waits.
    pub(super) fn next_job(&self, mut help: impl FnMut() -> bool) -> Option<Job<T, R>> {
        let mut s = self.monitor.lock();
        loop {
            if s.stopped {
                return None;
            }
            if !s.applying {
                let next = s.applied;
                match s.cast.remove(&next) {
                    Some(Ok(result)) => {
                        s.applying = true;
                        let share = s.cast.contains_key(&(next + 1));
                        return Some(Job::Apply(result, share));
                    }
                    Some(Err(e)) => {
                        drop(s);
                        self.change(|s| {
                            s.refused = Some((next, e));
                            s.stopped = true;
                        });
                        return None;
                    }
                    None => {}
                }
            }
            if !s.exhausted && s.taken - s.applied < self.lookahead {
                // (while another thread reads a scan, this one waits below
                // for its return or other work)
                if let Some(mut scans) = s.scans.take() {
                    // the scan counts as taken while it is read, so that the
                    // sequence cannot look finished meanwhile
                    s.taken += 1;
                    drop(s);
                    let next = scans.next();
                    s = self.monitor.lock();
                    s.scans = Some(scans);
                    s.epoch += 1;
                    self.monitor.notify_all();
                    match next {
                        Some((i, scan)) => return Some(Job::Cast(i, scan)),
                        None => {
                            s.taken -= 1;
                            s.exhausted = true;
                        }
                    }
                    continue;
                }
            }
            if s.exhausted && s.applied == s.taken {
                return None;
            }
            if s.applying {
                let seen = s.epoch;
                drop(s);
                while help() {}
                s = self.monitor.lock();
                if s.epoch != seen {
                    continue;
                }
            }
            s = self.monitor.wait(s);
        }
    }

    /// Stores the cast result of scan `i`.
    pub(super) fn cast_done(&self, i: usize, result: Result<R, E>) {
        self.change(|s| {
            s.cast.insert(i, result);
        });
    }

    /// Records that the scan handed out by the last [`Job::Apply`] is in
    /// the tree.
    pub(super) fn apply_done(&self) {
        self.change(|s| {
            s.applied += 1;
            s.applying = false;
        });
    }

    /// Tells waiting threads that the applying thread has work for the
    /// pool to take.
    pub(super) fn announce(&self) {
        self.change(|_| {});
    }

    /// A guard that stops the pipeline if its thread panics, so the other
    /// threads do not wait for work that will never come.
    pub(super) fn stop_on_panic(&self) -> impl Drop + '_ {
        StopOnPanic(move || self.change(|s| s.stopped = true))
    }

    /// The refused scan and its error, if one stopped the pipeline.
    pub(super) fn take_refused(&self) -> Option<(usize, E)> {
        self.monitor.lock().refused.take()
    }
}

/// Runs its closure when dropped during a panic.
struct StopOnPanic<F: FnMut()>(F);

impl<F: FnMut()> Drop for StopOnPanic<F> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            (self.0)();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;

    /// [`Monitor`] on loom's primitives, for the model checks.
    struct LoomMonitor<T> {
        value: loom::sync::Mutex<T>,
        changed: loom::sync::Condvar,
    }

    impl<T> Monitor for LoomMonitor<T> {
        type Value = T;
        type Guard<'a>
            = loom::sync::MutexGuard<'a, T>
        where
            T: 'a;

        fn new(value: T) -> Self {
            LoomMonitor { value: loom::sync::Mutex::new(value), changed: loom::sync::Condvar::new() }
        }

        fn lock(&self) -> Self::Guard<'_> {
            self.value.lock().unwrap()
        }

        fn wait<'a>(&'a self, guard: Self::Guard<'a>) -> Self::Guard<'a> {
            self.changed.wait(guard).unwrap()
        }

        fn notify_all(&self) {
            self.changed.notify_all();
        }
    }

    type Scans = std::iter::Enumerate<std::ops::Range<u32>>;

    /// What a worker of the model did: the scans it applied, in order.
    fn worker<M>(pipeline: &Pipeline<M>, fail_at: Option<u32>, announce: bool) -> Vec<u32>
    where
        M: Monitor<Value = State<Scans, u32, u32>>,
    {
        let _stop = pipeline.stop_on_panic();
        let mut applied = Vec::new();
        while let Some(job) = pipeline.next_job(|| false) {
            match job {
                Job::Cast(i, scan) => {
                    let result = if Some(scan) == fail_at { Err(scan) } else { Ok(scan) };
                    pipeline.cast_done(i, result);
                }
                Job::Apply(scan, _) => {
                    if announce {
                        pipeline.announce();
                    }
                    applied.push(scan);
                    pipeline.apply_done();
                }
            }
        }
        applied
    }

    /// Every interleaving of `threads` workers over `scans` scans (up to
    /// loom's preemption bound) ends, applies each scan once and in order,
    /// and stops at a refused scan.
    fn model(threads: usize, scans: u32, lookahead: usize, fail_at: Option<u32>, announce: bool) {
        let mut builder = loom::model::Builder::new();
        builder.preemption_bound = Some(3);
        builder.check(move || {
            let pipeline = Arc::new(Pipeline::<LoomMonitor<_>>::new((0..scans).enumerate(), lookahead));
            let handles: Vec<_> = (1..threads)
                .map(|_| {
                    let p = Arc::clone(&pipeline);
                    loom::thread::spawn(move || worker(&p, fail_at, announce))
                })
                .collect();
            let mut applied = worker(&pipeline, fail_at, announce);
            for h in handles {
                applied.extend(h.join().unwrap());
            }
            applied.sort_unstable();
            let end = fail_at.unwrap_or(scans);
            assert_eq!(applied, (0..end).collect::<Vec<_>>());
            let refused = pipeline.take_refused();
            assert_eq!(refused, fail_at.map(|s| (s as usize, s)));
        });
    }

    #[test]
    fn two_threads_apply_every_scan_once_in_order() {
        model(2, 3, 3, None, false);
    }

    #[test]
    fn three_threads_with_a_short_lookahead() {
        model(3, 3, 1, None, true);
    }

    #[test]
    fn a_refused_scan_stops_every_thread() {
        model(2, 3, 2, Some(1), false);
    }

    /// The real monitor, many threads and many tiny scans: every run ends
    /// with each scan applied once, in order.
    #[test]
    fn many_threads_and_scans_on_std_primitives() {
        for _ in 0..20 {
            let pipeline = Pipeline::<StdMonitor<_>>::new((0..2000u32).enumerate(), 9);
            let applied = AtomicUsize::new(0);
            std::thread::scope(|scope| {
                for _ in 0..64 {
                    scope.spawn(|| {
                        while let Some(job) = pipeline.next_job(|| {
                            std::thread::yield_now();
                            false
                        }) {
                            match job {
                                Job::Cast(i, scan) => pipeline.cast_done(i, Ok::<u32, u32>(scan)),
                                Job::Apply(scan, _) => {
                                    assert_eq!(scan as usize, applied.fetch_add(1, Ordering::SeqCst));
                                    pipeline.announce();
                                    pipeline.apply_done();
                                }
                            }
                        }
                    });
                }
            });
            assert_eq!(applied.into_inner(), 2000);
        }
    }
}
