//! The process's resident memory while units run: a watcher thread samples it every
//! [`SAMPLE`] and keeps, for every unit running at the time, the highest value seen. The unit's
//! record keeps its peak (`peak_rss_bytes`: what a Slurm task running that unit needs), and each
//! stage's line prints the highest peak of its units.
//!
//! Sampled from `/proc/self/statm`, not from the kernel's high-water mark: resetting that mark
//! per unit (`/proc/self/clear_refs`) would also lower the peak `getrusage` and `/usr/bin/time`
//! report for the whole process, which the memory benchmarks judge the budget by. A sample every
//! few milliseconds misses nothing that matters: resident memory grows as pages are touched, at
//! most a few GB/s, so a peak held for less than one period is a few MiB above the samples.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Time between samples.
pub const SAMPLE: Duration = Duration::from_millis(5);

/// Peak resident bytes per running unit, kept by a sampling thread that lives as long as this.
pub struct Watch {
    running: Arc<Mutex<HashMap<usize, u64>>>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Watch {
    /// Start watching (no thread when /proc cannot be read: peaks are then unknown).
    pub fn start() -> Watch {
        let running: Arc<Mutex<HashMap<usize, u64>>> = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let thread = crate::memory::resident_bytes().is_some().then(|| {
            let (running, stop) = (running.clone(), stop.clone());
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    if let Some(now) = crate::memory::resident_bytes() {
                        let mut r = running.lock().unwrap_or_else(|e| e.into_inner());
                        for peak in r.values_mut() {
                            *peak = (*peak).max(now);
                        }
                    }
                    std::thread::sleep(SAMPLE);
                }
            })
        });
        Watch {
            running,
            stop,
            thread,
        }
    }

    /// Unit `i` starts.
    pub fn begin(&self, i: usize) {
        let now = crate::memory::resident_bytes().unwrap_or(0);
        self.lock().insert(i, now);
    }

    /// Unit `i` ended: the highest resident memory seen while it ran (`None` when unknown).
    pub fn end(&self, i: usize) -> Option<u64> {
        let now = crate::memory::resident_bytes();
        let peak = self.lock().remove(&i)?;
        now.map(|n| n.max(peak))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<usize, u64>> {
        self.running.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
