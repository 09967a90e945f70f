//! The executor's progress: one [`Stage`] (a bar on a terminal, a line at the end) per stage of
//! the pipeline, opened when this process starts the stage's first unit and closed when every unit
//! of the stage is done. A stage whose units were all done before the run says so: `..., reused`.

use std::sync::Mutex;

use crate::plan::Plan;
use crate::progress::Stage;
use crate::units::stage::{registry, Line};

struct Open {
    /// Units of the stage not done yet.
    remaining: usize,
    /// Units of the stage in the plan.
    units: usize,
    stage: Option<Stage>,
    /// The line was printed (stage finished, or reused).
    closed: bool,
    /// The highest resident memory seen while one of the stage's units ran here.
    peak: u64,
}

pub(crate) struct Stages {
    /// The registry's progress lines, in pipeline order.
    lines: Vec<Line>,
    open: Mutex<Vec<Open>>,
}

/// The index in `lines` of the line units of `kind` count on.
fn line_of(lines: &[Line], kind: &str) -> usize {
    let name = registry().get(kind).map(|s| s.line().name).ok();
    lines
        .iter()
        .position(|l| Some(l.name) == name)
        .unwrap_or(lines.len().saturating_sub(1))
}

impl Stages {
    /// The stages of `plan`, `done[i]` telling which units were done before the run.
    pub(crate) fn new(plan: &Plan, done: &[bool]) -> Stages {
        let lines = registry().lines();
        let mut open: Vec<Open> = lines
            .iter()
            .map(|_| Open {
                remaining: 0,
                units: 0,
                stage: None,
                closed: false,
                peak: 0,
            })
            .collect();
        for (i, u) in plan.units.iter().enumerate() {
            let s = &mut open[line_of(&lines, u.kind())];
            s.units += 1;
            if !done[i] {
                s.remaining += 1;
            }
        }
        Stages {
            lines,
            open: Mutex::new(open),
        }
    }

    fn with<T>(&self, f: impl FnOnce(&mut Vec<Open>) -> T) -> T {
        let mut g = self.open.lock().unwrap_or_else(|e| e.into_inner());
        f(&mut g)
    }

    /// Print the lines of the stages before `upto` whose units were all done already.
    fn close_reused(lines: &[Line], open: &mut [Open], upto: usize) {
        for (k, s) in open.iter_mut().enumerate().take(upto) {
            if !s.closed && s.remaining == 0 && s.stage.is_none() && s.units > 0 {
                Stage::log_only(lines[k].name, lines[k].counts).finish("reused");
                s.closed = true;
            }
        }
    }

    /// Unit `i` starts in this process.
    pub(crate) fn unit_started(&self, plan: &Plan, i: usize) {
        let k = line_of(&self.lines, plan.units[i].kind());
        let line = self.lines[k];
        self.with(|open| {
            Self::close_reused(&self.lines, open, k);
            let s = &mut open[k];
            if s.stage.is_none() && !s.closed {
                let total = line.total.of(plan);
                s.stage = Some(Stage::start(line.name, total, line.counts));
            }
        });
    }

    /// Unit `i` handled `n` more items.
    pub(crate) fn add(&self, plan: &Plan, i: usize, n: u64) {
        let k = line_of(&self.lines, plan.units[i].kind());
        self.with(|open| {
            if let Some(s) = &open[k].stage {
                s.inc(n);
            }
        });
    }

    /// Unit `i` ran with at most `bytes` resident.
    pub(crate) fn peak(&self, plan: &Plan, i: usize, bytes: u64) {
        let k = line_of(&self.lines, plan.units[i].kind());
        self.with(|open| open[k].peak = open[k].peak.max(bytes));
    }

    /// Unit `i` was committed; `done` says which units are done now.
    pub(crate) fn unit_done(&self, plan: &Plan, i: usize, done: &[bool]) {
        let k = line_of(&self.lines, plan.units[i].kind());
        let remaining = plan
            .units
            .iter()
            .enumerate()
            .filter(|(j, u)| line_of(&self.lines, u.kind()) == k && !done[*j])
            .count();
        self.with(|open| {
            let s = &mut open[k];
            s.remaining = remaining;
            if remaining == 0 {
                if let Some(stage) = s.stage.take() {
                    stage.finish(&peak_note(s.peak));
                }
                s.closed = true;
            }
        });
    }

    /// Unit `i` must be done again (its files were damaged).
    pub(crate) fn reopen(&self, plan: &Plan, i: usize) {
        let k = line_of(&self.lines, plan.units[i].kind());
        self.with(|open| {
            open[k].remaining += 1;
            open[k].closed = false;
        });
    }

    /// The run failed: clear the bars of unfinished stages without their lines.
    pub(crate) fn abandon(&self) {
        self.with(|open| {
            for s in open.iter_mut() {
                if let Some(stage) = s.stage.take() {
                    stage.abandon();
                }
            }
        });
    }

    /// The run ended: close what is still open.
    pub(crate) fn finish_all(&self) {
        self.with(|open| {
            let n = open.len();
            Self::close_reused(&self.lines, open, n);
            for s in open.iter_mut() {
                if let Some(stage) = s.stage.take() {
                    stage.finish(&peak_note(s.peak));
                }
            }
        });
    }
}

/// "peak 412 MiB" for a stage's line (nothing when unknown).
fn peak_note(bytes: u64) -> String {
    if bytes == 0 {
        String::new()
    } else {
        format!("peak {} MiB", bytes >> 20)
    }
}
