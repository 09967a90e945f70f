//! The plan of a run: its units and their dependencies (SPEC.md §3 "Units").
//!
//! A unit is one piece of work with immutable results: a survey's tiling, a tile's normals and
//! M3C2 for a pair, a pair's stable ground, a pair's events, a tile's event volumes, a pair's
//! outputs. Each has a **key**, a hash of what its result depends on — its inputs' content (the
//! files' content keys, `store::Store::content_key`), the parameters it uses, and the keys of the
//! units it reads (a Merkle chain: a change anywhere upstream changes every key below it, and
//! nothing else). A unit's name holds its key, so a finished unit with that name is exactly the
//! result wanted, whichever process or run made it, and `--resume` needs no other bookkeeping.
//!
//! The plan is written to `DIR/.talus/plan.json`, so that any process (`talus worker DIR`, a
//! Slurm array task) can run any unit whose dependencies are done. A `compare` is a one-pair
//! plan; a campaign is a bigger one with the same kinds of units.

pub mod fit;
pub mod inputs;
pub mod layout;
pub mod reach;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use talus_tiling::{Fnv64, TileId};

use crate::error::{Error, Result};
use crate::io::Bounds;
use crate::params::Params;
use crate::sampling::Spacing;
pub use layout::Layout;

/// The version of plan.json's layout (a plan of another version is planned again).
pub const PLAN_VERSION: u32 = 1;

/// An input file and its content key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputFile {
    pub path: PathBuf,
    pub key: String,
}

/// One survey (epoch) of the run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Survey {
    /// A short name for unit names and outputs (`before`, `after`, a date, a label).
    pub label: String,
    /// The argument as given: a file, a folder or a pattern of tiles.
    pub arg: PathBuf,
    /// Its files, in name order, with their content keys.
    pub files: Vec<InputFile>,
    /// The survey's content key: over its files' keys.
    pub key: String,
    /// When it was surveyed (`YYYY-MM-DD`; campaigns).
    pub date: Option<String>,
    pub points: u64,
    pub bounds: Bounds,
    /// e.g. `LAZ 1.4 point format 6`.
    pub format: String,
    /// e.g. `EPSG:32755`.
    pub crs: String,
    /// The LAS scale factors (coordinate quanta), None for text and PLY.
    pub scale: Option<[f64; 3]>,
}

/// Two surveys compared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pair {
    pub label: String,
    pub before: usize,
    pub after: usize,
}

/// What a unit does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Spec {
    /// Cut a survey into the layout's tiles.
    Tiling { survey: usize },
    /// Cut the user's core-point file into the layout's tiles.
    Cores,
    /// The core points of every pair of a campaign: a survey thinned on the core-point grid.
    Thinned { survey: usize },
    /// Normals and M3C2 for the core points one tile owns.
    M3c2 { pair: usize, tile: [u32; 2] },
    /// Noise and registration error on the pair's stable ground.
    Stable { pair: usize },
    /// The pair's events: filter, smoothing, signed clustering, description.
    Events { pair: usize },
    /// The volumes of the pair's events whose centroid a tile owns.
    Volumes { pair: usize, tile: [u32; 2] },
    /// The pair's outputs, ready to publish.
    Outputs { pair: usize },
    /// The campaign's outputs: table, tracks, time series, magnitude–frequency, report.
    Campaign,
}

impl Spec {
    /// The kind, as in unit names and store directories.
    pub fn kind(&self) -> &'static str {
        match self {
            Spec::Tiling { .. } => "tiling",
            Spec::Cores => "cores",
            Spec::Thinned { .. } => "cores",
            Spec::M3c2 { .. } => "m3c2",
            Spec::Stable { .. } => "stable",
            Spec::Events { .. } => "events",
            Spec::Volumes { .. } => "volumes",
            Spec::Outputs { .. } => "outputs",
            Spec::Campaign => "campaign",
        }
    }
}

/// A tile id from the plan's [col, row].
pub fn tile_id(t: [u32; 2]) -> TileId {
    TileId {
        col: t[0],
        row: t[1],
    }
}

/// One unit of the plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Unit {
    /// Store directory: `units/<kind>/<name>`; the name ends in the key.
    pub name: String,
    pub key: String,
    /// Indices (into `Plan::units`) of the units whose results this one reads.
    pub deps: Vec<usize>,
    pub spec: Spec,
}

impl Unit {
    pub fn kind(&self) -> &'static str {
        self.spec.kind()
    }
}

/// Everything a run needs, for any process that executes its units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    pub version: u32,
    /// The run's id: the key of its final units (so the same work is the same run).
    pub run: String,
    pub surveys: Vec<Survey>,
    pub pairs: Vec<Pair>,
    /// Parameters as resolved before M3C2 (the stable-ground unit measures the rest).
    pub params: Params,
    pub spacing: Spacing,
    pub layout: Layout,
    pub core_points: Option<InputFile>,
    /// The user's surfaces (before, after) instead of the local reconstruction.
    pub meshes: Option<[InputFile; 2]>,
    /// Stop after M3C2: no events, volumes or meshes.
    pub m3c2_only: bool,
    pub units: Vec<Unit>,
}

/// A unit key: FNV-1a 64 over the parts, each length-prefixed (so ("ab","c") ≠ ("a","bc")).
pub fn key_of(parts: &[&str]) -> String {
    let mut h = Fnv64::new();
    for p in parts {
        h.write_str(p);
    }
    h.hex()
}

/// A name safe in file names: ASCII letters, digits, '-', '_', '.', the rest '_'.
pub fn slug(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

impl Plan {
    /// Pair `pair` for messages: "BEFORE and AFTER" (the arguments) in a one-pair plan, "pair
    /// LABEL (BEFORE and AFTER)" in a campaign.
    pub fn pair_name(&self, pair: usize) -> String {
        let p = &self.pairs[pair];
        let (b, a) = (&self.surveys[p.before], &self.surveys[p.after]);
        let files = format!("{} and {}", b.arg.display(), a.arg.display());
        if self.pairs.len() == 1 {
            files
        } else {
            format!("pair {} ({files})", p.label)
        }
    }

    /// Add a unit; returns its index.
    fn push(&mut self, spec: Spec, label: &str, key_parts: &[&str], deps: Vec<usize>) -> usize {
        let dep_keys: Vec<&str> = deps.iter().map(|&d| self.units[d].key.as_str()).collect();
        // The spec itself (which survey, pair, tile) is part of what the unit computes.
        let what = serde_json::to_string(&spec).unwrap_or_default();
        let mut parts = vec![what.as_str()];
        parts.extend_from_slice(key_parts);
        parts.extend(dep_keys);
        let key = key_of(&parts);
        self.units.push(Unit {
            name: format!("{}-{key}", slug(label)),
            key,
            deps,
            spec,
        });
        self.units.len() - 1
    }

    /// The unit of the campaign's core points: survey `survey` thinned on the core-point grid.
    pub fn add_thinned_cores(&mut self, survey: usize) -> usize {
        let t = self.tiling_unit(survey);
        let c = self.params.core_spacing.value.to_string();
        let label = format!("thinned-{}", self.surveys[survey].label);
        self.push(Spec::Thinned { survey }, &label, &[&c], vec![t])
    }

    /// The tiling unit of survey `s` (added when missing): a survey tiled once serves every pair
    /// it is in.
    fn tiling_unit(&mut self, s: usize) -> usize {
        if let Some(i) = self.find(&Spec::Tiling { survey: s }) {
            return i;
        }
        let (key, label, layout) = (
            self.surveys[s].key.clone(),
            self.surveys[s].label.clone(),
            self.layout.key(),
        );
        // The frames a tile file is written in (their size comes from the memory budget): the
        // same points in other frames are other bytes.
        let frames = match self.layout.grid() {
            Ok(g) => format!(
                "frame {}",
                crate::units::tiling::frame_points(self, g.len())
            ),
            Err(_) => String::new(),
        };
        self.push(
            Spec::Tiling { survey: s },
            &label,
            &[&key, &layout, &frames],
            Vec::new(),
        )
    }

    /// The units of pair `pair`, appended: its surveys' tilings (when not there yet), an M3C2
    /// unit per tile, the stable ground, the events, a volumes unit per tile and the outputs (no
    /// events, volumes with `m3c2_only`); the pair's outputs unit becomes the run's id. The core
    /// points are `cores` (a core-point unit), the user's file when the plan has one, else the
    /// pair's before survey thinned tile by tile inside the M3C2 units.
    pub fn add_pair_units(&mut self, pair: usize, cores: Option<usize>) -> Result<usize> {
        fit::check_planned(self, pair)?;
        let grid = self.layout.grid()?;
        let layout_key = self.layout.key();
        let (b, a) = (self.pairs[pair].before, self.pairs[pair].after);
        let label = self.pairs[pair].label.clone();
        let (tb, ta) = (self.tiling_unit(b), self.tiling_unit(a));
        let m3c2 = format!(
            "{:?}|{}",
            self.params.m3c2(),
            self.params.core_spacing.value
        );
        let core_unit = match (cores, self.core_points.clone()) {
            (Some(c), _) => Some(c),
            (None, Some(c)) => Some(match self.find(&Spec::Cores) {
                Some(i) => i,
                None => self.push(Spec::Cores, "cores", &[&c.key, &layout_key], Vec::new()),
            }),
            (None, None) => None,
        };
        // The core points are a core-point unit's (its key is a dependency's), or the thinning's.
        let cores = match core_unit {
            Some(_) => "core-point unit".to_string(),
            None => "thinned C1".to_string(),
        };
        let tiles: Vec<TileId> = grid.tiles().collect();
        let m3c2_units: Vec<usize> = tiles
            .iter()
            .map(|t| {
                self.push(
                    Spec::M3c2 {
                        pair,
                        tile: [t.col, t.row],
                    },
                    &format!("{label}-{}", t.name()),
                    &[&m3c2, &cores],
                    [tb, ta].into_iter().chain(core_unit).collect(),
                )
            })
            .collect();
        let samples = crate::units::stable::SAMPLES.to_string();
        let stable = self.push(
            Spec::Stable { pair },
            &label,
            &[&samples],
            m3c2_units.clone(),
        );
        let mut final_deps = vec![stable];
        final_deps.extend(&m3c2_units);
        if !self.m3c2_only {
            let p = &self.params;
            let user = |r: &crate::params::Resolved<f64>| {
                if r.source == "user" {
                    r.value.to_string()
                } else {
                    "measured".into()
                }
            };
            let events_params = format!(
                "{}|{}|{}|{}|{}|{}",
                user(&p.reg_error),
                user(&p.threshold),
                p.smooth_k.value,
                p.smooth_sigma.value,
                p.eps.value,
                p.cluster_min_points.value
            );
            let mut deps = vec![stable];
            deps.extend(&m3c2_units);
            let events = self.push(Spec::Events { pair }, &label, &[&events_params], deps);
            let meshes = self
                .meshes
                .as_ref()
                .map_or("points".to_string(), |[m1, m2]| {
                    format!("{}|{}", m1.key, m2.key)
                });
            let volume_params = format!(
                "{}|{}|{}",
                self.params.cyl_radius.value,
                self.params.cyl_halflen.value,
                self.params.point_spacing.value
            );
            let volumes: Vec<usize> = tiles
                .iter()
                .map(|t| {
                    self.push(
                        Spec::Volumes {
                            pair,
                            tile: [t.col, t.row],
                        },
                        &format!("{label}-{}", t.name()),
                        &[&volume_params, &meshes],
                        vec![events, stable, tb, ta],
                    )
                })
                .collect();
            final_deps.push(events);
            final_deps.extend(volumes);
        }
        let inputs: Vec<String> = [b, a]
            .iter()
            .map(|&s| serde_json::to_string(&self.surveys[s]).unwrap_or_default())
            .collect();
        let version = format!("{}|{}", env!("CARGO_PKG_VERSION"), self.m3c2_only);
        let out = self.push(
            Spec::Outputs { pair },
            &label,
            &[&version, &inputs[0], &inputs[1], &cores],
            final_deps,
        );
        self.run = self.units[out].key.clone();
        Ok(out)
    }

    /// The campaign unit over every pair's outputs (and M3C2 units, for the time series); it
    /// becomes the run's id.
    pub fn add_campaign_unit(&mut self, cores: usize, title: &str) -> usize {
        let mut deps = vec![cores];
        deps.extend(self.of_kind("outputs").collect::<Vec<_>>());
        deps.extend(self.of_kind("m3c2").collect::<Vec<_>>());
        let pairs = serde_json::to_string(&self.pairs).unwrap_or_default();
        let version = env!("CARGO_PKG_VERSION");
        let c = self.push(Spec::Campaign, "campaign", &[version, &pairs, title], deps);
        self.run = self.units[c].key.clone();
        c
    }

    /// The index of the unit of `spec`.
    pub fn find(&self, spec: &Spec) -> Option<usize> {
        self.units.iter().position(|u| &u.spec == spec)
    }

    /// The units of `kind` for `pair` (every pair for kinds without one), in plan order.
    pub fn of_kind<'a>(&'a self, kind: &'a str) -> impl Iterator<Item = usize> + 'a {
        (0..self.units.len()).filter(move |&i| self.units[i].kind() == kind)
    }

    /// Write the plan to `path` atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text =
            serde_json::to_vec_pretty(self).map_err(|e| Error::Internal(format!("plan: {e}")))?;
        talus_tiling::atomic_write(path, &text).map_err(layout::tiling_error)
    }

    /// Read the plan at `path`.
    pub fn load(path: &Path) -> Result<Plan> {
        let text = std::fs::read(path)
            .map_err(|e| Error::input(path, format!("cannot read the run's plan: {e}")))?;
        let plan: Plan = serde_json::from_slice(&text)
            .map_err(|e| Error::input(path, format!("not a talus plan: {e}")))?;
        if plan.version != PLAN_VERSION {
            return Err(Error::input(
                path,
                format!(
                    "a plan of version {} (this talus writes {PLAN_VERSION}): run the command again",
                    plan.version
                ),
            ));
        }
        Ok(plan)
    }
}
