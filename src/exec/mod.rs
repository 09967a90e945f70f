//! Drivers: executing a plan's units (SPEC.md §3, §6).
//!
//! `run` executes, in this process, every unit of a plan that is not done: a few slot threads
//! each take the first unit (pair by pair, then in plan order) whose dependencies are done, claim it in the store (so
//! that other processes working on the same DIR — `talus worker DIR`, Slurm array tasks — do not
//! compute it too), run it and commit its files. Units use the rayon pool inside (M3C2 over core
//! points, volumes over events); two slots let one unit's reading overlap another's computing, as
//! a bounded read-ahead would, within the two tiles in flight the layout's memory plan allows for.
//! A unit another process holds is waited for (its record appears) or, when that process died,
//! taken over (its claim is stale). A unit that finds a dependency's file damaged has that
//! dependency thrown away and both redone, once.
//!
//! `run` never publishes: the process holding DIR's lock does, once every unit is done
//! (`publish`; after a Slurm submission, its final job).

pub(crate) mod progress;
pub(crate) mod publish;
pub mod resident;
pub(crate) mod slurm;

use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use crate::plan::Plan;
use crate::store::{Claim, Store};
use crate::units::{self, unit_ref, Ctx};
use progress::Stages;

/// How long a slot waits before looking again at units other processes hold.
const POLL: Duration = Duration::from_millis(250);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Not done, not running here.
    Todo,
    /// Running in this process.
    Running,
    Done,
}

struct Shared {
    state: Vec<State>,
    /// Redos after damage, per unit.
    redone: Vec<u8>,
    /// Times each unit was thrown away for damage: a unit whose dependency's count moved while
    /// it ran had that dependency's files taken from under it.
    withdrawn: Vec<u32>,
    error: Option<Error>,
    /// Units found claimed by another live process at the last look.
    elsewhere: Vec<bool>,
    /// Units this run released (or let go to be released) once their dependents were done.
    released: Vec<bool>,
    /// A unit that read a damaged record of a unit it does not depend on directly waits for
    /// that unit to be computed again.
    waits: Vec<Option<usize>>,
}

/// What a run of the executor did.
#[derive(Debug, Default)]
pub struct Report {
    /// Units this process computed.
    pub computed: usize,
    /// Units found done.
    pub reused: usize,
}

/// How a command executes its plan (SPEC.md §6).
#[derive(Debug, Clone, Default)]
pub enum Executor {
    /// The plan's units in this process.
    #[default]
    Local,
    /// The plan's units as Slurm job arrays (`slurm`).
    Slurm(slurm::Options),
}

/// Execute every unit of `plan` not yet done in `store`, with `slots` units at a time, as a
/// process of run `plan.run` labelled `label` (for claims).
pub(crate) fn run(store: &Store, plan: &Plan, slots: usize, label: &str) -> Result<Report> {
    run_units(store, plan, None, slots, label, None)
}

/// Like [`run`], but only the units `only` (indices into the plan) and whichever of their
/// dependencies, transitively, are not done (normally none: a Slurm task runs after the stages it
/// depends on). `None`: every unit. `attempt`: which attempt of a task that runs one attempt at
/// a time under `label` this is (a Slurm array task's restart count: it takes over the claims of
/// its earlier attempts, `Store::claim_attempt`).
pub(crate) fn run_units(
    store: &Store,
    plan: &Plan,
    only: Option<&[usize]>,
    slots: usize,
    label: &str,
    attempt: Option<u32>,
) -> Result<Report> {
    let n = plan.units.len();
    let mut released = vec![false; n];
    let finished: Vec<bool> = (0..n)
        .map(|i| -> Result<bool> {
            let unit = unit_ref(plan, i);
            let Some(record) = store.done(&unit) else {
                return Ok(false);
            };
            released[i] = record.released;
            // A file edited after the unit's commit (a published output edited in place: it
            // is a hard link to the unit's file) is not reused: the unit is thrown away and
            // computed again, and the next publish puts its files back.
            // A publishing unit's list of outputs names paths: one read back from DIR that
            // names anything outside it is damage too (`publish::listed_outputs`).
            if let Err(e @ Error::Damaged { .. }) = publish::listed_outputs(store, plan, i, &record)
            {
                eprintln!("talus: {e}; computing unit {} again", unit.name);
                store.invalidate(&unit)?;
                return Ok(false);
            }
            let edited = store.edited_files(&unit, &record);
            if edited.is_empty() {
                return Ok(true);
            }
            eprintln!(
                "talus: {}: damaged ({} changed since the unit was computed: size or checksum \
                 no longer match its record); computing unit {} again",
                store.unit_dir(&unit)?.display(),
                edited.join(", "),
                unit.name
            );
            store.invalidate(&unit)?;
            Ok(false)
        })
        .collect::<Result<Vec<bool>>>()?;
    let mut finished = finished;
    // A released unit (`Store::release`) is done, but a unit to be computed reads its files:
    // computed again first (the same bytes), and so on down its released dependencies.
    // Dependencies precede their dependents: one pass from the end sees every need.
    let mut needed: Vec<bool> = match only {
        None => (0..n).map(|i| !finished[i]).collect(),
        Some(list) => {
            let mut m = vec![false; n];
            for &i in list.iter().filter(|&&i| i < n) {
                m[i] = !finished[i];
            }
            m
        }
    };
    for i in (0..n).rev() {
        if !needed[i] {
            continue;
        }
        for &d in &plan.units[i].deps {
            if !finished[d] {
                needed[d] = true;
            } else if released[d] {
                finished[d] = false;
                needed[d] = true;
            }
        }
    }
    let revive: Vec<bool> = (0..n).map(|i| needed[i] && released[i]).collect();
    // A unit found done counts as done only once every unit before it is (dependencies precede
    // their dependents): a unit reads records beyond its direct dependencies (the outputs' stage
    // times, the surveys' tilings), so one whose dependency is computed again waits for it, and
    // is then found done without being computed.
    for i in 0..n {
        if finished[i] && plan.units[i].deps.iter().any(|&d| !finished[d]) {
            finished[i] = false;
        }
    }
    let reused = finished.iter().filter(|&&d| d).count();
    // Units outside the wanted set count as done for this run.
    let wanted = match only {
        None => vec![true; n],
        Some(list) => {
            let mut w = vec![false; n];
            let mut stack: Vec<usize> = list.to_vec();
            while let Some(i) = stack.pop() {
                if i < n && !w[i] && !finished[i] {
                    w[i] = true;
                    stack.extend(&plan.units[i].deps);
                }
            }
            w
        }
    };
    let done: Vec<bool> = (0..n).map(|i| finished[i] || !wanted[i]).collect();
    let shared = Mutex::new(Shared {
        state: done
            .iter()
            .map(|&d| if d { State::Done } else { State::Todo })
            .collect(),
        redone: vec![0; n],
        withdrawn: vec![0; n],
        error: None,
        elsewhere: vec![false; n],
        released: vec![false; n],
        waits: vec![None; n],
    });
    let wake = Condvar::new();
    let stages = Stages::new(plan, &done);
    let watch = resident::Watch::start();
    let pool = crate::memory::pool_for(plan.params.memory_bytes.value);
    let computed = std::sync::atomic::AtomicUsize::new(0);
    let early = (only.is_none() && !plan.keep_units)
        .then(|| EarlyRelease::new(plan))
        .transpose()?;
    let order = pair_by_pair(plan);
    std::thread::scope(|s| {
        for _ in 0..slots.max(1) {
            s.spawn(|| {
                slot(&RunCtx {
                    store,
                    plan,
                    label,
                    attempt,
                    shared: &shared,
                    wake: &wake,
                    stages: &stages,
                    watch: &watch,
                    pool: &pool,
                    computed: &computed,
                    revive: &revive,
                    early: early.as_ref(),
                    order: &order,
                })
            });
        }
    });
    let shared = shared.into_inner().unwrap_or_else(|e| e.into_inner());
    if let Some(e) = shared.error {
        // A failed run prints its error, not the lines of stages it did not finish.
        stages.abandon();
        return Err(e);
    }
    stages.finish_all();
    if let Some(e) = &early {
        publish::say_released(e.freed.load(std::sync::atomic::Ordering::Relaxed));
    }
    Ok(Report {
        computed: computed.into_inner(),
        reused,
    })
}

/// What every slot of one run shares.
struct RunCtx<'a> {
    store: &'a Store,
    plan: &'a Plan,
    label: &'a str,
    attempt: Option<u32>,
    shared: &'a Mutex<Shared>,
    wake: &'a Condvar,
    stages: &'a Stages,
    watch: &'a resident::Watch,
    pool: &'a crate::memory::Pool,
    computed: &'a std::sync::atomic::AtomicUsize,
    /// Released units to be computed again (their files needed); any other released unit
    /// reached is found done.
    revive: &'a [bool],
    /// Releasing intermediate units as the run goes (None: a run over part of the plan, or
    /// `--keep-units`).
    early: Option<&'a EarlyRelease>,
    /// The order slots look for a ready unit in ([`pair_by_pair`]).
    order: &'a [usize],
}

/// The order slots take ready units in: by the first pair each unit serves (its own pair, or
/// the earliest of the units that read it), then in plan order. Plan order is stage after
/// stage: a campaign's slots took every pair's M3C2 before any pair's events, so every pair's
/// M3C2 results and every survey's tiles were on disk at once (4.3× the inputs of 41 surveys of
/// 400k points, issue 46). Pair by pair, a pair's readers finish and release its intermediate
/// units before later pairs' pile up. A preference, not a barrier: a slot with nothing of the
/// earliest pair ready takes a later pair's unit. A comparison (one pair) keeps plan order.
/// Outputs never depend on the order (units are pure functions of their inputs).
fn pair_by_pair(plan: &Plan) -> Vec<usize> {
    let n = plan.units.len();
    let mut first = vec![usize::MAX; n];
    // Dependencies precede their dependents: from the end, each unit's rank is final when its
    // dependencies are reached.
    for i in (0..n).rev() {
        if let Some(p) = plan.units[i].spec.pair {
            first[i] = first[i].min(p);
        }
        for &d in &plan.units[i].deps {
            first[d] = first[d].min(first[i]);
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| (first[i], i));
    order
}

/// Releasing a unit's files as soon as every unit that reads them is done, rather than after
/// publishing: the tiles, the per-tile M3C2 results and m3c2.laz would otherwise all be on disk
/// at once near the end of a run (issue 46: the run's peak disk). A unit reads only its
/// dependencies' files (`Ctx::input` refuses others), so once its dependents are done no unit
/// of the plan reads it again.
struct EarlyRelease {
    /// The units that depend on each unit.
    dependents: Vec<Vec<usize>>,
    /// What each unit keeps when released (None: never released, `publish::releasable`).
    kept: Vec<Option<&'static [&'static str]>>,
    freed: std::sync::atomic::AtomicU64,
}

impl EarlyRelease {
    fn new(plan: &Plan) -> Result<EarlyRelease> {
        let n = plan.units.len();
        let mut dependents = vec![Vec::new(); n];
        for (i, u) in plan.units.iter().enumerate() {
            for &d in &u.deps {
                dependents[d].push(i);
            }
        }
        Ok(EarlyRelease {
            dependents,
            kept: publish::releasable(plan)?,
            freed: Default::default(),
        })
    }

    /// The dependencies of unit `done` (just done) that no unit still needs, marked released.
    fn due(&self, plan: &Plan, sh: &mut Shared, done: usize) -> Vec<usize> {
        let mut out = Vec::new();
        for &d in &plan.units[done].deps {
            let free = self.kept[d].is_some()
                && !sh.released[d]
                && sh.state[d] == State::Done
                && self.dependents[d]
                    .iter()
                    .all(|&j| sh.state[j] == State::Done);
            if free {
                sh.released[d] = true;
                out.push(d);
            }
        }
        out
    }

    /// Release units `due` ([`EarlyRelease::due`]).
    fn release(&self, store: &Store, plan: &Plan, due: &[usize]) -> Result<()> {
        for &d in due {
            let kept = self.kept[d].unwrap_or_default();
            let freed = store.release(&unit_ref(plan, d), kept)?;
            crate::progress::trace(|| format!("unit {} released", plan.units[d].name));
            self.freed
                .fetch_add(freed, std::sync::atomic::Ordering::Relaxed);
        }
        Ok(())
    }
}

/// One slot: take ready units until every unit is done or the run failed.
fn slot(cx: &RunCtx) {
    let RunCtx {
        store,
        plan,
        shared,
        wake,
        stages,
        computed,
        ..
    } = *cx;
    let lock = || shared.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        // Pick the first ready unit nobody else holds.
        let (picked, withdrawn_before) = {
            let mut sh = lock();
            loop {
                if sh.error.is_some() || crate::interrupt::requested() {
                    if sh.error.is_none() {
                        sh.error = Some(Error::Interrupted);
                    }
                    wake.notify_all();
                    return;
                }
                if sh.state.iter().all(|&s| s == State::Done) {
                    wake.notify_all();
                    return;
                }
                let ready = cx.order.iter().copied().find(|&i| {
                    sh.state[i] == State::Todo
                        && plan.units[i]
                            .deps
                            .iter()
                            .chain(&plan.units[i].after)
                            .all(|&d| sh.state[d] == State::Done)
                        && sh.waits[i].is_none_or(|w| sh.state[w] == State::Done)
                        && !sh.elsewhere[i]
                });
                if let Some(i) = ready {
                    sh.state[i] = State::Running;
                    break (i, deps_withdrawn(plan, &sh, i));
                }
                // Nothing ready here: wait for a unit of this process to finish, or look again
                // at what other processes hold.
                let others = sh.elsewhere.iter().any(|&e| e);
                let (guard, _) = wake
                    .wait_timeout(sh, POLL)
                    .unwrap_or_else(|e| e.into_inner());
                sh = guard;
                if others {
                    refresh_elsewhere(store, plan, &mut sh);
                }
            }
        };
        let outcome = claim_and_run(cx, picked);
        let mut sh = lock();
        // A dependency thrown away while this unit ran (another unit found it damaged) took its
        // files from under it: whatever that made it fail with, run it again once the dependency
        // is redone (the same bytes again), without spending its own redo.
        if outcome.is_err() && deps_withdrawn(plan, &sh, picked) != withdrawn_before {
            sh.state[picked] = State::Todo;
            wake.notify_all();
            continue;
        }
        match outcome {
            Ok(ran @ (Ran::Done | Ran::Found)) => {
                if ran == Ran::Done {
                    computed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                sh.state[picked] = State::Done;
                // Under the lock, so that no unit the release makes room for (the points unit
                // after the tiles) starts before the files are gone.
                if let Some(e) = cx.early {
                    let due = e.due(plan, &mut sh, picked);
                    if let Err(err) = e.release(store, plan, &due) {
                        sh.error.get_or_insert(err);
                    }
                }
                stages.unit_done(
                    plan,
                    picked,
                    &sh.state
                        .iter()
                        .map(|&s| s == State::Done)
                        .collect::<Vec<_>>(),
                );
            }
            Ok(Ran::Elsewhere) => {
                sh.state[picked] = State::Todo;
                sh.elsewhere[picked] = true;
            }
            Err(Error::Damaged { path, problem }) if sh.redone[picked] == 0 => {
                // Throw away the dependency that holds the damaged file, redo both: a direct
                // one, or one further up whose record the unit read (the outputs unit reads the
                // timings of every unit it depends on through others).
                let holds = |d: &usize| {
                    store
                        .unit_dir(&unit_ref(plan, *d))
                        .is_ok_and(|dir| path.starts_with(dir))
                };
                let dep = plan.units[picked]
                    .deps
                    .iter()
                    .copied()
                    .find(holds)
                    .or_else(|| (0..picked).find(holds));
                match dep {
                    Some(d) => {
                        eprintln!(
                            "talus: {}: damaged ({problem}); computing unit {} again",
                            path.display(),
                            plan.units[d].name
                        );
                        sh.redone[picked] += 1;
                        if let Err(e) = store.invalidate(&unit_ref(plan, d)) {
                            sh.error.get_or_insert(e);
                        }
                        sh.state[d] = State::Todo;
                        sh.withdrawn[d] += 1;
                        sh.state[picked] = State::Todo;
                        sh.waits[picked] = Some(d);
                        stages.reopen(plan, d);
                    }
                    None => {
                        sh.error.get_or_insert(Error::Damaged { path, problem });
                    }
                }
            }
            Err(e) => {
                sh.state[picked] = State::Todo;
                sh.error.get_or_insert(e);
            }
        }
        wake.notify_all();
    }
}

/// How many times unit `i`'s dependencies were thrown away so far.
fn deps_withdrawn(plan: &Plan, sh: &Shared, i: usize) -> u32 {
    plan.units[i].deps.iter().map(|&d| sh.withdrawn[d]).sum()
}

/// Units another process held at the last look: done now, or claimable again.
fn refresh_elsewhere(store: &Store, plan: &Plan, sh: &mut Shared) {
    for i in 0..plan.units.len() {
        if sh.elsewhere[i] {
            sh.elsewhere[i] = false;
            if store.done(&unit_ref(plan, i)).is_some() {
                sh.state[i] = State::Done;
            }
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Ran {
    Done,
    /// It was done already (by another process, or before this run: see `run_units`).
    Found,
    /// Another live process holds the unit.
    Elsewhere,
}

/// Claim unit `i`, run it, commit it (or find another process did).
fn claim_and_run(cx: &RunCtx, i: usize) -> Result<Ran> {
    let RunCtx {
        store,
        plan,
        label,
        stages,
        watch,
        pool,
        ..
    } = *cx;
    let revive = cx.revive[i];
    let unit = unit_ref(plan, i);
    let claim: Option<Claim> = match cx.attempt {
        Some(a) => store.claim_attempt(&plan.run, &unit, label, a)?,
        None => store.claim(&plan.run, &unit, label)?,
    };
    let Some(claim) = claim else {
        return Ok(Ran::Elsewhere);
    };
    // Another process may have finished it between our look and our claim. A released unit to
    // be revived is computed again: its record goes (its files already have).
    match store.done(&unit) {
        Some(r) if !(r.released && revive) => {
            drop(claim);
            return Ok(Ran::Found);
        }
        Some(_) => store.invalidate(&unit)?,
        None => {}
    }
    let started = Instant::now();
    stages.unit_started(plan, i);
    let progress = |n: u64| stages.add(plan, i, n);
    let ctx = Ctx {
        plan,
        store,
        progress: &progress,
        pool,
        reader: Some(i),
    };
    let mut out = store.begin(&unit)?;
    watch.begin(i);
    crate::progress::trace(|| format!("unit {} begins", unit.name));
    let ran = units::run(&ctx, i, &mut out);
    crate::progress::trace(|| format!("unit {} ends", unit.name));
    crate::memory::trim();
    crate::progress::trace(|| format!("unit {} trimmed", unit.name));
    let peak = watch.end(i);
    let meta = ran?;
    if let Some(p) = peak {
        stages.peak(plan, i, p);
    }
    let timing = crate::store::Timing {
        seconds: started.elapsed().as_secs_f64(),
        peak_rss_bytes: peak,
    };
    out.commit(meta, Some(timing))?;
    crate::progress::trace(|| format!("unit {} committed", unit.name));
    drop(claim);
    Ok(Ran::Done)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::Spec;

    /// A campaign of three surveys, two pairs: each pair's units come before the next pair's,
    /// a survey's tiling with the first pair that reads it, the campaign's unit last; one pair
    /// keeps plan order.
    #[test]
    fn slots_take_units_pair_by_pair() {
        let mut plan = crate::plan::tests::empty_plan();
        let mut add = |spec: Spec, deps: Vec<usize>| plan.push(spec, "u", &[], deps);
        let t: Vec<usize> = (0..3)
            .map(|s| add(Spec::survey("tiling", s), vec![]))
            .collect();
        let m0 = add(Spec::pair("m3c2", 0), vec![t[0], t[1]]);
        let m1 = add(Spec::pair("m3c2", 1), vec![t[1], t[2]]);
        let e0 = add(Spec::pair("events", 0), vec![m0]);
        let e1 = add(Spec::pair("events", 1), vec![m1]);
        let c = add(Spec::run("campaign"), vec![e0, e1]);
        assert_eq!(pair_by_pair(&plan), [t[0], t[1], m0, e0, t[2], m1, e1, c]);
        let mut one = crate::plan::tests::empty_plan();
        let t0 = one.push(Spec::survey("tiling", 0), "u", &[], vec![]);
        let t1 = one.push(Spec::survey("tiling", 1), "u", &[], vec![]);
        let m = one.push(Spec::pair("m3c2", 0), "u", &[], vec![t0, t1]);
        let o = one.push(Spec::run("outputs"), "u", &[], vec![m]);
        assert_eq!(pair_by_pair(&one), [t0, t1, m, o]);
    }
}
