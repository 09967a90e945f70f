//! A memory pool shared by the units running in one process (after DataFusion's `MemoryPool`):
//! a unit reserves what it will hold before it starts and gives it back when it ends, so units
//! that would not fit beside each other run one after the other instead of at once.
//!
//! The pool is the budget less what the process holds whatever runs (see
//! [`super::BASE`]). A unit needing more than the whole pool is refused before it runs
//! (the budget is the user's to raise), never started to be killed later.

use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// How often a waiting unit looks whether the run was interrupted.
const POLL: Duration = Duration::from_millis(200);

/// Bytes reservable by the units of one process.
#[derive(Debug)]
pub struct Pool {
    limit: u64,
    used: Mutex<u64>,
    freed: Condvar,
}

/// Bytes held from a [`Pool`] until dropped.
#[derive(Debug)]
pub struct Reservation<'a> {
    pool: &'a Pool,
    bytes: u64,
}

impl Pool {
    /// A pool of `limit` bytes.
    pub(crate) fn new(limit: u64) -> Pool {
        Pool {
            limit,
            used: Mutex::new(0),
            freed: Condvar::new(),
        }
    }

    /// The pool's size.
    pub(crate) fn limit(&self) -> u64 {
        self.limit
    }

    /// Bytes reserved now (the tests' check that a reservation is given back).
    #[cfg(test)]
    pub(crate) fn used(&self) -> u64 {
        *self.used.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Reserve `bytes` (at most [`Self::limit`]: the caller refuses larger units), waiting until
    /// they fit beside what others hold; `None` when `stop()` turned true while waiting.
    pub(crate) fn reserve(&self, bytes: u64, stop: &dyn Fn() -> bool) -> Option<Reservation<'_>> {
        let bytes = bytes.min(self.limit);
        let mut used = self.used.lock().unwrap_or_else(|e| e.into_inner());
        while *used + bytes > self.limit {
            if stop() {
                return None;
            }
            used = self
                .freed
                .wait_timeout(used, POLL)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        *used += bytes;
        Some(Reservation { pool: self, bytes })
    }
}

impl Drop for Reservation<'_> {
    fn drop(&mut self) {
        let mut used = self.pool.used.lock().unwrap_or_else(|e| e.into_inner());
        *used -= self.bytes;
        self.pool.freed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};

    #[test]
    fn reservations_never_exceed_the_limit_and_all_run() {
        let pool = Pool::new(100);
        let (now, peak, ran) = (AtomicU64::new(0), AtomicU64::new(0), AtomicU64::new(0));
        std::thread::scope(|s| {
            for k in 0..8u64 {
                let (pool, now, peak, ran) = (&pool, &now, &peak, &ran);
                s.spawn(move || {
                    let need = 30 + 10 * (k % 3);
                    let r = pool.reserve(need, &|| false).expect("not stopped");
                    let held = now.fetch_add(need, Ordering::SeqCst) + need;
                    peak.fetch_max(held, Ordering::SeqCst);
                    std::thread::sleep(Duration::from_millis(20));
                    now.fetch_sub(need, Ordering::SeqCst);
                    ran.fetch_add(1, Ordering::SeqCst);
                    drop(r);
                });
            }
        });
        assert_eq!(ran.load(Ordering::SeqCst), 8);
        assert!(
            peak.load(Ordering::SeqCst) <= 100,
            "{}",
            peak.load(Ordering::SeqCst)
        );
        assert!(peak.load(Ordering::SeqCst) >= 60, "never two at once");
        assert_eq!(pool.used(), 0);
    }

    #[test]
    fn a_waiting_reservation_gives_up_when_stopped() {
        let pool = Pool::new(10);
        let held = pool.reserve(10, &|| false).expect("fits");
        assert!(pool.reserve(5, &|| true).is_none());
        drop(held);
        assert!(pool.reserve(5, &|| true).is_some());
    }
}
