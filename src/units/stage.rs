//! A stage of the pipeline, described once: its kind, how many units it has (one per survey,
//! pair, tile or run), which progress line it counts on, how it adds its units to a plan (its
//! key parts, its dependencies found by what they are, the memory it can refuse early), how one
//! of its units runs, and the typed meta its units record. The planner, the local executor,
//! `talus worker`, the Slurm executor, progress, `plan-stats` and the outputs all read stages
//! from the [`registry`]; none of them names a kind.
//!
//! Adding a stage is writing one module with a type that implements [`Stage`] and registering
//! it: in `default_stages` (the pipeline's own stages, in pipeline order), or with [`register`]
//! before anything reads the registry (`examples/survey_stage.rs` does so in its own `main`).

use std::sync::OnceLock;

use serde::de::DeserializeOwned;
use serde::Serialize;

use super::Ctx;
use crate::error::{Error, Result};
use crate::plan::{Plan, Spec};
use crate::store::UnitWriter;

/// How many units a stage has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scope {
    /// One per survey (tiling).
    Survey,
    /// One per run (the user's core points, a campaign's outputs).
    Run,
    /// One per pair (stable ground, events, outputs).
    Pair,
    /// One per pair and tile (M3C2, volumes): a Slurm task runs several of them.
    Tile,
    /// One per survey and tile (the orientation field's sample): as [`Scope::Tile`], a Slurm
    /// task runs several of them.
    SurveyTile,
}

impl Scope {
    /// Whether the stage has a unit per tile (of a pair or of a survey): its work spreads
    /// over the tiles, and a Slurm task runs several of its units.
    pub(crate) fn per_tile(self) -> bool {
        matches!(self, Scope::Tile | Scope::SurveyTile)
    }
}

/// The progress line a stage's units count on (stages may share one), and what it counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Line {
    pub name: &'static str,
    pub counts: &'static str,
    /// What the line's bar counts up to.
    pub total: Total,
}

/// What a progress line counts up to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Total {
    /// No known total (a spinner).
    Unknown,
    /// The surveys' points.
    SurveyPoints,
    /// The points of each pair's two surveys, over the pairs.
    PairPoints,
}

impl Total {
    /// The total for `plan`.
    pub(crate) fn of(&self, plan: &Plan) -> Option<u64> {
        match self {
            Total::Unknown => None,
            Total::SurveyPoints => Some(plan.surveys.iter().map(|s| s.points).sum()),
            Total::PairPoints => Some(
                plan.pairs
                    .iter()
                    .map(|p| plan.surveys[p.before].points + plan.surveys[p.after].points)
                    .sum(),
            ),
        }
    }
}

/// One kind of unit.
pub trait Stage: Send + Sync + 'static {
    /// Its kind: the plan's `spec.kind` and the store's folder (`units/<kind>/`).
    const KIND: &'static str;
    /// How many units it has.
    const SCOPE: Scope;
    /// The version of what its units write (tantivy versions its index format so). It is part of
    /// every unit's key, so a unit an older talus wrote is computed again, never reused beside
    /// new ones, after a `--resume` or an appended survey; units after it in the pipeline follow
    /// (their keys hold their dependencies'). Bump it whenever the stage's files or meta change
    /// for the same inputs: `tests/stage_versions.rs` fails when a stage's output on a fixed
    /// campaign changes and its version did not.
    const VERSION: u32;
    /// Whether its units' files are intermediate: read only by later units (tiles, per-tile
    /// M3C2 results), never published. After a finished run they are released
    /// ([`crate::store::Store::release`]: the record stays, the files go) unless `--keep-units`,
    /// and a later run that needs them (an appended survey, new parameters) computes them
    /// again — the same bytes, units being deterministic.
    const INTERMEDIATE: bool = false;
    /// The files an intermediate unit keeps when released: small records that units beyond its
    /// dependents read (the aligned unit's route, for every pair's and the campaign's summary).
    const KEPT: &'static [&'static str] = &[];
    /// The progress line (and summary.json stage) its units count on.
    const LINE: Line;
    /// What its units record (their record's meta, beside the executor's [`Timing`], which is
    /// not part of it: a field of any name is the stage's own). A field
    /// missing from a record is an error naming the unit, never a default.
    type Meta: Serialize + DeserializeOwned;

    /// Add its units to the plan (after every stage before it in the registry has added its
    /// own): their key parts (the parameters they use, the input files' keys) and dependencies
    /// (found by what they are: [`Planner::find`]). A need that certainly does not fit the memory
    /// budget is refused here, before anything runs.
    fn plan(p: &mut Planner) -> Result<()>;

    /// Run unit `unit` of the plan, writing its files into `out`.
    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<Self::Meta>;

    /// For a stage whose units publish DIR's outputs: which names in DIR are its outputs (so
    /// that publishing replaces them and nothing else), and the list its meta holds.
    fn publishes() -> Option<Publishes<Self::Meta>> {
        None
    }

    /// For a stage whose units hold a survey's tiles in the run's frame (the tiling; the
    /// aligned tiling where the alignment applied; the cleared one with `--vegetation remove`):
    /// the tiles' record, read from a unit's meta (None where that unit holds none). A later
    /// unit reads a survey's tiles from the last stage in the registry that provides them for it
    /// (`Ctx::tiles`), and planning counts every provider's unit of a survey among the units
    /// its readers depend on ([`Planner::survey_tiles`]): a new provider needs nothing more than
    /// this and its registration.
    const TILES: Option<TilesOf<Self::Meta>> = None;

    /// For a stage of the plan: the intermediate units of the plan that a later run will read
    /// and that are therefore not released after this one (a campaign keeps its first and last
    /// surveys' units for the survey appended next).
    fn keeps(_plan: &Plan) -> Vec<usize> {
        Vec::new()
    }
}

/// The tiles' record a unit of a tile-providing stage holds, from its meta ([`Stage::TILES`]).
pub type TilesOf<M> = fn(&M) -> Option<super::tiling::TilingMeta>;

/// What a publishing stage gives the executor.
pub struct Publishes<M> {
    /// Whether a name in DIR is one of this stage's outputs.
    pub(crate) is_output: fn(&str) -> bool,
    /// The files to publish, from a unit's meta.
    pub(crate) list: fn(&M) -> &[super::outputs::Publish],
}

/// What the executor keeps in every unit's record beside its meta: how long it ran and its peak
/// resident memory.
pub(crate) use crate::store::Timing;

/// A stage as the drivers see it: [`Stage`] without its types.
pub trait Registered: Send + Sync {
    fn kind(&self) -> &'static str;
    fn scope(&self) -> Scope;
    fn line(&self) -> Line;
    fn version(&self) -> u32;
    fn intermediate(&self) -> bool;
    fn kept(&self) -> &'static [&'static str];
    fn plan(&self, p: &mut Planner) -> Result<()>;
    fn run(&self, ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<serde_json::Value>;
    fn is_output(&self) -> Option<fn(&str) -> bool>;
    /// The outputs a unit's record lists (an error when its meta is not the stage's: the
    /// caller names the record, `damaged_record`).
    fn publish_list(
        &self,
        meta: &serde_json::Value,
    ) -> std::result::Result<Option<Vec<super::outputs::Publish>>, String>;
    fn provides_tiles(&self) -> bool;
    fn keeps(&self, plan: &Plan) -> Vec<usize>;
    /// [`Stage::TILES`] of a record's meta (an error when the meta is not the stage's).
    fn tiles(
        &self,
        meta: &serde_json::Value,
    ) -> std::result::Result<Option<super::tiling::TilingMeta>, String>;
}

struct Entry<S>(std::marker::PhantomData<S>);

impl<S: Stage> Registered for Entry<S> {
    fn kind(&self) -> &'static str {
        S::KIND
    }
    fn scope(&self) -> Scope {
        S::SCOPE
    }
    fn line(&self) -> Line {
        S::LINE
    }
    fn version(&self) -> u32 {
        S::VERSION
    }
    fn intermediate(&self) -> bool {
        S::INTERMEDIATE
    }
    fn kept(&self) -> &'static [&'static str] {
        S::KEPT
    }
    fn plan(&self, p: &mut Planner) -> Result<()> {
        S::plan(p)
    }
    fn run(&self, ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<serde_json::Value> {
        let meta = S::run(ctx, unit, out)?;
        serde_json::to_value(&meta)
            .map_err(|e| Error::Internal(format!("unit {}: meta: {e}", ctx.plan.units[unit].name)))
    }
    fn is_output(&self) -> Option<fn(&str) -> bool> {
        S::publishes().map(|p| p.is_output)
    }
    fn publish_list(
        &self,
        meta: &serde_json::Value,
    ) -> std::result::Result<Option<Vec<super::outputs::Publish>>, String> {
        let Some(p) = S::publishes() else {
            return Ok(None);
        };
        Ok(Some((p.list)(&Self::read(meta)?).to_vec()))
    }
    fn provides_tiles(&self) -> bool {
        S::TILES.is_some()
    }
    fn keeps(&self, plan: &Plan) -> Vec<usize> {
        S::keeps(plan)
    }
    fn tiles(
        &self,
        meta: &serde_json::Value,
    ) -> std::result::Result<Option<super::tiling::TilingMeta>, String> {
        match S::TILES {
            Some(of) => Ok(of(&Self::read(meta)?)),
            None => Ok(None),
        }
    }
}

impl<S: Stage> Entry<S> {
    /// A record's meta as `S`'s.
    fn read(meta: &serde_json::Value) -> std::result::Result<S::Meta, String> {
        <S::Meta as serde::Deserialize>::deserialize(meta).map_err(|e| e.to_string())
    }
}

/// `meta` (unit `unit`'s record, in `store`) as `M`. A record whose meta lacks a field is
/// damaged ([`Error::Damaged`] naming the record): never read as a default.
pub(crate) fn typed_meta<M: DeserializeOwned>(
    store: &crate::store::Store,
    unit: &crate::store::UnitRef,
    meta: &serde_json::Value,
) -> Result<M> {
    M::deserialize(meta).map_err(|e| damaged_record(store, unit, e))
}

/// Unit `unit`'s record (in `store`) is damaged: its meta does not read (`e`). The executor
/// finds the unit to compute again by the record's path.
pub(crate) fn damaged_record(
    store: &crate::store::Store,
    unit: &crate::store::UnitRef,
    e: impl std::fmt::Display,
) -> Error {
    Error::Damaged {
        path: store
            .unit_dir(unit)
            .map(|d| d.join(crate::store::RECORD_FILE))
            .unwrap_or_default(),
        problem: format!("unit {}: its record's meta: {e}", unit.name),
    }
}

/// The timing of `unit` in its record `rec` ([`crate::store::Record::timing`]); a record that
/// holds none is damaged, naming it.
pub(crate) fn timing_of(
    store: &crate::store::Store,
    unit: &crate::store::UnitRef,
    rec: &crate::store::Record,
) -> Result<Timing> {
    rec.timing().ok_or_else(|| Error::Damaged {
        path: store
            .unit_dir(unit)
            .map(|d| d.join(crate::store::RECORD_FILE))
            .unwrap_or_default(),
        problem: format!("unit {}: its record has no timing", unit.name),
    })
}

/// The stage `S` as the registry holds it.
pub(crate) fn entry<S: Stage>() -> &'static dyn Registered {
    // A zero-sized entry per stage type: leaking it costs nothing.
    Box::leak(Box::new(Entry::<S>(std::marker::PhantomData)))
}

/// The pipeline's stages, in pipeline order: a stage's units depend only on units of stages
/// before it (the Slurm executor runs one job array per stage in this order).
pub(crate) fn default_stages() -> Vec<&'static dyn Registered> {
    use super::*;
    vec![
        entry::<tiling::TilingStage>(),
        entry::<align::AlignStage>(),
        entry::<aligned::AlignedStage>(),
        entry::<cleared::ClearedStage>(),
        entry::<field::FieldStage>(),
        entry::<orient::OrientStage>(),
        entry::<cores::UserCoresStage>(),
        entry::<cores::ThinnedStage>(),
        entry::<m3c2::M3c2Stage>(),
        entry::<merged::MergedStage>(),
        entry::<sampled::SampledStage>(),
        entry::<stable::StableStage>(),
        entry::<events::kept::KeptStage>(),
        entry::<events::EventsStage>(),
        entry::<series::SeriesStage>(),
        entry::<volumes::VolumesStage>(),
        entry::<outputs::segments::SegmentsStage>(),
        entry::<outputs::points::PointsStage>(),
        entry::<outputs::OutputsStage>(),
        entry::<campaign::CampaignStage>(),
    ]
}

/// The stages of this program.
pub struct Registry {
    stages: Vec<&'static dyn Registered>,
}

static REGISTRY: OnceLock<Registry> = OnceLock::new();
static EXTRA: std::sync::Mutex<Vec<(&'static str, &'static dyn Registered)>> =
    std::sync::Mutex::new(Vec::new());

/// Register stage `S` after the stage of kind `after` (a program's own stage: call it first thing
/// in `main`, before anything reads the [`registry`]). Every process that runs the plan
/// (`talus worker`, a Slurm task) must be the same program: the registry is not in the plan.
pub fn register<S: Stage>(after: &'static str) -> Result<()> {
    if REGISTRY.get().is_some() {
        return Err(Error::Internal(format!(
            "stage {} registered after the registry was read",
            S::KIND
        )));
    }
    EXTRA
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push((after, entry::<S>()));
    Ok(())
}

/// The registry: the default stages, with the registered ones in their places.
pub fn registry() -> &'static Registry {
    REGISTRY.get_or_init(|| {
        let mut stages = default_stages();
        for (after, s) in EXTRA.lock().unwrap_or_else(|e| e.into_inner()).iter() {
            let at = stages
                .iter()
                .position(|x| x.kind() == *after)
                .map_or(stages.len(), |i| i + 1);
            stages.insert(at, *s);
        }
        Registry { stages }
    })
}

impl Registry {
    /// The stages in pipeline order.
    pub fn stages(&self) -> &[&'static dyn Registered] {
        &self.stages
    }

    /// The stage of `kind`.
    pub fn get(&self, kind: &str) -> Result<&'static dyn Registered> {
        self.stages
            .iter()
            .copied()
            .find(|s| s.kind() == kind)
            .ok_or_else(|| {
                Error::Internal(format!(
                    "a unit of kind {kind}, which this program has no stage for (a plan of \
                     another program?)"
                ))
            })
    }

    /// The rank of `kind` in pipeline order.
    pub(crate) fn rank(&self, kind: &str) -> Option<usize> {
        self.stages.iter().position(|s| s.kind() == kind)
    }

    /// The progress lines in pipeline order, each once.
    pub(crate) fn lines(&self) -> Vec<Line> {
        let mut out: Vec<Line> = Vec::new();
        for s in &self.stages {
            if !out.iter().any(|l| l.name == s.line().name) {
                out.push(s.line());
            }
        }
        out
    }
}

/// Where the run's core points come from, as planned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CoreSource {
    /// Each pair's before survey, thinned tile by tile inside its M3C2 units.
    PerPair,
    /// The user's core-point file (the plan's `core_points`).
    UserFile,
    /// A campaign: the first survey thinned once, for every pair.
    Campaign,
}

/// What the stages add their units through.
pub struct Planner<'a> {
    pub plan: &'a mut Plan,
    pub(crate) cores: CoreSource,
    /// A campaign's title (None: a comparison).
    pub(crate) campaign: Option<String>,
}

impl Planner<'_> {
    /// The unit of `spec`, if planned.
    pub fn find(&self, spec: &Spec) -> Option<usize> {
        self.plan.find(spec)
    }

    /// Run unit `unit` after units `after` without reading them ([`crate::plan::Unit::after`]).
    pub(crate) fn order_after(&mut self, unit: usize, after: Vec<usize>) {
        self.plan.units[unit].after = after;
    }

    /// Survey `s`'s own tiling: its unit, or its parts in order (`units::tiling::parts`).
    pub fn tiling_units(&self, s: usize) -> Result<Vec<usize>> {
        let units = self.plan.survey_units(super::tiling::TilingStage::KIND, s);
        if units.is_empty() {
            return Err(Error::Internal(format!(
                "no tiling of survey {s} planned before"
            )));
        }
        Ok(units)
    }

    /// The unit of `spec`, which an earlier stage must have planned.
    pub(crate) fn the(&self, spec: &Spec) -> Result<usize> {
        self.find(spec)
            .ok_or_else(|| Error::Internal(format!("no unit {spec:?} planned before")))
    }

    /// Add a unit (see `Plan::push`); the unit of `spec` if it is planned already (a survey
    /// tiled once serves every pair it is in).
    pub fn add(&mut self, spec: Spec, label: &str, key_parts: &[&str], deps: Vec<usize>) -> usize {
        if let Some(i) = self.find(&spec) {
            return i;
        }
        // The stage's version is part of the key ([`Stage::VERSION`]).
        let version = registry().get(&spec.kind).map_or(0, |s| s.version());
        let v = format!("{} v{version}", spec.kind);
        let mut parts = vec![v.as_str()];
        parts.extend_from_slice(key_parts);
        self.plan.push(spec, label, &parts, deps)
    }

    /// The unit the pairs' core points come from: the user's core points, or a campaign's
    /// thinned first survey (None: each M3C2 unit thins its tile of the before survey).
    pub(crate) fn core_unit(&self) -> Option<usize> {
        self.find(&Spec::run(super::cores::UserCoresStage::KIND))
            .or_else(|| self.find(&Spec::survey(super::cores::ThinnedStage::KIND, 0)))
    }

    /// Add pair `pair`'s unit of `kind`, keyed by `version`, the pair's two surveys (as the plan
    /// holds them: files, counts, bounds) and where its core points come from.
    pub(crate) fn add_pair(
        &mut self,
        kind: &'static str,
        pair: usize,
        version: &str,
        deps: Vec<usize>,
    ) -> usize {
        self.add_pair_spec(Spec::pair(kind, pair), "", version, deps)
    }

    /// [`Planner::add_pair`] for `n` units of `kind`, part k the k-th of `n` ranges of the
    /// pair's results in key order (`units::m3c2::seek::ranks`), each over `deps`; their indices.
    pub(crate) fn add_pair_ranges(
        &mut self,
        kind: &'static str,
        pair: usize,
        n: usize,
        version: &str,
        deps: &[usize],
    ) -> Vec<usize> {
        (0..n)
            .map(|k| {
                let spec = Spec {
                    part: Some(k as u32),
                    ..Spec::pair(kind, pair)
                };
                let key = format!("{version}|range {k} of {n}");
                self.add_pair_spec(spec, &format!("-p{k}"), &key, deps.to_vec())
            })
            .collect()
    }

    fn add_pair_spec(
        &mut self,
        spec: Spec,
        suffix: &str,
        version: &str,
        deps: Vec<usize>,
    ) -> usize {
        let pair = spec.pair.unwrap_or_default();
        let cores = super::m3c2::cores_key(self.core_unit());
        let (b, a) = (self.plan.pairs[pair].before, self.plan.pairs[pair].after);
        // The surveys as keys before `file_points` existed: the files' point counts decide how a
        // survey is tiled, not what a pair's units compute from it.
        let inputs: Vec<String> = [b, a]
            .iter()
            .map(|&s| {
                let mut sv = self.plan.surveys[s].clone();
                sv.file_points.clear();
                serde_json::to_string(&sv).unwrap_or_default()
            })
            .collect();
        let label = format!("{}{suffix}", self.plan.pairs[pair].label);
        self.add(
            spec,
            &label,
            &[version, &inputs[0], &inputs[1], cores],
            deps,
        )
    }

    /// The units holding pair `pair`'s M3C2 results: its M3C2 units, and its merged runs when
    /// the layout has more tiles than one merge holds (`units::merged`).
    pub(crate) fn pair_results(&self, pair: usize) -> Vec<usize> {
        let mut out = self.of_pair(super::m3c2::M3c2Stage::KIND, pair);
        out.extend(self.find(&Spec::pair(super::merged::MergedStage::KIND, pair)));
        out
    }

    /// The units of `kind` for pair `pair`, in plan order.
    pub(crate) fn of_pair(&self, kind: &str, pair: usize) -> Vec<usize> {
        self.plan.of_pair(kind, pair).collect()
    }

    /// The units that may hold survey `s`'s tiles, in pipeline order: its unit of every stage
    /// that provides tiles ([`Stage::TILES`]: the tiling, the aligned tiling, the cleared one).
    /// Which of them does is known once they ran (`Ctx::tiling`).
    pub fn survey_tiles(&self, s: usize) -> Result<Vec<usize>> {
        let out: Vec<usize> = registry()
            .stages()
            .iter()
            .filter(|st| st.provides_tiles())
            .flat_map(|st| self.plan.survey_units(st.kind(), s))
            .collect();
        if out.is_empty() {
            return Err(Error::Internal(format!("no unit holds survey {s}'s tiles")));
        }
        Ok(out)
    }
}

/// Plan the units of every pair of `plan` (and of the campaign, when `campaign` names one):
/// each stage in pipeline order adds its own. The final unit's key becomes the run's id.
pub(crate) fn plan_units(plan: &mut Plan, cores: CoreSource, campaign: Option<&str>) -> Result<()> {
    let mut p = Planner {
        plan,
        cores,
        campaign: campaign.map(str::to_string),
    };
    for s in registry().stages() {
        s.plan(&mut p)?;
    }
    check_plan(p.plan)?;
    let last = final_unit(p.plan)?;
    p.plan.run = p.plan.units[last].key.clone();
    Ok(())
}

/// Check what every executor relies on, once the stages have planned: each unit's stage is
/// registered and its spec names what the stage's [`Scope`] says (a survey, a pair, a pair's
/// tile, or nothing), and each unit depends only on units of earlier stages — so the stages in
/// registry order are a valid order to run them in (Slurm's arrays, `plan-stats`), and no
/// stage's planning can make a cycle. Returns each unit's stage rank (its stage's place in the
/// registry: Slurm's array, `plan-stats`' stage).
pub(crate) fn check_plan(plan: &Plan) -> Result<Vec<usize>> {
    let reg = registry();
    let mut ranks = Vec::with_capacity(plan.units.len());
    for u in &plan.units {
        let stage = reg.get(u.kind())?;
        let s = &u.spec;
        let fits = match stage.scope() {
            Scope::Survey => s.survey.is_some() && s.pair.is_none() && s.tile.is_none(),
            Scope::Pair => s.survey.is_none() && s.pair.is_some() && s.tile.is_none(),
            Scope::Tile => s.survey.is_none() && s.pair.is_some() && s.tile.is_some(),
            Scope::SurveyTile => s.survey.is_some() && s.pair.is_none() && s.tile.is_some(),
            Scope::Run => s.survey.is_none() && s.pair.is_none() && s.tile.is_none(),
        };
        if !fits {
            return Err(Error::Internal(format!(
                "unit {} of stage {} is planned as {s:?}, not one per {:?}",
                u.name,
                u.kind(),
                stage.scope()
            )));
        }
        // Registered (`reg.get` above): it has a rank.
        ranks.push(reg.rank(u.kind()).unwrap_or(usize::MAX));
    }
    for (i, u) in plan.units.iter().enumerate() {
        let mut before = u.deps.iter().chain(&u.after);
        if let Some(&d) = before.find(|&&d| d >= i || ranks[d] >= ranks[i]) {
            return Err(Error::Internal(format!(
                "unit {} ({}) depends on {} ({}), not of an earlier stage",
                u.name,
                u.kind(),
                plan.units[d].name,
                plan.units[d].kind()
            )));
        }
    }
    Ok(ranks)
}

/// The plan's final unit: the last unit of a stage that publishes DIR's outputs.
pub(crate) fn final_unit(plan: &Plan) -> Result<usize> {
    let reg = registry();
    (0..plan.units.len())
        .rev()
        .find(|&i| {
            reg.get(plan.units[i].kind())
                .is_ok_and(|s| s.is_output().is_some())
        })
        .ok_or_else(|| Error::Internal("a plan without an outputs unit".into()))
}
