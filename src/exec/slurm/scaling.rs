//! Scaling on paper (`talus plan-stats DIR`): how a finished run's plan maps onto job arrays —
//! tasks per stage, their work and memory from the units' own records (`seconds`,
//! `peak_rss_bytes`) — and the wall time expected on a number of nodes: the stages one after the
//! other (each array waits `afterok` for the previous one, plus a scheduling latency), the tasks
//! of a stage list-scheduled longest first on `nodes × cores` one-CPU task slots.
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

/// One stage's tasks (seconds each) and the highest peak resident memory of its units.
struct StageWork {
    kind: &'static str,
    tasks: Vec<f64>,
    peak: u64,
    scaled_peak: bool,
}

/// The makespan of `tasks` list-scheduled longest first on `slots` identical slots.
fn makespan(tasks: &[f64], slots: usize) -> f64 {
    let mut t = tasks.to_vec();
    t.sort_by(|a, b| b.total_cmp(a));
    let mut load = vec![0.0f64; slots.max(1)];
    for x in t {
        let i = (0..load.len())
            .min_by(|&a, &b| load[a].total_cmp(&load[b]))
            .unwrap_or(0);
        load[i] += x;
    }
    load.into_iter().fold(0.0, f64::max)
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
            peak,
            // A survey's tiling holds its splitter's buffers whatever the survey's size.
            scaled_peak: !tile && stage.scope() != Scope::Survey && scale > 1.0,
        });
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
    let _ = writeln!(
        s,
        "work: {total:.1} s; critical path with the stage barriers of the job arrays: {barrier_path:.1} s \
         (longest task of each stage + {STAGE_LATENCY} s of scheduling per array){}",
        if scale > 1.0 {
            String::new()
        } else {
            format!("; along the dependencies alone: {dag:.1} s")
        }
    );
    let _ = writeln!(s);
    let _ = writeln!(
        s,
        "| nodes × cores | task slots | expected wall time (s) | speed-up |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|");
    let wall = |slots: usize| -> f64 {
        stages
            .iter()
            .map(|st| makespan(&st.tasks, slots) + STAGE_LATENCY)
            .sum::<f64>()
            + STAGE_LATENCY
    };
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
    use super::makespan;

    #[test]
    fn longest_first_list_scheduling() {
        // Longest first is not optimal (3+3 | 2+2+2 would be 6), it is the list schedule.
        assert_eq!(makespan(&[3.0, 3.0, 2.0, 2.0, 2.0], 2), 7.0);
        assert_eq!(makespan(&[5.0, 1.0, 1.0], 4), 5.0);
        assert_eq!(makespan(&[1.0; 8], 1), 8.0);
        assert_eq!(makespan(&[], 3), 0.0);
    }
}
