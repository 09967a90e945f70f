//! `talus status DIR`: the units of DIR's plan, done, running, queued or failed, by stage, with
//! the Slurm job ids of DIR's latest submission; which tasks failed, were cancelled or timed out
//! and why. A unit's state comes first from the store (its record: done; a live claim: running),
//! then from its task: Slurm's view (`squeue -t all`, while slurmctld remembers the job) and the
//! task's own report (which survives Slurm forgetting the job).

use std::collections::HashMap;
use std::fmt::Write as _;

use super::cluster::{self, JobState};
use super::record::{self, Jobs, Submission, TaskReport};
use super::{stage_order, PUBLISH};
use crate::error::{Error, Result};
use crate::plan::Plan;
use crate::store::{Store, DEFAULT_LEASE};
use crate::units::unit_ref;

/// What became of one array task.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Outcome {
    /// Waiting in the queue (squeue's reason: Dependency, Resources, Priority, …).
    Queued(String),
    Running,
    Done,
    /// Failed, cancelled, timed out, killed…: why.
    Failed(String),
    /// Cancelled because a job it depended on failed.
    DependencyFailed,
    /// Unknown to Slurm and no report of its own: never ran (or Slurm could not be asked).
    Unknown,
}

/// One task of the latest submission.
#[derive(Debug, Clone)]
pub(crate) struct Task {
    pub stage: String,
    pub index: usize,
    /// `<array>_<index>`, the name scancel and squeue take.
    pub id: String,
    pub units: Vec<String>,
    pub outcome: Outcome,
    /// squeue's state, when Slurm still knows the task.
    pub slurm: Option<JobState>,
    pub report: Option<TaskReport>,
}

/// A unit's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum UnitState {
    Done,
    Running,
    Queued,
    Failed,
    /// Not done and in no task of the latest submission.
    Missing,
}

/// Everything `talus status` shows.
pub(crate) struct Report {
    pub dir: std::path::PathBuf,
    pub plan: Plan,
    pub units: Vec<UnitState>,
    /// The latest submission, its jobs, its tasks.
    pub submission: Option<(Submission, Option<Jobs>, Vec<Task>)>,
    /// Why Slurm could not be asked, if it could not.
    pub slurm_unavailable: Option<String>,
    /// DIR's published summary.json is this plan's and every published file is as published.
    pub published: bool,
    /// Published files of this plan that differ from the run's result (edited or damaged in
    /// DIR); `--resume` publishes them again.
    pub damaged: Vec<String>,
}

/// A task's outcome from what Slurm says of it (`asked`: whether Slurm could be asked) and its
/// own report.
fn outcome(asked: bool, slurm: Option<&JobState>, report: Option<&TaskReport>) -> Outcome {
    if let Some(s) = slurm {
        if s.state.is_pending() {
            return Outcome::Queued(s.reason.clone());
        }
        if s.state.is_active() {
            return Outcome::Running;
        }
        if s.state.is_completed() {
            return Outcome::Done;
        }
        if s.reason == "DependencyNeverSatisfied" && report.is_none() {
            return Outcome::DependencyFailed;
        }
        let mut why = s.state.to_string();
        if !s.reason.is_empty() && s.reason != "None" {
            why.push_str(&format!(" ({})", s.reason));
        }
        if let Some(e) = report.and_then(|r| r.error.as_ref()) {
            why.push_str(&format!(": {e}"));
        }
        return Outcome::Failed(why);
    }
    match report {
        // Slurm keeps no record of an array task cancelled while it was queued (squeue and
        // scontrol: "not found", no job-completion line), nor of any job after MinJobAge.
        None if asked => Outcome::Failed(
            "never ran: cancelled while queued, or forgotten by Slurm (no record left)".into(),
        ),
        None => Outcome::Unknown,
        Some(r) => match r.state.as_str() {
            "done" => Outcome::Done,
            "failed" => Outcome::Failed(format!(
                "failed: {}",
                r.error.as_deref().unwrap_or("no message")
            )),
            "interrupted" => {
                Outcome::Failed("interrupted (SIGTERM: cancelled or time limit)".into())
            }
            // Started, never finished, and Slurm no longer lists it.
            _ => Outcome::Failed(
                "ended without finishing (killed: cancelled, time limit or node failure)".into(),
            ),
        },
    }
}

impl Report {
    /// Look at DIR's store, its latest submission and Slurm.
    pub(crate) fn gather(store: &Store) -> Result<Report> {
        let plan_path = store.plan_path();
        if !plan_path.is_file() {
            return Err(Error::Usage(format!(
                "{}: no talus run here (no .talus/plan.json)",
                store.dir().display()
            )));
        }
        let plan = Plan::load(&plan_path)?;
        let mut slurm_unavailable = None;
        let submission = match record::latest(store)? {
            None => None,
            Some((n, sub, jobs)) => {
                let states: HashMap<String, JobState> = match &jobs {
                    Some(j) => match cluster::states(&j.ids) {
                        Ok(s) => s,
                        Err(cluster::Unavailable(why)) => {
                            slurm_unavailable = Some(why);
                            HashMap::new()
                        }
                    },
                    None => HashMap::new(),
                };
                let sdir = record::dir(store, n);
                let mut tasks = Vec::new();
                for (k, s) in sub.stages.iter().enumerate() {
                    for (t, units) in s.tasks.iter().enumerate() {
                        let array = jobs.as_ref().and_then(|j| j.ids.get(k));
                        let id = array.map_or(format!("?_{t}"), |a| format!("{a}_{t}"));
                        let slurm = states.get(&id).cloned();
                        // The kind names a file: read back from DIR, it must stay a name.
                        let report = crate::store::check_component("stage", &s.kind)
                            .ok()
                            .and_then(|()| {
                                record::task_report(&record::task_report_path(&sdir, &s.kind, t))
                            });
                        let outcome = if jobs.is_none() {
                            Outcome::Unknown
                        } else {
                            outcome(slurm_unavailable.is_none(), slurm.as_ref(), report.as_ref())
                        };
                        tasks.push(Task {
                            stage: s.kind.clone(),
                            index: t,
                            id,
                            units: units.clone(),
                            outcome,
                            slurm,
                            report,
                        });
                    }
                }
                Some((sub, jobs, tasks))
            }
        };
        let by_unit: HashMap<&str, &Task> = submission
            .iter()
            .flat_map(|(_, _, tasks)| tasks.iter())
            .flat_map(|t| t.units.iter().map(move |u| (u.as_str(), t)))
            .collect();
        let units = (0..plan.units.len())
            .map(|i| {
                let u = unit_ref(&plan, i);
                if store.done(&u).is_some() {
                    return UnitState::Done;
                }
                if store
                    .claim_holder(&plan.run, &u)
                    .is_some_and(|c| !c.owner.gone(Some(DEFAULT_LEASE)))
                {
                    return UnitState::Running;
                }
                match by_unit.get(plan.units[i].name.as_str()).map(|t| &t.outcome) {
                    None => UnitState::Missing,
                    Some(Outcome::Queued(_)) => UnitState::Queued,
                    // In a running task's slice, not started yet.
                    Some(Outcome::Running) => UnitState::Queued,
                    Some(Outcome::Unknown)
                        if submission.as_ref().is_some_and(|s| s.1.is_none()) =>
                    {
                        UnitState::Missing
                    }
                    Some(_) => UnitState::Failed,
                }
            })
            .collect();
        // Neither file through a link, nor a FIFO that would block: see `read_store_file`.
        let marker = crate::exec::publish::marker_path(store, &plan)
            .ok()
            .and_then(|m| crate::store::read_store_file(&m).ok())
            .is_some_and(|m| {
                crate::store::read_store_file(&store.dir().join(crate::units::outputs::MARKER)).ok()
                    == Some(m)
            });
        // This plan's marker is there: check every published file against the run's result.
        let damaged = if marker {
            match crate::exec::publish::damaged_outputs(store, &plan) {
                Ok(d) => d,
                // The run's list of what it published is damaged itself: nothing it names is
                // read, and the set is not taken for whole.
                Err(e) => vec![format!("the run's list of outputs ({e})")],
            }
        } else {
            Vec::new()
        };
        let published = marker && damaged.is_empty();
        Ok(Report {
            dir: store.dir().to_path_buf(),
            plan,
            units,
            submission,
            slurm_unavailable,
            published,
            damaged,
        })
    }

    /// The latest submission's publishing task ended well and DIR holds this plan's outputs.
    pub(crate) fn submission_ok(&self) -> bool {
        self.published
            && self.submission.as_ref().is_some_and(|(_, _, tasks)| {
                tasks
                    .iter()
                    .any(|t| t.stage == PUBLISH && t.outcome == Outcome::Done)
            })
    }

    /// One line per task that failed on its own, one per stage cancelled for a failed
    /// dependency.
    pub(crate) fn failures(&self) -> Vec<String> {
        let mut out = Vec::new();
        let Some((_, _, tasks)) = &self.submission else {
            return out;
        };
        let mut cancelled: Vec<String> = Vec::new();
        for t in tasks {
            match &t.outcome {
                Outcome::Failed(why) => {
                    let job = t
                        .slurm
                        .as_ref()
                        .map(|s| s.job.clone())
                        .or_else(|| t.report.as_ref().map(|r| r.job_id.clone()));
                    let units = if t.units.is_empty() {
                        String::new()
                    } else {
                        format!("; units {}", t.units.join(", "))
                    };
                    out.push(format!(
                        "  {} task {} ({}{}): {why}{units}",
                        t.stage,
                        t.index,
                        t.id,
                        job.map_or(String::new(), |j| format!(", job {j}"))
                    ));
                }
                Outcome::DependencyFailed if !cancelled.contains(&t.stage) => {
                    cancelled.push(t.stage.clone())
                }
                _ => {}
            }
        }
        if !cancelled.is_empty() {
            out.push(format!(
                "  cancelled by Slurm because a job they wait for failed: {}",
                cancelled.join(", ")
            ));
        }
        out
    }

    /// The text `talus status` prints.
    pub(crate) fn render(&self) -> String {
        let mut s = String::new();
        let count = |st: UnitState| self.units.iter().filter(|&&u| u == st).count();
        let _ = writeln!(
            s,
            "{}: run {}, {} units: {} done, {} running, {} queued, {} failed, {} not submitted",
            self.dir.display(),
            &self.plan.run[..self.plan.run.len().min(16)],
            self.units.len(),
            count(UnitState::Done),
            count(UnitState::Running),
            count(UnitState::Queued),
            count(UnitState::Failed),
            count(UnitState::Missing)
        );
        for r in &self.plan.recomputed {
            let _ = writeln!(
                s,
                "computed again: {} {} unit(s): {}",
                r.units, r.kind, r.reason
            );
        }
        let _ =
            writeln!(
                s,
                "outputs: {}",
                if self.published {
                    "published (this plan's)".to_string()
                } else if !self.damaged.is_empty() {
                    format!(
                    "published, but {} file(s) differ from the run's result (edited or damaged): \
                     {}; run the command again with --resume to publish them again",
                    self.damaged.len(),
                    self.damaged.iter().take(5).cloned().collect::<Vec<_>>().join(", ")
                )
                } else {
                    "not published".to_string()
                }
            );
        let sub = self.submission.as_ref();
        if let Some((sub, jobs, _)) = sub {
            let _ = writeln!(
                s,
                "slurm submission {} ({}): {}",
                sub.number,
                match jobs {
                    Some(j) => format!("arrays {}", j.ids.join(" ")),
                    None => "not submitted (--plan-only)".into(),
                },
                sub.command
            );
        }
        if let Some(why) = &self.slurm_unavailable {
            let _ = writeln!(
                s,
                "note: Slurm could not be asked ({why}); states from the tasks' reports"
            );
        }
        let _ = writeln!(
            s,
            "{:<9} {:>6} {:>6} {:>8} {:>7} {:>7}  {:<8} tasks",
            "stage", "units", "done", "running", "queued", "failed", "job"
        );
        let mut rows: Vec<&str> = stage_order().map(|s| s.kind()).collect();
        rows.push(PUBLISH);
        for kind in rows {
            let idx: Vec<usize> = (0..self.plan.units.len())
                .filter(|&i| self.plan.units[i].kind() == kind)
                .collect();
            let tasks: Vec<&Task> = sub
                .map(|(_, _, t)| t.iter().filter(|t| t.stage == kind).collect())
                .unwrap_or_default();
            if idx.is_empty() && tasks.is_empty() {
                continue;
            }
            let c = |st: UnitState| idx.iter().filter(|&&i| self.units[i] == st).count();
            let job = tasks.first().map_or("-".to_string(), |t| {
                t.id.split('_').next().unwrap_or("-").to_string()
            });
            let mut outcomes: Vec<(String, usize)> = Vec::new();
            for t in &tasks {
                let name = match &t.outcome {
                    Outcome::Queued(r) if r.is_empty() || r == "None" => "queued".into(),
                    Outcome::Queued(r) => format!("queued ({r})"),
                    Outcome::Running => "running".into(),
                    Outcome::Done => "done".into(),
                    Outcome::Failed(_) => "failed".into(),
                    Outcome::DependencyFailed => "cancelled (dependency)".into(),
                    Outcome::Unknown => "unknown".into(),
                };
                match outcomes.iter_mut().find(|(n, _)| *n == name) {
                    Some(x) => x.1 += 1,
                    None => outcomes.push((name, 1)),
                }
            }
            let outcomes: Vec<String> = outcomes.iter().map(|(n, k)| format!("{k} {n}")).collect();
            if kind == PUBLISH {
                let _ = writeln!(
                    s,
                    "{:<9} {:>6} {:>6} {:>8} {:>7} {:>7}  {:<8} {}",
                    kind,
                    "",
                    "",
                    "",
                    "",
                    "",
                    job,
                    outcomes.join(", ")
                );
                continue;
            }
            let _ = writeln!(
                s,
                "{:<9} {:>6} {:>6} {:>8} {:>7} {:>7}  {:<8} {}",
                kind,
                idx.len(),
                c(UnitState::Done),
                c(UnitState::Running),
                c(UnitState::Queued),
                c(UnitState::Failed),
                job,
                if tasks.is_empty() {
                    // A tail (`super::Tail`): computed at the end of the arrays holding what it
                    // reads.
                    let names: Vec<&str> = idx
                        .iter()
                        .map(|&i| self.plan.units[i].name.as_str())
                        .collect();
                    let hosts: Vec<&str> = sub
                        .map(|(sub, _, _)| {
                            (sub.stages.iter())
                                .filter(|a| a.tails.iter().any(|t| names.contains(&t.as_str())))
                                .map(|a| a.kind.as_str())
                                .collect()
                        })
                        .unwrap_or_default();
                    match hosts.is_empty() {
                        true => "(not in the submission)".to_string(),
                        false => format!("(at the end of {}'s tasks)", hosts.join("'s and ")),
                    }
                } else {
                    outcomes.join(", ")
                }
            );
        }
        let failures = self.failures();
        if !failures.is_empty() {
            let _ = writeln!(s, "failed:");
            for f in failures {
                let _ = writeln!(s, "{f}");
            }
        }
        if let Some((_, _, tasks)) = sub {
            let running: Vec<String> = tasks
                .iter()
                .filter(|t| t.outcome == Outcome::Running)
                .map(|t| {
                    format!(
                        "  {} task {} ({}{})",
                        t.stage,
                        t.index,
                        t.id,
                        t.slurm
                            .as_ref()
                            .map_or(String::new(), |j| format!(", job {}", j.job))
                    )
                })
                .collect();
            if !running.is_empty() {
                let _ = writeln!(s, "running:");
                for r in running {
                    let _ = writeln!(s, "{r}");
                }
            }
        }
        let todo = self.units.iter().any(|&u| u != UnitState::Done);
        let active = sub.is_some_and(|(_, _, t)| {
            t.iter()
                .any(|t| matches!(t.outcome, Outcome::Queued(_) | Outcome::Running))
        });
        if (todo || !self.published) && !active {
            let _ = writeln!(
                s,
                "to finish: run the same command again with --resume (only what is missing is computed)"
            );
        }
        s
    }
}
