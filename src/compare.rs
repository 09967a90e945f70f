//! `talus compare`: a one-pair plan (SPEC.md §2, §3), executed in this process and published.
//!
//! 1. check the inputs (headers, counts, overlap, meshes) and the user's values, before anything
//!    is written;
//! 2. open DIR's store, take its lock (one run per DIR), finish a publish a crash interrupted;
//! 3. measure the point spacing, resolve the parameters, key every input by its content, plan the
//!    tiles and the units, write the plan;
//! 4. execute the units not done ([`crate::exec`]; `--resume` reuses the store's units, whose
//!    names hold their keys; `--force` recomputes them);
//! 5. publish the outputs unit's files into DIR as one set, drop units no longer in the plan.

use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::io::{self, CloudInfo};
use crate::params::{Params, UserParams};
use crate::plan::{InputFile, Layout, Pair, Plan, Spec, Survey, PLAN_VERSION};
use crate::sampling;
use crate::store::Store;
use crate::units::outputs::{is_output, Publish, Summary, MARKER};
use crate::units::unit_ref;

/// Everything `compare` needs.
#[derive(Debug, Clone, Default)]
pub struct CompareOptions {
    pub before: PathBuf,
    pub after: PathBuf,
    pub out: PathBuf,
    pub config: Option<PathBuf>,
    pub core_points: Option<PathBuf>,
    pub user: UserParams,
    pub resume: bool,
    pub force: bool,
    pub before_mesh: Option<PathBuf>,
    pub after_mesh: Option<PathBuf>,
    /// Force the tile side (tests of tiling invariance); None = plan from the memory budget.
    pub tile_size: Option<f64>,
    /// Stop after M3C2: m3c2.laz (without smoothed values and event ids), summary.json and the
    /// viewer's terrain; no events, volumes or meshes.
    pub m3c2_only: bool,
}

/// The headers of the inputs, checked (before anything is written).
struct Inputs {
    before: CloudInfo,
    after: CloudInfo,
    cores: Option<CloudInfo>,
}

fn check_inputs(opts: &CompareOptions, user: &UserParams) -> Result<Inputs> {
    let before = io::open(&opts.before)?.info().clone();
    let after = io::open(&opts.after)?.info().clone();
    if !before.bounds.overlaps_xy(&after.bounds) {
        let (b, a) = (before.bounds, after.bounds);
        return Err(Error::Epochs(format!(
            "{} and {}: the epochs do not overlap (x {:.3}..{:.3}, y {:.3}..{:.3} vs x {:.3}..{:.3}, y {:.3}..{:.3})",
            opts.before.display(),
            opts.after.display(),
            b.min[0], b.max[0], b.min[1], b.max[1], a.min[0], a.max[0], a.min[1], a.max[1],
        )));
    }
    let cores = match &opts.core_points {
        Some(p) => Some(io::open(p)?.info().clone()),
        None => None,
    };
    match (&opts.before_mesh, &opts.after_mesh) {
        (Some(_), None) | (None, Some(_)) => {
            let p = opts.before_mesh.as_ref().or(opts.after_mesh.as_ref());
            return Err(Error::input(
                p.cloned().unwrap_or_default(),
                "--before-mesh and --after-mesh go together: give both surfaces",
            ));
        }
        _ => {}
    }
    for mesh in [&opts.before_mesh, &opts.after_mesh].into_iter().flatten() {
        if !mesh.is_file() {
            return Err(Error::input(mesh, "no such mesh file"));
        }
    }
    // Validate the user's values before measuring anything.
    Params::resolve(user, 1.0)?;
    user.check_lengths_within(&[before.bounds, after.bounds])?;
    Ok(Inputs {
        before,
        after,
        cores,
    })
}

fn survey(store: &Store, label: &str, info: &CloudInfo) -> Result<Survey> {
    Ok(Survey {
        label: label.into(),
        file: InputFile {
            path: std::fs::canonicalize(&info.path).unwrap_or_else(|_| info.path.clone()),
            key: store.content_key(&info.path)?,
        },
        points: info.point_count,
        bounds: info.bounds,
        format: info.format_detail.clone(),
        crs: info.crs.describe(),
        scale: info.scale,
    })
}

/// Plan the comparison of `opts` in `store`.
fn plan(store: &Store, opts: &CompareOptions, user: &UserParams, inputs: &Inputs) -> Result<Plan> {
    let spacing = sampling::measure(&opts.before)?;
    let params = Params::resolve(user, spacing.effective_spacing)?;
    let surveys = vec![
        survey(store, "before", &inputs.before)?,
        survey(store, "after", &inputs.after)?,
    ];
    let input = |p: &PathBuf| -> Result<InputFile> {
        Ok(InputFile {
            path: std::fs::canonicalize(p).unwrap_or_else(|_| p.clone()),
            key: store.content_key(p)?,
        })
    };
    let core_points = opts.core_points.as_ref().map(input).transpose()?;
    let meshes = match (&opts.before_mesh, &opts.after_mesh) {
        (Some(b), Some(a)) => Some([input(b)?, input(a)?]),
        _ => None,
    };
    let mut bounds = vec![inputs.before.bounds, inputs.after.bounds];
    bounds.extend(inputs.cores.as_ref().map(|c| c.bounds));
    let layout = Layout::plan(
        &bounds,
        inputs.before.point_count + inputs.after.point_count,
        &params,
        opts.tile_size,
    )?;
    let mut plan = Plan {
        version: PLAN_VERSION,
        run: String::new(),
        surveys,
        pairs: vec![Pair {
            label: "pair".into(),
            before: 0,
            after: 1,
        }],
        params,
        spacing,
        layout,
        core_points,
        meshes,
        m3c2_only: opts.m3c2_only,
        units: Vec::new(),
    };
    plan.add_pair_units(0)?;
    Ok(plan)
}

/// Prepare DIR: refuse one that holds something else unless --resume or --force.
fn open_store(opts: &CompareOptions) -> Result<(Store, bool)> {
    let out = &opts.out;
    let existed = out.exists();
    if existed && !out.is_dir() {
        return Err(Error::Usage(format!(
            "{}: --out exists and is not a directory",
            out.display()
        )));
    }
    if existed && !opts.resume && !opts.force {
        let mut entries = std::fs::read_dir(out).map_err(|e| Error::output(out, e))?;
        if entries.next().is_some() {
            return Err(Error::Usage(format!(
                "{}: the output directory is not empty; use --resume to continue a run there or --force to replace it",
                out.display()
            )));
        }
    }
    Ok((Store::open(out, true)?, !existed))
}

/// The path of the plan in a store.
pub fn plan_path(store: &Store) -> PathBuf {
    store.work().join("plan.json")
}

/// Run a comparison. On failure nothing is left under a final output name, and a DIR this run
/// created is removed when the failure is the input's (nothing worth resuming).
pub fn compare(opts: &CompareOptions) -> Result<Summary> {
    let config = match &opts.config {
        Some(p) => UserParams::from_toml_file(p)?,
        None => UserParams::default(),
    };
    let user = opts.user.clone().over(config);
    let inputs = check_inputs(opts, &user)?;
    let (store, created) = open_store(opts)?;
    let result = (|| {
        let command = std::env::args().collect::<Vec<_>>().join(" ");
        // The lock's run id is only for the lock file; the plan's run follows.
        let lock = store.lock("compare", &command)?;
        store.recover()?;
        let plan = plan(&store, opts, &user, &inputs)?;
        plan.save(&plan_path(&store))?;
        if opts.force {
            for i in 0..plan.units.len() {
                store.invalidate(&unit_ref(&plan, i))?;
            }
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(plan.params.threads.value)
            .build()
            .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
        let slots = plan.params.threads.value.min(2);
        pool.install(|| crate::exec::run(&store, &plan, slots, "compare"))?;
        let summary = publish(&store, &plan)?;
        let keep = (0..plan.units.len()).map(|i| unit_ref(&plan, i)).collect();
        store.gc(&keep)?;
        drop(lock);
        Ok(summary)
    })();
    match result {
        Ok(s) => Ok(s),
        Err(e) => {
            // Bad input found while streaming: nothing worth keeping.
            if created && matches!(e, Error::Input { .. } | Error::Usage(_) | Error::Epochs(_)) {
                let _ = std::fs::remove_dir_all(&opts.out);
            }
            Err(e)
        }
    }
}

/// Publish the plan's outputs unit into DIR as one set; returns its summary.
pub fn publish(store: &Store, plan: &Plan) -> Result<Summary> {
    let out = plan
        .find(&Spec::Outputs { pair: 0 })
        .ok_or_else(|| Error::Internal("a plan without outputs".into()))?;
    let unit = unit_ref(plan, out);
    let record = store
        .done(&unit)
        .ok_or_else(|| Error::Internal(format!("outputs unit {} not done", unit.name)))?;
    let list: Vec<Publish> = serde_json::from_value(record.meta["publish"].clone())
        .map_err(|e| Error::Internal(format!("outputs unit record: {e}")))?;
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
    store.publish(&files, MARKER, &is_output)?;
    let path = store.unit_dir(&unit)?.join(MARKER);
    let text = std::fs::read(&path).map_err(|e| Error::output(&path, e))?;
    serde_json::from_slice(&text).map_err(|e| Error::Internal(format!("summary.json: {e}")))
}
