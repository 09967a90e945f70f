//! Scaling on paper (`talus plan-stats DIR`): how a finished run's plan maps onto job arrays —
//! tasks per stage, their work and memory from the units' own records (`seconds`,
//! `peak_rss_bytes`) — and the wall time expected on a number of nodes: each array released a
//! scheduling latency after the arrays it waits for (`afterok`, as `super::stages` submits them)
//! have ended, the released arrays' tasks list-scheduled on `nodes × cores` one-CPU task slots
//! (the earlier array first, as Slurm's age priority does, and within it the longest task first).
//!
//! `scale` extrapolates to a bigger input of the same kind, linearly per tile: at a fixed memory
//! budget a tile holds the same number of points, so the tile stages (m3c2, volumes) get `scale`
//! times as many tasks of the measured lengths, and the one-per-survey or one-per-pair units
//! (tiling, cores, stable, events, outputs, campaign) `scale` times the work.

use std::fmt::Write as _;

use super::stage_order;
use crate::error::{Error, Result};
use crate::plan::Plan;
use crate::store::Store;
use crate::units::stage::{timing_of, Scope, Timing};
use crate::units::unit_ref;

/// Seconds from one array's end to the start of the next (afterok): 0.6–1 s measured on the test
/// cluster (scripts/slurm/README.md, (b)).
pub(crate) const STAGE_LATENCY: f64 = 1.0;

/// One stage's tasks (seconds each), what it waits for (indices among the stages, each with the
/// time from its end to this stage's release: [`STAGE_LATENCY`] from an array, none from a tail's
/// host to the tail) and the highest peak resident memory of its units.
#[derive(Clone)]
struct StageWork {
    kind: &'static str,
    tasks: Vec<f64>,
    after: Vec<(usize, f64)>,
    peak: u64,
    scaled_peak: bool,
}

/// The wall time of `stages` on `slots` task slots, the publishing job's latency included: an
/// event-driven list schedule. An array is released [`STAGE_LATENCY`] after the last of the
/// arrays it waits for ends (a tail, `super::Tail`: when its hosts end); a free slot takes a
/// released task, of the earliest array first and the longest first within it.
fn wall_time(stages: &[StageWork], slots: usize) -> f64 {
    let n = stages.len();
    let mut end: Vec<Option<f64>> = vec![None; n];
    let mut left: Vec<usize> = stages.iter().map(|s| s.tasks.len()).collect();
    let mut release: Vec<Option<f64>> = vec![None; n];
    // Released tasks waiting for a slot: (array, seconds), and the tasks running: (end, array).
    let mut ready: Vec<(usize, f64)> = Vec::new();
    let mut running: Vec<(f64, usize)> = Vec::new();
    let mut queued = vec![false; n];
    let mut t = 0.0f64;
    loop {
        for k in 0..n {
            if release[k].is_none() && stages[k].after.iter().all(|&(j, _)| end[j].is_some()) {
                let r = match stages[k].after.is_empty() {
                    true => STAGE_LATENCY,
                    false => (stages[k].after.iter())
                        .filter_map(|&(j, l)| Some(end[j]? + l))
                        .fold(0.0, f64::max),
                };
                release[k] = Some(r);
                if left[k] == 0 {
                    end[k] = release[k];
                }
            }
        }
        for k in 0..n {
            if !queued[k] && release[k].is_some_and(|r| r <= t) {
                queued[k] = true;
                ready.extend(stages[k].tasks.iter().map(|&x| (k, x)));
            }
        }
        ready.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.total_cmp(&b.1)));
        while running.len() < slots.max(1) {
            let Some((k, x)) = ready.pop() else { break };
            running.push((t + x, k));
        }
        // The next moment something happens: a task ends, or an array is released.
        let next_end = running.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
        let next_release = (0..n)
            .filter(|&k| !queued[k])
            .filter_map(|k| release[k])
            .fold(f64::INFINITY, f64::min);
        let next = next_end.min(next_release);
        if !next.is_finite() {
            break;
        }
        t = t.max(next);
        running.retain(|&(e, k)| {
            if e <= t {
                left[k] -= 1;
                if left[k] == 0 {
                    end[k] = Some(e);
                }
                false
            } else {
                true
            }
        });
    }
    end.iter().flatten().copied().fold(0.0, f64::max) + STAGE_LATENCY
}

/// The report `talus plan-stats` prints (Markdown tables).
pub(crate) fn report(
    dir: &std::path::Path,
    nodes: &[usize],
    cores: usize,
    scale: f64,
) -> Result<String> {
    if !(scale.is_finite() && scale >= 1.0) {
        return Err(Error::Usage("--scale: a factor of at least 1".into()));
    }
    let store = Store::inspect(dir)?;
    let plan = Plan::load(&store.plan_path())?;
    let mut stages: Vec<StageWork> = Vec::new();
    let mut secs = vec![0.0; plan.units.len()];
    let ranks = crate::units::stage::check_plan(&plan)?;
    for (r, stage) in stage_order().enumerate() {
        let kind = stage.kind();
        let idx: Vec<usize> = (0..plan.units.len()).filter(|&i| ranks[i] == r).collect();
        if idx.is_empty() {
            continue;
        }
        let mut tasks = Vec::new();
        let mut peak = 0;
        for &i in &idx {
            let rec = store.done(&unit_ref(&plan, i)).ok_or_else(|| {
                Error::Usage(format!(
                    "{}: unit {} is not done: plan-stats needs a finished run",
                    dir.display(),
                    plan.units[i].name
                ))
            })?;
            let t: Timing = timing_of(&store, &unit_ref(&plan, i), &rec)?;
            secs[i] = t.seconds;
            tasks.push(t.seconds);
            peak = peak.max(t.peak_rss_bytes.unwrap_or(0));
        }
        // A stage whose units spread over the input as it grows: per tile, or a survey's
        // tiling in parts (a larger survey has more parts, not longer ones).
        let tile =
            stage.scope().per_tile() || idx.iter().any(|&i| plan.units[i].spec.part.is_some());
        let tasks = if tile {
            let n = (tasks.len() as f64 * scale).round() as usize;
            (0..n).map(|k| tasks[k % tasks.len()]).collect()
        } else {
            tasks.iter().map(|s| s * scale).collect()
        };
        stages.push(StageWork {
            kind,
            tasks,
            after: Vec::new(),
            peak,
            // A survey's tiling holds its splitter's buffers whatever the survey's size.
            scaled_peak: !tile && stage.scope() != Scope::Survey && scale > 1.0,
        });
    }
    // The arrays each waits for, and the stages absorbed into arrays' tasks, as a submission of
    // the whole plan has them.
    let arrays = super::stages(&plan, &vec![false; plan.units.len()], 1)?;
    let kinds: Vec<&str> = stages.iter().map(|st| st.kind).collect();
    let at = |kind: &str| {
        kinds.iter().position(|&k| k == kind).ok_or_else(|| {
            Error::Internal(format!(
                "plan-stats: the submission's stage {kind} has no units"
            ))
        })
    };
    let of_array: Vec<usize> = (arrays.stages.iter())
        .map(|a| at(a.kind))
        .collect::<Result<_>>()?;
    for (a, &k) in arrays.stages.iter().zip(&of_array) {
        stages[k].after = a
            .after
            .iter()
            .map(|&j| (of_array[j], STAGE_LATENCY))
            .collect();
    }
    let mut tails = Vec::new();
    for t in &arrays.tails {
        let k = at(t.kind)?;
        // Released when the last of its hosts ends: the task ending last computes it.
        stages[k].after = t.hosts.iter().map(|&h| (of_array[h], 0.0)).collect();
        let reads = |units: &[usize], of: &[usize]| {
            (units.iter()).any(|u| of.iter().any(|v| plan.units[*u].deps.contains(v)))
        };
        // After the tails it reads, computed before it at the same ends.
        for other in &arrays.tails {
            if reads(&t.units, &other.units) {
                stages[k].after.push((at(other.kind)?, 0.0));
            }
        }
        // The arrays waiting for one of its hosts wait a scheduling pass after it too: their
        // afterok is on the host, whose last task it ends (whether they read it or not).
        for (a, &r) in arrays.stages.iter().zip(&of_array) {
            if a.after.iter().any(|h| t.hosts.contains(h)) {
                stages[r].after.push((k, STAGE_LATENCY));
            }
        }
        let hosts: Vec<&str> = t.hosts.iter().map(|&h| arrays.stages[h].kind).collect();
        tails.push(format!(
            "{} (at the end of {})",
            t.kind,
            hosts.join(" and ")
        ));
    }
    // Critical path along the dependencies alone (no stage barriers), unscaled.
    let mut finish = vec![0.0f64; plan.units.len()];
    for (i, u) in plan.units.iter().enumerate() {
        let start = u.deps.iter().map(|&d| finish[d]).fold(0.0, f64::max);
        finish[i] = start + secs[i];
    }
    let dag = finish.iter().copied().fold(0.0, f64::max);

    let mut s = String::new();
    let tiles = plan.layout.len();
    let _ = writeln!(
        s,
        "plan of {}: {} survey(s), {} pair(s), {} tile(s), {} units; unit seconds and peak RSS \
         from the units' records{}",
        dir.display(),
        plan.surveys.len(),
        plan.pairs.len(),
        tiles,
        plan.units.len(),
        if scale > 1.0 {
            format!(
                ", extrapolated ×{scale} linearly per tile (tile stages and tilings in parts: ×{scale} tasks; the \
                 others: ×{scale} work)"
            )
        } else {
            String::new()
        }
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "| stage | tasks | work (s) | longest task (s) | peak RSS of a task (MiB) |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|");
    // Each array after the one before it (the submission before issue 47's), for comparison.
    let mut barrier_path = 0.0;
    for st in &stages {
        let work: f64 = st.tasks.iter().sum();
        let longest = st.tasks.iter().copied().fold(0.0, f64::max);
        barrier_path += longest + STAGE_LATENCY;
        let peak = if st.scaled_peak {
            format!(
                "{} (×{scale}: ≤ {})",
                crate::memory::mib(st.peak),
                (crate::memory::mib(st.peak) as f64 * scale) as u64
            )
        } else {
            crate::memory::mib(st.peak).to_string()
        };
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} | {:.1} | {} |",
            st.kind,
            st.tasks.len(),
            work,
            longest,
            peak
        );
    }
    barrier_path += STAGE_LATENCY; // the publishing job
    let _ = writeln!(s, "| publish | 1 | – | – | – |");
    let total: f64 = stages.iter().flat_map(|st| st.tasks.iter()).sum();
    let _ = writeln!(s);
    let arrays_path = wall_time(&stages, usize::MAX);
    let _ = writeln!(
        s,
        "work: {total:.1} s; critical path of the job arrays, each after those it waits for: \
         {arrays_path:.1} s (longest task of each array + {STAGE_LATENCY} s of scheduling per \
         array; each array after the one before it: {barrier_path:.1} s){}",
        if scale > 1.0 {
            String::new()
        } else {
            format!("; along the units' dependencies alone: {dag:.1} s")
        }
    );
    if !tails.is_empty() {
        let _ = writeln!(
            s,
            "\nstages of one unit a task computed by the last task of the arrays holding what they read, \
             not an array of their own: {}",
            tails.join(", ")
        );
    }
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "| nodes × cores | task slots | expected wall time (s) | speed-up |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|");
    let wall = |slots: usize| wall_time(&stages, slots);
    let one = wall(cores.max(1));
    for &n in nodes {
        let slots = n.max(1) * cores.max(1);
        let w = wall(slots);
        let _ = writeln!(s, "| {n} × {cores} | {slots} | {w:.1} | {:.2} |", one / w);
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::{wall_time, StageWork, STAGE_LATENCY};

    fn array(tasks: &[f64], after: &[usize]) -> StageWork {
        StageWork {
            kind: "x",
            tasks: tasks.to_vec(),
            after: after.iter().map(|&j| (j, STAGE_LATENCY)).collect(),
            peak: 0,
            scaled_peak: false,
        }
    }

    #[test]
    fn arrays_list_scheduled_after_what_they_wait_for() {
        let l = STAGE_LATENCY;
        // One array: longest first is not optimal (3+3 | 2+2+2 would be 6), it is the list
        // schedule; then the publishing job's latency.
        assert_eq!(
            wall_time(&[array(&[3.0, 3.0, 2.0, 2.0, 2.0], &[])], 2),
            l + 7.0 + l
        );
        assert_eq!(wall_time(&[array(&[1.0; 8], &[])], 1), l + 8.0 + l);
        assert_eq!(wall_time(&[array(&[], &[])], 3), l + l);
        // C waits for B only: it runs beside A.
        let dag = [array(&[4.0], &[]), array(&[1.0], &[]), array(&[1.0], &[1])];
        assert_eq!(wall_time(&dag, 8), l + 4.0 + l);
        // C waits for A: after it.
        let chain = [array(&[4.0], &[]), array(&[1.0], &[]), array(&[1.0], &[0])];
        assert_eq!(wall_time(&chain, 8), l + 4.0 + l + 1.0 + l);
        // One slot: the earlier array's tasks first (A, then B), C released after B.
        assert_eq!(wall_time(&dag, 1), l + 5.0 + l + 1.0 + l);
    }

    #[test]
    fn a_tail_starts_when_its_host_ends() {
        let l = STAGE_LATENCY;
        // B (2 s) a tail of A: released when A ends; C, reading it, a pass after it.
        let mut b = array(&[2.0], &[]);
        b.after = vec![(0, 0.0)];
        let mut c = array(&[1.0, 1.0], &[0]);
        c.after.push((1, l));
        assert_eq!(
            wall_time(&[array(&[4.0], &[]), b, c], 8),
            l + 4.0 + 2.0 + l + 1.0 + l
        );
    }
}
