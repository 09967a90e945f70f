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

pub(crate) mod inputs;
pub mod layout;
pub(crate) mod measured;
pub(crate) mod reach;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use talus_tiling::{Fnv64, TileId};

use crate::error::{Error, Result};
use crate::io::Bounds;
use crate::params::Params;
use crate::sampling::Spacing;
pub(crate) use layout::Layout;

/// The version of plan.json's layout (a plan of another version is planned again).
pub(crate) const PLAN_VERSION: u32 = 1;

/// An input file and its content key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputFile {
    pub path: PathBuf,
    pub key: String,
}

/// The user's stable areas: the file (its content's key enters the units that use them) and its
/// polygons.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StableAreas {
    pub file: InputFile,
    pub areas: crate::spatial::areas::Areas,
}

impl StableAreas {
    /// Read `path` and check it against the surveys: its CRS (when both name an EPSG code) and
    /// every polygon meeting the surveys' footprint. `key` is the file's content key.
    pub(crate) fn read(path: &Path, key: String, surveys: &[Survey]) -> Result<StableAreas> {
        let areas = crate::spatial::areas::Areas::read(path)?;
        if let Some(e) = areas.epsg {
            for s in surveys {
                if let Some(c) = s.epsg.filter(|&c| c != e) {
                    return Err(Error::input(
                        path,
                        format!(
                            "its polygons are in EPSG:{e}, the survey {} in EPSG:{c}: give the \
                             stable areas in the surveys' CRS",
                            s.arg.display()
                        ),
                    ));
                }
            }
        }
        let all = crate::io::Bounds::union(&surveys.iter().map(|s| s.bounds).collect::<Vec<_>>());
        for (i, b) in areas.boxes().iter().enumerate() {
            if b[2] < all.min[0] || b[0] > all.max[0] || b[3] < all.min[1] || b[1] > all.max[1] {
                return Err(Error::input(
                    path,
                    format!(
                        "polygon {i} ([{:.2}, {:.2}] to [{:.2}, {:.2}]) lies wholly outside the \
                         surveys (x {:.2} to {:.2}, y {:.2} to {:.2}): is it in their CRS?",
                        b[0], b[1], b[2], b[3], all.min[0], all.max[0], all.min[1], all.max[1]
                    ),
                ));
            }
        }
        Ok(StableAreas {
            file: InputFile {
                path: std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
                key,
            },
            areas,
        })
    }
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
    /// The EPSG code its CRS names, if any (checked against `--stable`'s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epsg: Option<u32>,
    /// Its first file's LAS coordinate transform ([scale, offset] per axis), which the units
    /// that write coordinates quantise to: read once when planning, not by every unit. None for
    /// text and PLY (and in a plan written before 0.3: `units::Ctx::quantum` reads the header).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transform: Option<[[f64; 2]; 3]>,
    /// The points of each of its files, when every one is LAS or LAZ (whose headers count them
    /// exactly): a survey larger than [`Plan::tiling_part`] is tiled in parts, ranges of these
    /// (`units::tiling::parts`). Empty for text and PLY, which are tiled whole.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub file_points: Vec<u64>,
}

/// Points a tiling unit reads at most by default on a cluster (`Plan::tiling_part`): 8 Mi
/// points, a few seconds of decoding, so that a 120M-point survey is tiled by 15 tasks. A
/// local run tiles each survey whole by default (`commands::run::tiling_part`).
pub const TILING_PART: u64 = 1 << 23;

/// A plan written before `tiling_part` existed tiled every survey whole.
fn default_tiling_part() -> u64 {
    u64::MAX
}

/// Two surveys compared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pair {
    pub label: String,
    pub before: usize,
    pub after: usize,
}

/// What a unit does: its kind (a stage's [`crate::units::stage::Stage::KIND`]) and which survey,
/// pair or tile it is for. Serialized as `{"kind": .., "survey" | "pair", "tile"}`, part of the
/// unit's key.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Spec {
    pub kind: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub survey: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pair: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tile: Option<[u32; 2]>,
    /// The part of a survey's units that split it (a survey's tiling in ranges of its points:
    /// `units::tiling::parts`); None where the survey is one unit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part: Option<u32>,
}

impl Spec {
    /// The one unit of `kind` in a run.
    pub(crate) fn run(kind: &str) -> Spec {
        Spec {
            kind: kind.into(),
            survey: None,
            pair: None,
            tile: None,
            part: None,
        }
    }

    /// The unit of `kind` for survey `survey`.
    pub fn survey(kind: &str, survey: usize) -> Spec {
        Spec {
            survey: Some(survey),
            ..Spec::run(kind)
        }
    }

    /// The unit of `kind` for part `part` of survey `survey`.
    pub(crate) fn survey_part(kind: &str, survey: usize, part: u32) -> Spec {
        Spec {
            survey: Some(survey),
            part: Some(part),
            ..Spec::run(kind)
        }
    }

    /// The unit of `kind` for pair `pair`.
    pub(crate) fn pair(kind: &str, pair: usize) -> Spec {
        Spec {
            pair: Some(pair),
            ..Spec::run(kind)
        }
    }

    /// The unit of `kind` for tile `tile` of survey `survey`.
    pub(crate) fn survey_tile(kind: &str, survey: usize, tile: TileId) -> Spec {
        Spec {
            survey: Some(survey),
            tile: Some([tile.col, tile.row]),
            ..Spec::run(kind)
        }
    }

    /// The unit of `kind` for tile `tile` of pair `pair`.
    pub(crate) fn tile(kind: &str, pair: usize, tile: TileId) -> Spec {
        Spec {
            pair: Some(pair),
            tile: Some([tile.col, tile.row]),
            ..Spec::run(kind)
        }
    }
}

/// A tile id from the plan's [col, row].
pub(crate) fn tile_id(t: [u32; 2]) -> TileId {
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
    /// Its key's own parts (`Plan::push`'s `key_parts`: the stage's version first, then the
    /// parameters and inputs it computes from), each as itself when short, else as a hash: what
    /// a later plan compares to say why a unit is computed again (`Plan::recomputed`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<String>,
    /// Units this one runs after without reading them (an order, not an input: not in its key,
    /// never computed again for it): m3c2.laz is written once the pair's volumes are done, so
    /// that the tiles the volumes read are released before it is on disk (issue 46, the peak).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub after: Vec<usize>,
}

impl Unit {
    pub(crate) fn kind(&self) -> &str {
        &self.spec.kind
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
    /// The stable areas the user gave (`--stable`), read and checked.
    #[serde(default)]
    pub stable_areas: Option<StableAreas>,
    /// The user's surfaces (before, after) instead of the local reconstruction.
    pub meshes: Option<[InputFile; 2]>,
    /// Stop after M3C2: no events, volumes or meshes.
    pub m3c2_only: bool,
    /// Keep the intermediate units' files after the run (`--keep-units`); by default they are
    /// released once the outputs are published (`exec::publish`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub keep_units: bool,
    /// A campaign whose pairs hold no per-core-point cloud of their own (no m3c2.laz; the
    /// viewer's terrain positions once, in the first pair's terrain.bin): the time series holds
    /// every pair's distance at every core point, and a campaign's disk stays within a bound
    /// of its inputs (issue 46). False for a comparison, and for a campaign run with
    /// `--pair-clouds`, whose pairs are exactly compare's outputs.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub lean_pairs: bool,
    /// Points a tiling unit reads at most (`--tiling-part`): a larger LAS/LAZ survey is tiled
    /// by several units, ranges of its points, each a task of its own on a cluster.
    #[serde(default = "default_tiling_part")]
    pub tiling_part: u64,
    /// Units this run computes again that DIR's previous run had under other keys, and why
    /// (`talus status` shows them).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub recomputed: Vec<Recomputed>,
    pub units: Vec<Unit>,
    /// Where each spec's unit sits in `units`, for [`Plan::find`]: not part of plan.json.
    #[serde(skip)]
    index: SpecIndex,
}

/// The index of each spec's unit in [`Plan::units`] (the first, should two units share one),
/// and how many units it covers. Built on the first [`Plan::find`] (a plan read from plan.json
/// starts without), kept in step by [`Plan::push`]; a plan whose units were changed another way
/// is searched unit by unit. Never part of a plan's equality.
#[derive(Clone, Default)]
struct SpecIndex(std::sync::OnceLock<(HashMap<Spec, usize>, usize)>);

impl SpecIndex {
    /// The index of `units`.
    fn of(units: &[Unit]) -> (HashMap<Spec, usize>, usize) {
        let mut map = HashMap::with_capacity(units.len());
        for (i, u) in units.iter().enumerate() {
            map.entry(u.spec.clone()).or_insert(i);
        }
        (map, units.len())
    }
}

impl PartialEq for SpecIndex {
    fn eq(&self, _: &SpecIndex) -> bool {
        true
    }
}

impl std::fmt::Debug for SpecIndex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SpecIndex")
    }
}

/// Why unit `u` is computed again where `o` (a previous plan's unit of the same spec) had
/// another key (see [`Plan::recomputed`]).
fn reason(o: &Unit, u: &Unit) -> String {
    if o.parts.is_empty() {
        "its key's parts were not recorded (an older talus made it)".to_string()
    } else if o.parts.first() != u.parts.first() {
        format!(
            "the stage's version changed ({} → {})",
            o.parts.first().map_or("?", String::as_str),
            u.parts.first().map_or("?", String::as_str)
        )
    } else if let Some(k) = (0..u.parts.len()).find(|&k| o.parts.get(k) != u.parts.get(k)) {
        let (a, b) = (o.parts.get(k).map_or("", String::as_str), &u.parts[k]);
        if a.starts_with('#') || b.starts_with('#') {
            format!("an input it computes from changed (key part {k})")
        } else {
            // Parameters are `|`-separated in a part: the first that differs.
            let (a, b) = a
                .split('|')
                .zip(b.split('|'))
                .find(|(x, y)| x != y)
                .unwrap_or((a, b));
            format!("a parameter it computes from changed ({a} → {b})")
        }
    } else {
        "a unit it reads is computed again".to_string()
    }
}

/// Key parts up to this length are kept as they are in the plan ([`Unit::parts`]): a parameter's
/// value, a stage's version; longer ones (a survey's description) as a hash.
const PART_SHOWN: usize = 512;

/// Units of one kind computed again for one reason (`Plan::recomputed`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Recomputed {
    pub kind: String,
    pub units: usize,
    pub reason: String,
}

/// A unit key: FNV-1a 64 over the parts, each length-prefixed (so ("ab","c") ≠ ("a","bc")).
pub(crate) fn key_of(parts: &[&str]) -> String {
    let mut h = Fnv64::new();
    for p in parts {
        h.write_str(p);
    }
    h.hex()
}

/// A name safe in file names: ASCII letters, digits, '-', '_', '.', the rest '_'.
pub(crate) fn slug(s: &str) -> String {
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
    /// A plan of `surveys` and `pairs` with no units yet (the stages add them:
    /// `units::stage::plan_units`), no run id, and none of the options: no core-point file,
    /// stable areas or meshes, every stage, the intermediate units released.
    pub(crate) fn new(
        surveys: Vec<Survey>,
        pairs: Vec<Pair>,
        params: Params,
        spacing: Spacing,
        layout: Layout,
    ) -> Plan {
        Plan {
            version: PLAN_VERSION,
            run: String::new(),
            surveys,
            pairs,
            params,
            spacing,
            layout,
            core_points: None,
            stable_areas: None,
            meshes: None,
            m3c2_only: false,
            keep_units: false,
            lean_pairs: false,
            tiling_part: u64::MAX,
            recomputed: Vec::new(),
            units: Vec::new(),
            index: SpecIndex::default(),
        }
    }

    /// Pair `pair` for messages: "BEFORE and AFTER" (the arguments) in a one-pair plan, "pair
    /// LABEL (BEFORE and AFTER)" in a campaign.
    pub(crate) fn pair_name(&self, pair: usize) -> String {
        let p = &self.pairs[pair];
        let (b, a) = (&self.surveys[p.before], &self.surveys[p.after]);
        let files = format!("{} and {}", b.arg.display(), a.arg.display());
        if self.pairs.len() == 1 {
            files
        } else {
            format!("pair {} ({files})", p.label)
        }
    }

    /// Add a unit: its key is over its spec, `key_parts` (what it computes from: parameters,
    /// input files' keys) and its dependencies' keys; returns its index.
    pub(crate) fn push(
        &mut self,
        spec: Spec,
        label: &str,
        key_parts: &[&str],
        deps: Vec<usize>,
    ) -> usize {
        let dep_keys: Vec<&str> = deps.iter().map(|&d| self.units[d].key.as_str()).collect();
        // The spec itself (which survey, pair, tile) is part of what the unit computes.
        let what = serde_json::to_string(&spec).unwrap_or_default();
        let mut parts = vec![what.as_str()];
        parts.extend_from_slice(key_parts);
        parts.extend(dep_keys);
        let key = key_of(&parts);
        let parts = key_parts
            .iter()
            .map(|p| {
                if p.len() <= PART_SHOWN {
                    (*p).to_string()
                } else {
                    format!("#{}", key_of(&[p]))
                }
            })
            .collect();
        let i = self.units.len();
        if let Some((map, covered)) = self.index.0.get_mut() {
            if *covered == i {
                map.entry(spec.clone()).or_insert(i);
                *covered += 1;
            }
        }
        self.units.push(Unit {
            name: format!("{}-{key}", slug(label)),
            key,
            deps,
            spec,
            parts,
            after: Vec::new(),
        });
        i
    }

    /// Why units not `done` (by index) are computed again where `old` (the plan of DIR's
    /// previous run) had a unit of the same spec under another key: by kind and
    /// reason, how many — the stage's version changed, a parameter or input it computes from
    /// changed (shown when short), or a unit it reads is computed again.
    pub(crate) fn recomputed(&self, old: &Plan, done: impl Fn(usize) -> bool) -> Vec<Recomputed> {
        let by_spec: HashMap<&Spec, &Unit> = old.units.iter().map(|u| (&u.spec, u)).collect();
        let mut out: Vec<Recomputed> = Vec::new();
        for (i, u) in self.units.iter().enumerate() {
            // The key first (in memory); the store is asked only about a unit whose key changed.
            let Some(&o) = by_spec.get(&u.spec) else {
                continue;
            };
            if o.key == u.key || done(i) {
                continue;
            }
            let why = reason(o, u);
            match out
                .iter_mut()
                .find(|r| r.kind == u.kind() && r.reason == why)
            {
                Some(r) => r.units += 1,
                None => out.push(Recomputed {
                    kind: u.kind().to_string(),
                    units: 1,
                    reason: why,
                }),
            }
        }
        out
    }

    /// The index of the unit of `spec` (the first, should two units share it).
    pub(crate) fn find(&self, spec: &Spec) -> Option<usize> {
        let (map, covered) = self.index.0.get_or_init(|| SpecIndex::of(&self.units));
        if *covered == self.units.len() {
            map.get(spec).copied()
        } else {
            self.units.iter().position(|u| &u.spec == spec)
        }
    }

    /// The units of `kind` for survey `survey`: its one unit, or its parts in order
    /// ([`Spec::part`]); empty when it has none.
    pub fn survey_units(&self, kind: &str, survey: usize) -> Vec<usize> {
        if let Some(u) = self.find(&Spec::survey(kind, survey)) {
            return vec![u];
        }
        (0u32..)
            .map_while(|k| self.find(&Spec::survey_part(kind, survey, k)))
            .collect()
    }

    /// The units of `kind` for `pair` (every pair for kinds without one), in plan order.
    pub(crate) fn of_kind<'a>(&'a self, kind: &'a str) -> impl Iterator<Item = usize> + 'a {
        (0..self.units.len()).filter(move |&i| self.units[i].kind() == kind)
    }

    /// The units of `kind` for pair `pair`, in plan order.
    pub(crate) fn of_pair<'a>(
        &'a self,
        kind: &'a str,
        pair: usize,
    ) -> impl Iterator<Item = usize> + 'a {
        self.of_kind(kind)
            .filter(move |&i| self.units[i].spec.pair == Some(pair))
    }

    /// Write the plan to `path` atomically.
    pub(crate) fn save(&self, path: &Path) -> Result<()> {
        let text =
            serde_json::to_vec_pretty(self).map_err(|e| Error::Internal(format!("plan: {e}")))?;
        Ok(talus_tiling::atomic_write(path, &text)?)
    }

    /// Read the plan at `path` (in DIR's store: a regular file, not through a link), and
    /// `Plan::check` it.
    pub fn load(path: &Path) -> Result<Plan> {
        let text = crate::store::read_store_file(path)
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
        plan.check().map_err(|problem| {
            Error::input(
                path,
                format!("a damaged plan ({problem}): run the command again with --force"),
            )
        })?;
        Ok(plan)
    }

    /// What every reader of a plan read back from DIR relies on: its run id and every unit's
    /// kind and name are single path components (they name directories of the store: nothing
    /// read or written through them leaves it), every dependency an earlier unit, every survey,
    /// pair and tile index within the plan. The problem, if any.
    pub(crate) fn check(&self) -> std::result::Result<(), String> {
        use crate::store::check_component;
        let n = self.surveys.len();
        if !self.run.is_empty() {
            check_component("run id", &self.run).map_err(|e| e.to_string())?;
        }
        for p in &self.pairs {
            if p.before >= n || p.after >= n {
                return Err(format!("pair {} names a survey it does not have", p.label));
            }
        }
        let tiles = self
            .layout
            .grid()
            .is_ok()
            .then_some((self.layout.cols, self.layout.rows));
        for (i, u) in self.units.iter().enumerate() {
            check_component("unit kind", u.kind()).map_err(|e| e.to_string())?;
            check_component("unit name", &u.name).map_err(|e| e.to_string())?;
            if u.deps.iter().any(|&d| d >= i) {
                return Err(format!(
                    "unit {i} depends on a unit that does not precede it"
                ));
            }
            let survey_ok = u.spec.survey.is_none_or(|s| s < n);
            let pair_ok = u.spec.pair.is_none_or(|p| p < self.pairs.len());
            let tile_ok = match (u.spec.tile, tiles) {
                (Some([c, r]), Some((cols, rows))) => c < cols && r < rows,
                (Some(_), None) => false,
                (None, _) => true,
            };
            if !(survey_ok && pair_ok && tile_ok) {
                return Err(format!(
                    "unit {i} is for a survey, pair or tile the plan does not have"
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn unit(parts: &[&str]) -> Unit {
        Unit {
            name: String::new(),
            key: key_of(parts),
            deps: Vec::new(),
            spec: Spec::run("m3c2"),
            parts: parts.iter().map(|p| p.to_string()).collect(),
            after: Vec::new(),
        }
    }

    /// A plan with no surveys, pairs or units, for the index's tests (and the executor's).
    pub(crate) fn empty_plan() -> Plan {
        let params = Params::resolve(&crate::params::UserParams::default(), 0.25).unwrap();
        let spacing = Spacing {
            spacing: 0.25,
            density: 16.0,
            effective_spacing: 0.25,
            measured_points: 0,
            method: String::new(),
        };
        let mut extent = Bounds::empty();
        extent.grow(&[0.0; 3]);
        extent.grow(&[20.0, 20.0, 1.0]);
        let layout = Layout {
            origin: [0.0; 2],
            tile_size: 10.0,
            cols: 2,
            rows: 2,
            halo: 1.0,
            anchor: [0.0; 3],
            core_spacing: 1.0,
            extent,
        };
        Plan::new(Vec::new(), Vec::new(), params, spacing, layout)
    }

    #[test]
    fn find_is_indexed_and_agrees_with_a_scan() {
        let mut plan = empty_plan();
        // Asked before any unit: the index is built empty, then kept in step by push.
        assert_eq!(plan.find(&Spec::run("a")), None);
        let specs = [
            Spec::run("a"),
            Spec::survey("t", 0),
            Spec::pair("p", 0),
            Spec::tile("m", 0, TileId { col: 1, row: 0 }),
            Spec::run("a"),
        ];
        for s in &specs {
            plan.push(s.clone(), "u", &[], Vec::new());
        }
        let scan = |p: &Plan, s: &Spec| p.units.iter().position(|u| &u.spec == s);
        for s in &specs {
            assert_eq!(plan.find(s), scan(&plan, s));
        }
        assert_eq!(plan.find(&Spec::run("b")), None);
        // Read back from its JSON: the same bytes, no index among them, and the index built
        // again on the first find.
        let text = serde_json::to_vec_pretty(&plan).unwrap();
        assert!(!String::from_utf8_lossy(&text).contains("index"));
        let back: Plan = serde_json::from_slice(&text).unwrap();
        assert_eq!(serde_json::to_vec_pretty(&back).unwrap(), text);
        assert_eq!(back, plan);
        for s in &specs {
            assert_eq!(back.find(s), scan(&plan, s));
        }
        // Units changed other than by push: searched one by one.
        let mut changed = back.clone();
        changed.units.remove(0);
        assert_eq!(changed.find(&Spec::survey("t", 0)), Some(0));
        assert_eq!(changed.find(&Spec::run("a")), Some(3));
        changed.units.pop();
        assert_eq!(changed.find(&Spec::run("a")), None);
    }

    #[test]
    fn a_unit_computed_again_says_why() {
        let old = unit(&["m3c2 v1", "0.5|2|measured"]);
        assert_eq!(
            reason(&old, &unit(&["m3c2 v2", "0.5|2|measured"])),
            "the stage's version changed (m3c2 v1 → m3c2 v2)"
        );
        assert_eq!(
            reason(&old, &unit(&["m3c2 v1", "0.5|3|measured"])),
            "a parameter it computes from changed (2 → 3)"
        );
        assert_eq!(
            reason(&old, &unit(&["m3c2 v1", "#0123456789abcdef"])),
            "an input it computes from changed (key part 1)"
        );
        assert_eq!(
            reason(&old, &unit(&["m3c2 v1", "0.5|2|measured"])),
            "a unit it reads is computed again"
        );
        let mut older = old.clone();
        older.parts.clear();
        assert!(reason(&older, &old).contains("older talus"));
    }
}
