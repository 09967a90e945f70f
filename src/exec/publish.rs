//! Publishing a finished plan: the last unit's `publish` list placed into DIR as one set
//! ([`Store::publish`]), then the units no longer in the plan dropped ([`Store::gc`]). Whoever
//! publishes holds DIR's lock: the command's process after a local run, the final job of a Slurm
//! submission.

use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::plan::Plan;
use crate::store::Store;
use crate::units::outputs::{Publish, MARKER};
use crate::units::stage::{final_unit, registry};
use crate::units::unit_ref;

/// Publish the plan's outputs ([`publish`]) and drop the units no longer in the plan; the caller
/// holds DIR's lock. Returns the path of the published marker in its unit.
pub(crate) fn publish_and_gc(
    store: &Store,
    plan: &Plan,
    ours: &dyn Fn(&str) -> bool,
) -> Result<PathBuf> {
    let marker = publish(store, plan, ours)?;
    let keep = (0..plan.units.len()).map(|i| unit_ref(plan, i)).collect();
    store.gc(&keep)?;
    if !plan.keep_units {
        release(store, plan)?;
    }
    Ok(marker)
}

/// Release the files of the plan's intermediate units that the run has not released already
/// ([`releasable`]; the executor releases most as soon as their dependents are done:
/// `exec::run_units`): what DIR keeps after a run is its outputs and the units' records, with
/// the small units the outputs are made from. Says how much it freed.
fn release(store: &Store, plan: &Plan) -> Result<()> {
    let mut freed = 0u64;
    for (i, kept) in releasable(plan)?.into_iter().enumerate() {
        if let Some(kept) = kept {
            freed += store.release(&unit_ref(plan, i), kept)?;
        }
    }
    say_released(freed);
    Ok(())
}

/// For each unit of the plan, whether it is released once its dependents are done, and the
/// files its release keeps ([`crate::units::stage::Stage::KEPT`]): the units of an intermediate
/// stage (tiles, per-tile M3C2 results), which a later run that needs them computes again, but
/// those a stage of the plan keeps for a later run ([`crate::units::stage::Stage::keeps`]: a
/// campaign's first and last surveys').
pub(crate) fn releasable(plan: &Plan) -> Result<Vec<Option<&'static [&'static str]>>> {
    let stages = registry();
    let mut kept = vec![false; plan.units.len()];
    for s in stages.stages() {
        if plan.of_kind(s.kind()).next().is_some() {
            for i in s.keeps(plan) {
                kept[i] = true;
            }
        }
    }
    plan.units
        .iter()
        .zip(kept)
        .map(|(u, kept)| {
            let stage = stages.get(u.kind())?;
            Ok((stage.intermediate() && !kept).then(|| stage.kept()))
        })
        .collect()
}

/// Tell the user how much releasing intermediate units freed, if anything.
pub(crate) fn say_released(freed: u64) {
    if freed > 0 {
        eprintln!(
            "talus: released {:.1} MiB of intermediate units (tiles, M3C2 results: a later run \
             computes again what it needs; --keep-units keeps them)",
            freed as f64 / f64::from(1 << 20)
        );
    }
}

/// The plan's final unit (whose record lists what to publish).
fn last_unit(plan: &Plan) -> Result<crate::store::UnitRef> {
    Ok(unit_ref(plan, final_unit(plan)?))
}

/// The path of the marker (the file published last) in the plan's last unit.
pub(crate) fn marker_path(store: &Store, plan: &Plan) -> Result<PathBuf> {
    Ok(store.unit_dir(&last_unit(plan)?)?.join(MARKER))
}

/// Which names in DIR are talus's outputs for this plan (a campaign's or a comparison's), so
/// that publishing replaces them and nothing else.
pub(crate) fn outputs_of(plan: &Plan) -> Result<fn(&str) -> bool> {
    let last = &plan.units[final_unit(plan)?];
    registry()
        .get(last.kind())?
        .is_output()
        .ok_or_else(|| Error::Internal(format!("unit {} publishes nothing", last.name)))
}

/// Whether `name` in DIR is an output of any stage that publishes (a comparison's or a
/// campaign's): what a command that does not know DIR's plan (`talus status`, `talus view`)
/// lets an interrupted publish's journal remove or place.
pub(crate) fn any_output(name: &str) -> bool {
    registry()
        .stages()
        .iter()
        .filter_map(|s| s.is_output())
        .any(|ours| ours(name))
}

/// Publish the plan's last unit's `publish` list into DIR as one set; returns the path of the
/// marker (the file published last) in its unit.
pub(crate) fn publish(store: &Store, plan: &Plan, ours: &dyn Fn(&str) -> bool) -> Result<PathBuf> {
    let unit = last_unit(plan)?;
    let list = publish_list(store, plan)?;
    let files: Vec<(PathBuf, String)> = list
        .iter()
        .map(|p| {
            let u = crate::store::UnitRef {
                kind: p.kind.clone(),
                name: p.unit.clone(),
            };
            Ok((store.unit_dir(&u)?.join(&p.file), p.name.clone()))
        })
        .collect::<Result<_>>()?;
    store.publish(&files, MARKER, ours)?;
    Ok(store.unit_dir(&unit)?.join(MARKER))
}

/// The published files in DIR that are not what the plan's run published: missing, or whose
/// size or CRC-32 differs from their source unit's record (a file edited or damaged in DIR).
/// Reads every published file once (`talus status`).
pub(crate) fn damaged_outputs(store: &Store, plan: &Plan) -> Result<Vec<String>> {
    let list = publish_list(store, plan)?;
    let mut bad = Vec::new();
    for p in &list {
        let u = crate::store::UnitRef {
            kind: p.kind.clone(),
            name: p.unit.clone(),
        };
        let want = store
            .done(&u)
            .and_then(|r| r.files.into_iter().find(|f| f.name == p.file));
        // Not through a link in DIR (`pairs` → elsewhere): such a file is not what was published.
        let got = crate::store::no_links(store.dir(), std::path::Path::new(&p.name))
            .ok()
            .and_then(|()| crate::store::crc_and_size(&store.dir().join(&p.name)).ok());
        if want.is_none_or(|w| got != Some((w.crc32, w.size))) {
            bad.push(p.name.clone());
        }
    }
    Ok(bad)
}

/// What the plan's final unit (done) lists to publish ([`listed_outputs`]).
fn publish_list(store: &Store, plan: &Plan) -> Result<Vec<Publish>> {
    let i = final_unit(plan)?;
    let unit = unit_ref(plan, i);
    let record = store
        .done(&unit)
        .ok_or_else(|| Error::Internal(format!("unit {} not done", unit.name)))?;
    listed_outputs(store, plan, i, &record)?
        .ok_or_else(|| Error::Internal(format!("unit {} publishes nothing", unit.name)))
}

/// What publishing unit `i` of the plan (done, with `record`) lists to publish, each entry
/// checked: a unit's file (kind, unit and file names that stay in their directories) published
/// under one of its stage's output names in DIR. A record is read back from DIR, which may come
/// from anyone: one that lists anything else is damaged (`Error::Damaged`: the executor
/// computes the unit again), and nothing of it is read or placed. None for a unit that
/// publishes nothing.
pub(crate) fn listed_outputs(
    store: &Store,
    plan: &Plan,
    i: usize,
    record: &crate::store::Record,
) -> Result<Option<Vec<Publish>>> {
    let unit = unit_ref(plan, i);
    let stage = registry().get(&unit.kind)?;
    let Some(ours) = stage.is_output() else {
        return Ok(None);
    };
    let damaged = |problem: String| Error::Damaged {
        path: store
            .unit_dir(&unit)
            .map(|d| d.join(crate::store::RECORD_FILE))
            .unwrap_or_default(),
        problem,
    };
    let list = match stage.publish_list(&record.meta) {
        Ok(Some(list)) => list,
        Ok(None) => return Ok(None),
        Err(e) => return Err(crate::units::stage::damaged_record(store, &unit, e)),
    };
    for p in &list {
        let ok = crate::store::UnitRef::new(p.kind.clone(), p.unit.clone()).is_ok()
            && crate::store::check_rel_path("file", &p.file).is_ok()
            && crate::store::check_rel_path("output", &p.name).is_ok()
            && ours(&p.name);
        if !ok {
            return Err(damaged(format!(
                "its list of outputs names {:?} of unit {:?} ({:?}) as {:?}: not a unit's file \
                 published as a talus output in DIR",
                p.file, p.unit, p.kind, p.name
            )));
        }
    }
    Ok(Some(list))
}
