//! `talus compare`: the whole run, stage by stage (SPEC.md §3).
//!
//! 1. check the inputs (headers, counts, overlap) and resolve the parameters;
//! 2. pass 1: stream each epoch into tiles with halos on disk ([`tiles`]);
//! 3. pass 2: per tile, normals and M3C2 for the core points it owns ([`m3c2_pass`]), a reader
//!    thread decoding the next tile while the current one is computed (bounded channel);
//! 4. outputs: m3c2.laz in a canonical order, summary.json ([`outputs`]).
//!
//! Every unit (an epoch's tiling, a tile's M3C2) is an immutable file recorded in the manifest
//! with the hash of what it was made from and the checksum of its files, so `--resume` redoes
//! only what is missing, stale or damaged ([`workdir`]). Each stage reports its progress on
//! stderr ([`progress`]).
//!
//! Tiling invariance: a tiled run writes the bytes of a whole-cloud run. Tiles are aligned to the
//! core-point grid, every tile uses the same local frame, M3C2's neighbourhood sums are exact
//! (so free of visiting order), the smoothing's run in a sorted order, and the events stage works
//! on global keys; `tests/tiling_invariance.rs` checks it.

pub mod event_outputs;
pub mod events_pass;
pub mod m3c2_pass;
pub mod outputs;
pub mod progress;
pub mod tiles;
pub mod view_export;
pub mod workdir;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::io::las_out::CoordinateGrid;
use crate::io::{self, CloudInfo};
use crate::params::{Params, UserParams};
use crate::sampling;
use progress::Stage;
use workdir::WorkDir;

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

/// One input as summary.json reports it.
#[derive(Debug, Clone, Serialize)]
pub struct InputSummary {
    pub path: PathBuf,
    pub format: String,
    pub points: u64,
    pub bounds: io::Bounds,
    pub crs: String,
}

impl InputSummary {
    fn of(info: &CloudInfo) -> Self {
        InputSummary {
            path: info.path.clone(),
            format: info.format_detail.clone(),
            points: info.point_count,
            bounds: info.bounds,
            crs: info.crs.describe(),
        }
    }
}

/// Wall time of one stage.
#[derive(Debug, Clone, Serialize)]
pub struct StageTime {
    pub stage: String,
    pub seconds: f64,
    /// True when the stage's units were all found done (`--resume`).
    pub reused: bool,
}

/// What summary.json holds.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub tool: String,
    pub version: String,
    pub inputs: Vec<InputSummary>,
    pub core_points_file: Option<PathBuf>,
    pub spacing: sampling::Spacing,
    pub parameters: Params,
    /// Noise and registration error measured on the stable ground (None: too little of it).
    pub stable: Option<crate::events::stable::Stable>,
    pub tiles: usize,
    pub tile_size: f64,
    pub core_points: u64,
    pub computed_points: u64,
    pub significant_points: u64,
    /// Core points kept by the significance filter (|d| ≥ τ and significant).
    pub kept_points: u64,
    pub events: usize,
    pub gain_events: usize,
    pub loss_events: usize,
    /// Events whose |volume| exceeds its 95 % uncertainty (the others stay out of the totals).
    pub significant_events: usize,
    /// Sum of the positive volumes of the significant events, m³.
    pub total_gain_m3: f64,
    /// Sum of the negative volumes of the significant events, m³ (≤ 0).
    pub total_loss_m3: f64,
    pub stages: Vec<StageTime>,
}

impl Summary {
    /// One line for the terminal.
    pub fn one_line(&self) -> String {
        format!(
            "talus: {} core points ({} with a distance, {} significant), {} event(s), {} significant: {} gain {:+.3} m³, {} loss {:+.3} m³; {} tile(s)",
            self.core_points,
            self.computed_points,
            self.significant_points,
            self.events,
            self.significant_events,
            self.gain_events,
            self.total_gain_m3,
            self.loss_events,
            self.total_loss_m3,
            self.tiles,
        )
    }
}

/// Run a comparison. On failure nothing is left under a final output name, and a DIR this run
/// created is removed unless finished units are worth resuming (interruption, I/O failure).
pub fn compare(opts: &CompareOptions) -> Result<Summary> {
    let config = match &opts.config {
        Some(p) => UserParams::from_toml_file(p)?,
        None => UserParams::default(),
    };
    let user = opts.user.clone().over(config);
    // Inputs: headers first, so that bad input fails before anything is written.
    let before = io::open(&opts.before)?.info().clone();
    let after = io::open(&opts.after)?.info().clone();
    if !before.bounds.overlaps_xy(&after.bounds) {
        return Err(Error::Epochs(format!(
            "{} and {}: the epochs do not overlap (x {:.3}..{:.3}, y {:.3}..{:.3} vs x {:.3}..{:.3}, y {:.3}..{:.3})",
            opts.before.display(),
            opts.after.display(),
            before.bounds.min[0],
            before.bounds.max[0],
            before.bounds.min[1],
            before.bounds.max[1],
            after.bounds.min[0],
            after.bounds.max[0],
            after.bounds.min[1],
            after.bounds.max[1],
        )));
    }
    let cores_info = match &opts.core_points {
        Some(p) => Some(io::open(p)?.info().clone()),
        None => None,
    };
    for mesh in [&opts.before_mesh, &opts.after_mesh].into_iter().flatten() {
        if !mesh.is_file() {
            return Err(Error::input(mesh, "no such mesh file"));
        }
    }
    // Validate the user's values before measuring anything.
    Params::resolve(&user, 1.0)?;
    user.check_lengths_within(&[before.bounds, after.bounds])?;
    let t0 = Instant::now();
    let spacing = sampling::measure(&opts.before)?;
    let params = Params::resolve(&user, spacing.effective_spacing)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(params.threads.value)
        .build()
        .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
    let key = run_key(opts, &params)?;
    let mut wd = WorkDir::prepare(&opts.out, &key, opts.resume, opts.force)?;
    let result = pool.install(|| {
        run_stages(
            opts,
            &mut wd,
            &before,
            &after,
            cores_info.as_ref(),
            spacing,
            params,
            t0,
        )
    });
    match result {
        Ok(s) => Ok(s),
        Err(e) => {
            // Bad input found while streaming: nothing worth keeping.
            if matches!(e, Error::Input { .. } | Error::Usage(_) | Error::Epochs(_)) {
                wd.discard_if_created();
            }
            Err(e)
        }
    }
}

/// The hash of everything a run's results depend on (inputs' identity and parameters).
fn run_key(opts: &CompareOptions, params: &Params) -> Result<String> {
    let mut h = talus_tiling::Fnv64::new();
    for p in [
        Some(&opts.before),
        Some(&opts.after),
        opts.core_points.as_ref(),
    ]
    .into_iter()
    .flatten()
    {
        h.write_str(&file_identity(p)?);
    }
    h.write_str(&serde_json::to_string(params).unwrap_or_default());
    Ok(h.hex())
}

/// Path, size and modification time: a changed file invalidates what was made from it.
pub fn file_identity(p: &Path) -> Result<String> {
    let m = std::fs::metadata(p).map_err(|e| Error::input(p, e.to_string()))?;
    let mtime = m
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let canon = std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    Ok(format!("{}|{}|{}", canon.display(), m.len(), mtime))
}

#[allow(clippy::too_many_arguments)]
fn run_stages(
    opts: &CompareOptions,
    wd: &mut WorkDir,
    before: &CloudInfo,
    after: &CloudInfo,
    cores: Option<&CloudInfo>,
    spacing: sampling::Spacing,
    params: Params,
    t0: Instant,
) -> Result<Summary> {
    let mut stages = vec![StageTime {
        stage: "inputs and parameters".into(),
        seconds: t0.elapsed().as_secs_f64(),
        reused: false,
    }];
    let layout = tiles::Layout::plan(before, after, cores, &params, opts.tile_size)?;
    let stage = Stage::start(
        "pass 1: tiling",
        Some(before.point_count + after.point_count),
        "points",
    );
    let tiled = tiles::tile_epochs(wd, &layout, opts, &params, &stage)?;
    stages.push(StageTime {
        stage: "pass 1: tiling".into(),
        seconds: stage.finish(if tiled.reused { "reused" } else { "" }),
        reused: tiled.reused,
    });
    let user_cores = match &opts.core_points {
        Some(p) => Some(m3c2_pass::UserCores::load(p, &layout)?),
        None => None,
    };
    // Every input point is owned by one tile, so the points of all tiles sum to the inputs'
    // counts; on a resume the bar's length is an estimate (the finished tiles' share is unknown
    // until they are read, and they are not).
    let stage = Stage::start(
        "pass 2: normals and M3C2",
        Some(before.point_count + after.point_count),
        "points",
    );
    let m3c2 = m3c2_pass::run(wd, &layout, &tiled, &params, user_cores.as_ref(), &stage)?;
    stages.push(StageTime {
        stage: "pass 2: normals and M3C2".into(),
        seconds: stage.finish(if m3c2.reused { "reused" } else { "" }),
        reused: m3c2.reused,
    });
    let stage = Stage::start(
        "stable ground: noise and registration",
        None,
        "core points sampled",
    );
    let (stable, params) = events_pass::measure_stable(&m3c2, params)?;
    stage.inc(stable.as_ref().map_or(0, |s| s.sampled_points as u64));
    stages.push(StageTime {
        stage: "stable ground".into(),
        seconds: stage.finish(&match &stable {
            Some(s) => format!(
                "reg_error {:.4}, σ_d {:.4}, threshold {:.4} ({} stable core points)",
                params.reg_error.value, s.sigma_d, params.threshold.value, s.stable_points
            ),
            None => "too few stable core points".into(),
        }),
        reused: false,
    });
    let ev = if opts.m3c2_only {
        events_pass::EventsOut::default()
    } else {
        let stage = Stage::start("events and volumes", None, "events");
        let ev = events_pass::run(
            &m3c2,
            &layout,
            &tiled,
            &params,
            stable.as_ref(),
            (opts.before_mesh.as_deref(), opts.after_mesh.as_deref()),
        )?;
        stage.inc(ev.events.len() as u64);
        stages.push(StageTime {
            stage: "events and volumes".into(),
            seconds: stage.finish(&format!("{} kept core points", ev.kept_points)),
            reused: false,
        });
        ev
    };
    let stage = Stage::start("outputs", None, "core points");
    let per_point = &ev.per_point;
    let mut terrain = view_export::TerrainSample::new(m3c2.count()?, layout.anchor);
    // Core points are C1 points or the user's: the finest coordinate quantum of the file they
    // come from keeps them exact.
    let scales: Vec<[f64; 3]> = [Some(before), cores]
        .iter()
        .flatten()
        .filter_map(|i| i.scale)
        .collect();
    let extent = &layout.extent;
    let written = outputs::write_m3c2_laz(
        wd,
        &m3c2,
        params.reg_error.value,
        &before.crs,
        CoordinateGrid::for_extent(extent.min, extent.max, &scales),
        &|k| per_point.get(&k).copied().unwrap_or((f64::NAN, 0)),
        &mut |k| terrain.push(k),
    )?;
    let meshes = if opts.m3c2_only {
        Vec::new()
    } else {
        let meshes = event_outputs::write_meshes(wd, &ev.events)?;
        event_outputs::write_tables(wd, &ev.events, &before.crs)?;
        event_outputs::write_regions(wd, &ev.events, &before.crs)?;
        meshes
    };
    terrain.write(wd, &before.crs, &meshes)?;
    stage.inc(written.core_points);
    stages.push(StageTime {
        stage: "outputs".into(),
        seconds: stage.finish(""),
        reused: false,
    });
    let mut inputs = vec![InputSummary::of(before), InputSummary::of(after)];
    if let Some(c) = cores {
        inputs.push(InputSummary::of(c));
    }
    let summary = Summary {
        tool: "talus".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        inputs,
        core_points_file: opts.core_points.clone(),
        spacing,
        parameters: params,
        stable,
        tiles: layout.grid.len(),
        tile_size: layout.grid.tile_size(),
        core_points: written.core_points,
        computed_points: written.computed,
        significant_points: written.significant,
        kept_points: ev.kept_points as u64,
        events: ev.events.len(),
        gain_events: ev
            .events
            .iter()
            .filter(|e| e.event.kind == crate::events::Kind::Gain)
            .count(),
        loss_events: ev
            .events
            .iter()
            .filter(|e| e.event.kind == crate::events::Kind::Loss)
            .count(),
        significant_events: ev.events.iter().filter(|e| e.significant).count(),
        total_gain_m3: ev
            .events
            .iter()
            .filter(|e| e.significant)
            .filter_map(|e| e.volume_m3)
            .filter(|v| *v > 0.0)
            .sum(),
        total_loss_m3: ev
            .events
            .iter()
            .filter(|e| e.significant)
            .filter_map(|e| e.volume_m3)
            .filter(|v| *v < 0.0)
            .sum(),
        stages,
    };
    outputs::write_summary(wd, &summary)?;
    Ok(summary)
}
