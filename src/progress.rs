//! Progress of a run's stages on stderr.
//!
//! On a terminal each stage draws an indicatif bar (items per second and ETA); otherwise (a log
//! file, a CI job, a test) nothing is drawn while the stage runs and one line is printed when it
//! ends: `talus: <stage>: <count> <unit> in <seconds> s[, reused]`. The line is the same whether
//! or not a bar was drawn, so a terminal keeps a record of every stage too.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// One stage being run.
pub(crate) struct Stage {
    name: String,
    unit: &'static str,
    bar: Option<ProgressBar>,
    count: AtomicU64,
    start: Instant,
}

impl Stage {
    /// Start a stage expected to handle about `total` items (`unit`, e.g. "points"); `None` when
    /// the total is unknown (a spinner on a terminal).
    pub(crate) fn start(name: &str, total: Option<u64>, unit: &'static str) -> Stage {
        let bar = (std::io::stderr().is_terminal() && !has_sink()).then(|| {
            let target = ProgressDrawTarget::stderr();
            let bar = match total {
                Some(n) => {
                    let b = ProgressBar::with_draw_target(Some(n), target);
                    // The template is a constant: it always parses.
                    if let Ok(s) = ProgressStyle::with_template(&format!(
                        "{{prefix}} [{{bar:30}}] {{human_pos}}/{{human_len}} {unit} ({{per_sec:0}}, ETA {{eta}})"
                    )) {
                        b.set_style(s.progress_chars("=> "));
                    }
                    b
                }
                None => {
                    let b = ProgressBar::with_draw_target(None, target);
                    if let Ok(s) = ProgressStyle::with_template("{prefix} {spinner} {elapsed}") {
                        b.set_style(s);
                    }
                    b.enable_steady_tick(Duration::from_millis(200));
                    b
                }
            };
            bar.set_prefix(name.to_string());
            bar
        });
        Stage {
            name: name.to_string(),
            unit,
            bar,
            count: AtomicU64::new(0),
            start: Instant::now(),
        }
    }

    /// A stage that draws no bar, only its line at the end (a stage nested in another one's bar).
    pub(crate) fn log_only(name: &str, unit: &'static str) -> Stage {
        Stage {
            name: name.to_string(),
            unit,
            bar: None,
            count: AtomicU64::new(0),
            start: Instant::now(),
        }
    }

    /// `n` more items done (callable from any thread).
    pub(crate) fn inc(&self, n: u64) {
        self.count.fetch_add(n, Ordering::Relaxed);
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }

    /// Items counted so far.
    pub(crate) fn count(&self) -> u64 {
        self.count.load(Ordering::Relaxed)
    }

    /// Seconds since the stage started.
    pub(crate) fn seconds(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// End the stage: clear its bar and print its line, with `note` (e.g. "reused") appended.
    /// Clear the bar without printing the stage's line (the run failed).
    pub(crate) fn abandon(self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }

    pub(crate) fn finish(self, note: &str) -> f64 {
        let secs = self.seconds();
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
        let note = if note.is_empty() {
            String::new()
        } else {
            format!(", {note}")
        };
        line(&format!(
            "talus: {}: {} {} in {:.2} s{}",
            self.name,
            self.count(),
            self.unit,
            secs,
            note
        ));
        secs
    }
}

impl Drop for Stage {
    /// A stage left by an error: take its bar off the screen so the error line reads cleanly.
    fn drop(&mut self) {
        if let Some(b) = &self.bar {
            if !b.is_finished() {
                b.abandon();
            }
        }
    }
}

/// Where the stages' lines go instead of stderr, when set ([`set_sink`]).
type Sink = Box<dyn Fn(&str) + Send + Sync>;
static SINK: std::sync::RwLock<Option<Sink>> = std::sync::RwLock::new(None);

/// Send the stages' lines to `sink` instead of stderr, and draw no bars (None: stderr again).
/// For a host with a console of its own: the Python bindings hand them to `sys.stderr`, which a
/// notebook shows (the process's stderr it does not).
pub fn set_sink(sink: Option<Sink>) {
    *SINK.write().unwrap_or_else(|e| e.into_inner()) = sink;
}

fn has_sink() -> bool {
    SINK.read().map(|s| s.is_some()).unwrap_or(false)
}

/// Print a stage's line: to the sink when one is set, else on stderr.
fn line(text: &str) {
    match SINK.read().as_deref() {
        Ok(Some(sink)) => sink(text),
        _ => eprintln!("{text}"),
    }
}

/// When the run started (the first call of [`trace`] or [`start_clock`]).
static CLOCK: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();

/// Start the clock [`trace`] measures from (call first thing in `main`).
pub(crate) fn start_clock() {
    CLOCK.get_or_init(Instant::now);
}

/// Seconds since the process started its clock ([`start_clock`]).
pub(crate) fn since_start() -> f64 {
    CLOCK.get_or_init(Instant::now).elapsed().as_secs_f64()
}

/// With `TALUS_TRACE` set in the environment, print `talus: [+S.SSS s, R MiB resident] what` on
/// stderr: when each phase of a run and each unit started and ended (and was trimmed), with the
/// process's resident size then, for profiling a run's timeline.
pub(crate) fn trace(what: impl FnOnce() -> String) {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    if *ON.get_or_init(|| std::env::var_os("TALUS_TRACE").is_some()) {
        let t = CLOCK.get_or_init(Instant::now).elapsed().as_secs_f64();
        let rss = crate::memory::resident_bytes().unwrap_or(0) >> 20;
        eprintln!("talus: [+{t:.3} s, {rss} MiB resident] {}", what());
    }
}
