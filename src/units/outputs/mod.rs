//! An outputs unit: a pair's result files (SPEC.md §2), written into the unit like any other and
//! published into DIR as one set by the executor (`store::Store::publish`): events.geojson,
//! event_regions.geojson, events.csv, view.json and summary.json here; m3c2.laz and terrain.bin
//! stay in the pair's points unit ([`points`]) and the meshes in the volumes units that wrote
//! them, and are published from there (the record's `publish` list says which file goes where).

pub(crate) mod laz;
pub(crate) mod points;
pub(crate) mod segments;
pub(crate) mod tables;
pub(crate) mod view;

use rustc_hash::FxHashMap as HashMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::events::EventsStage;
use super::series::SeriesStage;
use super::stable::StableStage;
use super::stage::{registry, Line, Planner, Publishes, Scope, Stage, Total};
use super::volumes::{mesh_files, Measured, VolumesStage};
use super::Ctx;
use crate::error::{Error, Result};
use crate::events::stable::Stable;
use crate::events::{Event, Kind};
use crate::io::{self, Bounds};
use crate::params::Params;
use crate::plan::Spec;
use crate::sampling::Spacing;
use crate::store::UnitWriter;
use crate::volume::uncertainty::VolumeUncertainty;
use points::{PointsMeta, PointsStage};

/// The file that completes a published set (written last, removed first).
pub(crate) const MARKER: &str = "summary.json";

/// The names of DIR entries talus writes (so that publishing may replace them; anything else in
/// DIR is the user's).
pub(crate) fn is_output(name: &str) -> bool {
    matches!(
        name,
        "m3c2.laz"
            | "events.geojson"
            | "events.csv"
            | "event_regions.geojson"
            | "summary.json"
            | "view.json"
            | "terrain.bin"
    ) || name
        .strip_prefix("meshes/")
        .is_some_and(tables::is_event_mesh)
}

/// One event with its volume, as the outputs report it.
#[derive(Debug, Clone)]
pub(crate) struct EventRecord {
    pub(crate) event: Event,
    pub(crate) volume_m3: Option<f64>,
    pub(crate) volume_uncertainty_m3: Option<f64>,
    pub(crate) uncertainty: Option<VolumeUncertainty>,
    /// |V| exceeds its 95 % half-width.
    pub(crate) significant: bool,
    pub(crate) gain_m3: Option<f64>,
    pub(crate) loss_m3: Option<f64>,
    pub(crate) footprint_area_m2: Option<f64>,
    pub(crate) region_area_m2: Option<f64>,
    pub(crate) coverage: Option<f64>,
    pub(crate) volume_note: Option<String>,
    /// The volume covers the whole change (see `units::volumes::Measured::complete`).
    pub(crate) complete: bool,
    pub(crate) region: Vec<Vec<Vec<crate::io::Point3>>>,
    /// The share of its core points that look like vegetation in either epoch.
    pub(crate) vegetation_fraction: Option<f64>,
    /// Most of its core points look like vegetation (`events::vegetation::MOST`).
    pub(crate) vegetation: bool,
    /// The data decides the event's sign (`units::volumes::sign_known`).
    pub(crate) sign_known: bool,
}

impl EventRecord {
    fn new(mut event: Event, m: Measured) -> EventRecord {
        event.obb = m.obb;
        // `kind` is the sign of the event's net volume where it has one: the cluster's sign
        // (its smoothed distances) says where change began, but the region it is measured over
        // may hold more of the other sign (a shrub resampled, a loss beside a larger gain), and
        // a "loss" with a positive volume contradicts itself. Without a volume, the cluster's.
        match m.volume_m3 {
            Some(v) if v > 0.0 => event.kind = Kind::Gain,
            Some(v) if v < 0.0 => event.kind = Kind::Loss,
            _ => {}
        }
        let u = m.uncertainty.map(|u| u.half_width_95_m3);
        let vegetation = m
            .vegetation_fraction
            .is_some_and(|f| f > crate::events::vegetation::MOST);
        EventRecord {
            vegetation_fraction: m.vegetation_fraction,
            vegetation,
            significant: matches!((m.volume_m3, u), (Some(v), Some(u)) if v.abs() > u),
            event,
            volume_m3: m.volume_m3,
            volume_uncertainty_m3: u,
            uncertainty: m.uncertainty,
            gain_m3: m.gain_m3,
            loss_m3: m.loss_m3,
            footprint_area_m2: m.footprint_area_m2,
            region_area_m2: m.region_area_m2,
            coverage: m.coverage,
            volume_note: m.note,
            complete: m.complete,
            region: m.region,
            sign_known: m.sign_known,
        }
    }
}

/// One input as summary.json reports it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct InputSummary {
    pub(crate) path: PathBuf,
    pub(crate) format: String,
    pub(crate) points: u64,
    pub(crate) bounds: Bounds,
    pub(crate) crs: String,
}

/// The work of one stage: its units and the seconds they took (summed over the units, in
/// whichever processes ran them).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct StageTime {
    pub(crate) stage: String,
    pub(crate) units: usize,
    pub(crate) seconds: f64,
}

/// What summary.json holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    pub(crate) tool: String,
    pub(crate) version: String,
    pub(crate) inputs: Vec<InputSummary>,
    pub(crate) core_points_file: Option<PathBuf>,
    pub(crate) spacing: Spacing,
    pub(crate) parameters: Params,
    /// Noise and registration error measured on the stable ground (None: too little of it).
    pub(crate) stable: Option<Stable>,
    /// With `--stable`: what the user's areas held (points inside, with a distance) and whether
    /// the stable ground is theirs (else why not, and what was used instead).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) stable_areas: Option<crate::events::stable::AreasUse>,
    pub(crate) tiles: usize,
    pub(crate) tile_size: f64,
    pub(crate) core_points: u64,
    pub(crate) computed_points: u64,
    pub(crate) significant_points: u64,
    /// Core points kept by the significance filter (|d| ≥ τ and significant).
    pub(crate) kept_points: u64,
    pub(crate) events: usize,
    /// The events the totals count ([`Totals::counted`]) that gained, and that lost.
    pub(crate) gain_events: usize,
    pub(crate) loss_events: usize,
    /// Events whose |volume| exceeds its 95 % uncertainty (the others stay out of the totals).
    pub(crate) significant_events: usize,
    /// Events most of whose core points look like vegetation; with `--vegetation flag` or
    /// `remove` they stay out of the totals.
    #[serde(default)]
    pub(crate) vegetation_events: usize,
    /// Sum of the volumes of the gain events the totals count, m³.
    pub(crate) total_gain_m3: f64,
    /// Sum of the volumes of the loss events they count, m³ (≤ 0).
    pub(crate) total_loss_m3: f64,
    /// What the totals hold, and every event they leave out, by why.
    pub(crate) totals: Totals,
    /// How far M3C2 looked for the other epoch (SPEC.md §1 "Change of any depth").
    #[serde(default)]
    pub(crate) reach: ReachSummary,
    /// The later survey's alignment onto the first (absent with `--align off`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) alignment: Option<AlignmentSummary>,
    /// The LAS classes compared and the points each survey left out by class.
    #[serde(default)]
    pub(crate) classes: ClassesSummary,
    /// With `--vegetation remove`: the points judged vegetation-like and dropped before M3C2,
    /// before then after.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) vegetation_removed: Option<[u64; 2]>,
    pub(crate) stages: Vec<StageTime>,
    /// The run computed M3C2 alone (`--m3c2-only`): no events, no totals.
    #[serde(default)]
    pub(crate) m3c2_only: bool,
}

/// summary.json `totals`: what `total_gain_m3` and `total_loss_m3` sum and what they leave out.
/// An event is counted when it is significant, complete and of known sign (and not vegetation,
/// unless `--vegetation keep`); an incomplete one measured part of its change only, so its
/// volume is a bound (the change is at least that), reported apart; one whose sign the data
/// cannot tell is reported by its size alone.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub(crate) struct Totals {
    /// The rule, in words.
    pub(crate) counted: String,
    /// Significant events of known sign whose volume covers part of their change only
    /// (`complete: false`): how many, and the least gain and loss they show (m³).
    pub(crate) incomplete_events: usize,
    pub(crate) incomplete_gain_at_least_m3: f64,
    pub(crate) incomplete_loss_at_least_m3: f64,
    /// Significant events whose sign the data does not decide (`sign_known: false`): how many
    /// and the sum of their |volumes| (m³).
    pub(crate) sign_unknown_events: usize,
    pub(crate) sign_unknown_abs_m3: f64,
    /// Events whose |volume| does not exceed its uncertainty.
    pub(crate) not_significant_events: usize,
    /// Vegetation events left out (`--vegetation flag` or `remove`).
    pub(crate) vegetation_left_out: usize,
}

/// Which of the totals an event falls in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Tally {
    Counted,
    Incomplete,
    SignUnknown,
    NotSignificant,
    Vegetation,
}

impl EventRecord {
    /// Where the totals put this event, under vegetation mode `mode`.
    pub(crate) fn tally(&self, mode: crate::params::Vegetation) -> Tally {
        if !mode.counts(self.vegetation) {
            Tally::Vegetation
        } else if !self.significant {
            Tally::NotSignificant
        } else if !self.sign_known {
            Tally::SignUnknown
        } else if !self.complete {
            Tally::Incomplete
        } else {
            Tally::Counted
        }
    }
}

impl Totals {
    /// The totals of `records` under vegetation mode `mode`: (gains counted, losses counted,
    /// the rest).
    pub(crate) fn of(
        records: &[EventRecord],
        mode: crate::params::Vegetation,
    ) -> ([f64; 2], [usize; 2], Totals) {
        let mut t = Totals {
            counted: format!(
                "significant (|V| above its 95 % uncertainty), complete and of known sign{}",
                if mode == crate::params::Vegetation::Keep {
                    ", vegetation events included (--vegetation keep)"
                } else {
                    ", not vegetation"
                }
            ),
            ..Totals::default()
        };
        let (mut sums, mut counts) = ([0.0f64; 2], [0usize; 2]);
        for e in records {
            let v = e.volume_m3.unwrap_or(0.0);
            match e.tally(mode) {
                Tally::Counted => {
                    let k = usize::from(v < 0.0);
                    sums[k] += v;
                    counts[k] += 1;
                }
                Tally::Incomplete => {
                    t.incomplete_events += 1;
                    if v > 0.0 {
                        t.incomplete_gain_at_least_m3 += v;
                    } else {
                        t.incomplete_loss_at_least_m3 += v;
                    }
                }
                Tally::SignUnknown => {
                    t.sign_unknown_events += 1;
                    t.sign_unknown_abs_m3 += v.abs();
                }
                Tally::NotSignificant => t.not_significant_events += 1,
                Tally::Vegetation => t.vegetation_left_out += 1,
            }
        }
        // An empty sum is +0, never the −0 a float sum starts from.
        (sums.map(|s| s + 0.0), counts, t)
    }
}

/// A volume for the terminal: signed, three decimals, zero without a sign.
pub(crate) fn volume_text(v: f64) -> String {
    if v == 0.0 {
        "0.000".into()
    } else {
        format!("{v:+.3}")
    }
}

/// summary.json `classes` (SPEC.md §4 "classification first").
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub(crate) struct ClassesSummary {
    /// The classes compared: `all`, `all but 3,4,5,7,18` (the default), or the kept list.
    pub(crate) used: String,
    /// Per survey, before then after: its classes as read (null when none was read: text or
    /// PLY input, or `--classes all`).
    pub(crate) surveys: Vec<Option<SurveyClasses>>,
}

/// One survey's classes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct SurveyClasses {
    /// The points carry a classification (some class other than 0 and 1).
    pub(crate) classified: bool,
    /// Points left out, in all.
    pub(crate) left_out: u64,
    /// Every class that occurred: its points, and how many were left out.
    pub(crate) per_class: Vec<ClassRow>,
}

/// One class of a survey.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct ClassRow {
    pub(crate) class: u8,
    pub(crate) points: u64,
    pub(crate) left_out: u64,
}

impl SurveyClasses {
    pub(crate) fn of(c: &crate::io::classes::ClassCounts) -> SurveyClasses {
        SurveyClasses {
            classified: c.classified(),
            left_out: c.left_out(),
            per_class: c
                .classes
                .iter()
                .map(|&(class, points, left_out)| ClassRow {
                    class,
                    points,
                    left_out,
                })
                .collect(),
        }
    }
}

/// summary.json `alignment` (SPEC.md §1): the rigid transform fitted on the stable ground, and
/// whether (and why) it was applied.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct AlignmentSummary {
    pub(crate) applied: bool,
    /// 4×4, row-major: maps the later survey's coordinates onto the earlier's.
    pub(crate) matrix: [[f64; 4]; 4],
    /// The later survey's misregistration: translation (m) and rotation vector (rad) about
    /// `origin`, with their standard errors.
    pub(crate) translation: [f64; 3],
    /// Null for a component the stable ground does not constrain (left at zero).
    pub(crate) translation_sd: [Option<f64>; 3],
    pub(crate) rotation: [f64; 3],
    pub(crate) rotation_sd: [Option<f64>; 3],
    pub(crate) rotation_deg: f64,
    pub(crate) origin: [f64; 3],
    /// Directions (of 6) the stable ground constrains.
    pub(crate) constrained: usize,
    pub(crate) stable_points: usize,
    /// Robust standard deviation of the stable ground's distances after the fit.
    pub(crate) residual_m: f64,
    /// The least share, over the directions fitted, of what the core points tell of that
    /// direction that comes from ground the fit leaves at rest (applied only from 0.5).
    pub(crate) at_rest_share: f64,
    /// The share of its predicted change the held-out blocks of stable ground confirm (applied
    /// only from 0.5; null where too little could be held out).
    pub(crate) confirmed_share: Option<f64>,
    /// The largest displacement it gives a point of the stable ground (m).
    pub(crate) largest_shift_m: f64,
    /// Only the vertical was fitted: the stable ground does not see both tilts.
    pub(crate) vertical_only: bool,
    /// The surveys the transform passes through, from this one to the first (0): `[k, 0]` for
    /// a fit onto the first, longer for a chain through predecessors.
    pub(crate) route: Vec<usize>,
    pub(crate) reason: String,
}

impl AlignmentSummary {
    pub(crate) fn of(r: &crate::events::chain::Route) -> AlignmentSummary {
        let a = &r.alignment;
        AlignmentSummary {
            applied: a.applied,
            matrix: a.matrix(),
            translation: a.translation,
            translation_sd: a.translation_sd,
            rotation: a.rotation,
            rotation_sd: a.rotation_sd,
            rotation_deg: a.rotation_deg(),
            origin: a.origin,
            constrained: a.constrained,
            stable_points: a.stable_points,
            residual_m: a.residual_m,
            at_rest_share: a.at_rest_share,
            confirmed_share: a.confirmed_share,
            largest_shift_m: a.largest_shift_m,
            vertical_only: a.vertical_only,
            route: r.surveys.clone(),
            reason: a.reason.clone(),
        }
    }
}

/// summary.json `reach`: the rule M3C2 followed where a cylinder held one epoch only, and what it
/// found.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub(crate) struct ReachSummary {
    /// "walk" (derived half-length: a search window, the other epoch sought on along the normal
    /// and measured) or "flag" (the user's half-length: what lies beyond it is flagged, not
    /// measured).
    pub(crate) rule: String,
    /// The rule in words.
    pub(crate) description: String,
    /// Core points whose distance the walk measured beyond the half-length.
    pub(crate) extended_points: u64,
    /// Core points with the other epoch beyond the user's half-length (`m3c2_beyond_reach`).
    pub(crate) beyond_reach_points: u64,
    /// Events whose volume does not cover their whole change (`complete: false`).
    pub(crate) incomplete_events: usize,
}

impl ReachSummary {
    fn new(params: &Params, written: &laz::Written, records: &[EventRecord]) -> ReachSummary {
        let (rule, description) = match params.walk() {
            crate::m3c2::Walk::Detect => (
                "flag",
                "cyl_halflen set by the user: a cylinder holding one epoch only is followed on \
                 along the normal to the data's extent; where the other epoch lies beyond the \
                 half-length the core point is flagged (m3c2_beyond_reach) and gets no distance, \
                 and its event is incomplete",
            ),
            _ => (
                "walk",
                "cyl_halflen derived: a search window only; a cylinder holding one epoch only is \
                 followed on along the normal, both ways, to the data's extent, and the first \
                 surface of the missing epoch met (crossing the axis, with the present epoch's \
                 next surface beyond it) is measured as the distance",
            ),
        };
        ReachSummary {
            rule: rule.into(),
            description: description.into(),
            extended_points: written.extended,
            beyond_reach_points: written.beyond_reach,
            incomplete_events: records.iter().filter(|e| !e.complete).count(),
        }
    }
}

impl Summary {
    /// One line for the terminal: what was measured, what the totals count and what they
    /// leave out.
    pub(crate) fn one_line(&self) -> String {
        let points = format!(
            "talus: {} core points ({} with a distance, {} significant)",
            self.core_points, self.computed_points, self.significant_points
        );
        if self.m3c2_only {
            return format!("{points}; M3C2 only, no events; {} tile(s)", self.tiles)
                + &self.alignment_line()
                + &self.classes_line();
        }
        let t = &self.totals;
        let mut line = format!(
            "{points}, {} event(s): {} gain {} m³ and {} loss {} m³ counted ({})",
            self.events,
            self.gain_events,
            volume_text(self.total_gain_m3),
            self.loss_events,
            volume_text(self.total_loss_m3),
            if self.parameters.vegetation.value == crate::params::Vegetation::Keep {
                "significant, complete, known sign, vegetation included"
            } else {
                "significant, complete, known sign"
            }
        );
        if t.incomplete_events > 0 {
            line += &format!(
                "; {} incomplete, measured in part: at least {} and {} m³, not in the totals \
                 (see volume_note)",
                t.incomplete_events,
                volume_text(t.incomplete_gain_at_least_m3),
                volume_text(t.incomplete_loss_at_least_m3)
            );
        }
        if t.sign_unknown_events > 0 {
            line += &format!(
                "; {} whose sign the data cannot tell (|V| {:.3} m³ in all), not in the totals: \
                 give --orientation toward:X,Y,Z",
                t.sign_unknown_events, t.sign_unknown_abs_m3
            );
        }
        if t.not_significant_events > 0 {
            line += &format!(
                "; {} not significant (|V| within its uncertainty)",
                t.not_significant_events
            );
        }
        line + &format!("; {} tile(s)", self.tiles)
            + &self.areas_line()
            + &self.vegetation_line()
            + &self.reach_line()
            + &self.alignment_line()
            + &self.classes_line()
    }

    /// What the one line says of the user's stable areas when they did not give the stable
    /// ground: never dropped in silence.
    fn areas_line(&self) -> String {
        match &self.stable_areas {
            Some(a) if !a.used => format!(
                "; the stable areas {} held {} points with a distance: too few, {}",
                a.file.display(),
                a.with_distance,
                if self.stable.is_some() {
                    "the automatic stable ground was used"
                } else {
                    "and no automatic stable ground either: the threshold is the point spacing's"
                }
            ),
            _ => String::new(),
        }
    }

    /// What the one line says of vegetation events, when there are any.
    fn vegetation_line(&self) -> String {
        let mut line = match (self.vegetation_events, self.parameters.vegetation.value) {
            (0, _) => String::new(),
            (n, crate::params::Vegetation::Keep) => {
                format!("; {n} vegetation event(s), counted (--vegetation keep)")
            }
            (n, _) => format!("; {n} vegetation event(s), left out of the totals"),
        };
        if let Some([b, a]) = self.vegetation_removed {
            line += &format!("; vegetation-like points removed before M3C2: before {b}, after {a}");
        }
        line
    }

    /// What the one line says of the classes: the points left out, when any were.
    fn classes_line(&self) -> String {
        let out: Vec<String> = ["before", "after"]
            .iter()
            .zip(&self.classes.surveys)
            .filter_map(|(name, s)| {
                let s = s.as_ref().filter(|s| s.left_out > 0)?;
                let which: Vec<String> = s
                    .per_class
                    .iter()
                    .filter(|c| c.left_out > 0)
                    .map(|c| c.class.to_string())
                    .collect();
                Some(format!(
                    "{name} {} (class {})",
                    s.left_out,
                    which.join(", ")
                ))
            })
            .collect();
        if out.is_empty() {
            String::new()
        } else {
            format!(
                "; points of classes not compared ({}) left out: {}",
                self.classes.used,
                out.join(", ")
            )
        }
    }

    /// What the one line says of the alignment: applied (by how much), or not (why), when the
    /// fit found a motion worth a word.
    fn alignment_line(&self) -> String {
        match &self.alignment {
            Some(a) if a.applied => format!(
                "; the after survey aligned on {} stable core points: shift ({:+.3}, {:+.3}, \
                 {:+.3}) m, turn {:.3}°, residual {:.3} m",
                a.stable_points,
                a.translation[0],
                a.translation[1],
                a.translation[2],
                a.rotation_deg,
                a.residual_m
            ),
            // Refused for a reason the user should hear (not merely too small to matter).
            Some(a)
                if !a.reason.contains("within its own uncertainty")
                    && !a.reason.contains("moves the stable surface by") =>
            {
                format!("; alignment {}", a.reason)
            }
            _ => String::new(),
        }
    }

    /// What the one line adds about reach: core points beyond a user's half-length.
    fn reach_line(&self) -> String {
        let r = &self.reach;
        let mut s = String::new();
        if r.beyond_reach_points > 0 {
            s += &format!(
                "; {} core point(s) with the other survey beyond --cyl-halflen, not measured",
                r.beyond_reach_points
            );
        }
        s
    }
}

/// A file the executor publishes: from unit `unit` (its name and kind), `file`, as `name` in DIR.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Publish {
    pub(crate) kind: String,
    pub(crate) unit: String,
    pub(crate) file: String,
    pub(crate) name: String,
}

impl Publish {
    /// File `file` of the plan's unit `unit`, published as `name`.
    pub(crate) fn of(plan: &crate::plan::Plan, unit: usize, file: &str, name: String) -> Publish {
        let u = &plan.units[unit];
        Publish {
            kind: u.kind().to_string(),
            unit: u.name.clone(),
            file: file.to_string(),
            name,
        }
    }
}

/// Resident bytes of an outputs unit: the events' records, their tables and the view (m3c2.laz
/// and the terrain sample are the points unit's, `points::need`). Measured: the process's peak
/// while it ran 38–43 MiB on the 120M-point pair (1,028 events, the process's base included);
/// reserved as what the unit reserved before m3c2.laz moved out, which the smallest budget holds.
pub(crate) const NEED: u64 = points::FIXED;

/// A pair's outputs, ready to publish.
pub(crate) struct OutputsStage;

/// What an outputs unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct OutputsMeta {
    /// The files to publish into DIR.
    pub(crate) publish: Vec<Publish>,
    /// Core points written to m3c2.laz.
    pub(crate) core_points: u64,
}

impl Stage for OutputsStage {
    const KIND: &'static str = "outputs";
    const SCOPE: Scope = Scope::Pair;
    /// 2: a lean campaign's pair (`Plan::lean_pairs`) publishes no m3c2.laz and names the
    /// first pair's terrain positions in view.json. 3: summary.json's stage table counts the
    /// orientation field's units (`units::field`).
    const VERSION: u32 = 3;
    const LINE: Line = Line {
        name: "outputs",
        counts: "files",
        total: Total::Unknown,
    };
    type Meta = OutputsMeta;

    /// One per pair, after its points unit (m3c2.laz, terrain.bin), stable ground, events and
    /// volumes.
    fn plan(p: &mut Planner) -> Result<()> {
        // The vegetation mode decides what the totals count.
        let version = format!(
            "{}|{}|vegetation {}",
            env!("CARGO_PKG_VERSION"),
            p.plan.m3c2_only,
            p.plan.params.vegetation.value
        );
        for pair in 0..p.plan.pairs.len() {
            let mut deps = vec![
                p.the(&Spec::pair(StableStage::KIND, pair))?,
                p.the(&Spec::pair(PointsStage::KIND, pair))?,
            ];
            if let Some(e) = p.find(&Spec::pair(EventsStage::KIND, pair)) {
                deps.push(e);
                deps.extend(p.of_pair(VolumesStage::KIND, pair));
            }
            // Where terrain.bin may come from (`view::Terrain::series`).
            if points::shared_positions(p.plan, pair).is_some() {
                deps.push(p.the(&Spec::pair(SeriesStage::KIND, pair))?);
            }
            p.add_pair(Self::KIND, pair, &version, deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<OutputsMeta> {
        run(ctx, unit, ctx.pair(unit)?, out)
    }

    fn publishes() -> Option<Publishes<OutputsMeta>> {
        Some(Publishes {
            is_output,
            list: |m| &m.publish,
        })
    }
}

/// Write pair `pair`'s outputs into `out`.
fn run(ctx: &Ctx, unit: usize, pair: usize, out: &mut UnitWriter) -> Result<OutputsMeta> {
    let plan = ctx.plan;
    let p = &plan.pairs[pair];
    let bs = &plan.surveys[p.before];
    let ground = super::stable::read(ctx, pair)?;
    let params = ground.params(plan);
    let grid = plan.layout.grid()?;
    let _held = ctx.reserve(NEED, "writing the outputs")?;
    // Events with their volumes, in id order.
    let (records, mesh_sources) = if plan.m3c2_only {
        (Vec::new(), Vec::new())
    } else {
        let drafts = super::events::read_drafts(ctx, pair)?;
        let mut measured: HashMap<u32, (Measured, usize)> = HashMap::default();
        for t in grid.tiles() {
            let v = ctx.unit(&Spec::tile(VolumesStage::KIND, pair, t))?;
            let list: Vec<Measured> = super::read_json(ctx, v, super::volumes::FILE)?;
            for m in list {
                measured.insert(m.id, (m, v));
            }
        }
        let mut records = Vec::new();
        let mut sources = Vec::new();
        for d in drafts {
            let (m, v) = measured.remove(&d.event.id).ok_or_else(|| {
                Error::Internal(format!("event {} has no volume record", d.event.id))
            })?;
            sources.push((d.event.id, v, m.meshes));
            records.push(EventRecord::new(d.event, m));
        }
        (records, sources)
    };
    // m3c2.laz and terrain.bin, from the pair's points unit.
    let points_unit = ctx.unit(&Spec::pair(PointsStage::KIND, pair))?;
    let PointsMeta {
        written,
        terrain,
        kept: kept_count,
    } = ctx.meta::<PointsStage>(points_unit)?;
    let crs = io::open(&bs.files[0].path)?.info().crs.clone();
    let mut publish = Vec::new();
    let mut meshes = Vec::new();
    for &(id, v, has) in &mesh_sources {
        if !has {
            continue;
        }
        let names = mesh_files(id);
        for n in &names {
            publish.push(Publish::of(plan, v, n, format!("meshes/{n}")));
        }
        meshes.push((
            id,
            view::EventMeshes {
                before: format!("meshes/{}", names[0]),
                after: format!("meshes/{}", names[1]),
            },
        ));
    }
    if !plan.m3c2_only {
        tables::write_tables(out, &records, &crs)?;
        tables::write_regions(out, &records, &crs)?;
    }
    view::write_view(out, &crs, &terrain, &meshes)?;
    let summary = summarize(
        ctx,
        unit,
        pair,
        params,
        (ground.stable, ground.areas),
        &records,
        &written,
        kept_count,
    )?;
    let text = serde_json::to_string_pretty(&summary)
        .map_err(|e| Error::Internal(format!("summary: {e}")))?;
    super::write_bytes(out, MARKER, text.as_bytes())?;
    for &f in points::files(plan) {
        if f == "terrain.bin" && terrain.series {
            let series = ctx.unit(&Spec::pair(SeriesStage::KIND, pair))?;
            publish.push(Publish::of(plan, series, super::series::FILE, f.into()));
        } else {
            publish.push(Publish::of(plan, points_unit, f, f.into()));
        }
    }
    let mut files = vec!["view.json", MARKER];
    if !plan.m3c2_only {
        files.extend(["events.geojson", "events.csv", "event_regions.geojson"]);
    }
    publish.extend(
        files
            .into_iter()
            .map(|f| Publish::of(plan, unit, f, f.into())),
    );
    (ctx.progress)(publish.len() as u64);
    Ok(OutputsMeta {
        publish,
        core_points: written.core_points,
    })
}

#[allow(clippy::too_many_arguments)]
fn summarize(
    ctx: &Ctx,
    unit: usize,
    pair: usize,
    params: Params,
    (stable, stable_areas): (Option<Stable>, Option<crate::events::stable::AreasUse>),
    records: &[EventRecord],
    written: &laz::Written,
    kept: u64,
) -> Result<Summary> {
    let plan = ctx.plan;
    let p = &plan.pairs[pair];
    let input = |s: &crate::plan::Survey| InputSummary {
        path: s.arg.clone(),
        format: s.format.clone(),
        points: s.points,
        bounds: s.bounds,
        crs: s.crs.clone(),
    };
    let mut inputs = vec![
        input(&plan.surveys[p.before]),
        input(&plan.surveys[p.after]),
    ];
    if let Some(c) = &plan.core_points {
        if let Ok(r) = io::open(&c.path) {
            let i = r.info();
            inputs.push(InputSummary {
                path: i.path.clone(),
                format: i.format_detail.clone(),
                points: i.point_count,
                bounds: i.bounds,
                crs: i.crs.describe(),
            });
        }
    }
    // Stage work from the records of the units this one depends on (transitively: its direct
    // dependencies are every unit of the pair but the tilings, whose records the M3C2 units'
    // dependencies name).
    let mut stages: HashMap<&'static str, (usize, f64)> = HashMap::default();
    let mut seen = std::collections::HashSet::new();
    let mut stack = plan.units[unit].deps.clone();
    while let Some(u) = stack.pop() {
        // A pair's time-series column is the campaign's work, not the pair's: a dependency
        // only where terrain.bin is published from it, which must not change the pair's stages.
        if !seen.insert(u) || plan.units[u].kind() == SeriesStage::KIND {
            continue;
        }
        stack.extend(&plan.units[u].deps);
        let name = registry().get(plan.units[u].kind())?.line().name;
        let secs = ctx.timing(u)?.seconds;
        let e = stages.entry(name).or_insert((0, 0.0));
        // A survey tiled in parts counts as one unit; a pair's units in ranges (m3c2.laz's
        // segments, the stable ground's and the events' passes) count not at all beside the
        // pair's unit of their line (their seconds add up): the table is the same whatever
        // `--tiling-part` and the executor chose.
        let spec = &plan.units[u].spec;
        if spec.part.is_none_or(|k| k == 0 && spec.pair.is_none()) {
            e.0 += 1;
        }
        e.1 += secs;
    }
    // The pipeline's lines before this stage's own.
    let pipeline: Vec<&str> = registry()
        .lines()
        .into_iter()
        .map(|l| l.name)
        .filter(|&n| n != OutputsStage::LINE.name)
        .collect();
    let stages = pipeline
        .iter()
        .filter_map(|&s| {
            stages.get(s).map(|&(units, seconds)| StageTime {
                stage: s.to_string(),
                units,
                seconds,
            })
        })
        .collect();
    let significant = || records.iter().filter(|e| e.significant);
    let mode = params.vegetation.value;
    let ([gain, loss], [gains, losses], totals) = Totals::of(records, mode);
    let reach = ReachSummary::new(&params, written, records);
    let alignment = super::aligned::route(ctx, p.after)?.map(|r| AlignmentSummary::of(&r));
    let classes = ClassesSummary {
        used: params.classes.value.clone(),
        surveys: [p.before, p.after]
            .iter()
            .map(|&s| Ok(ctx.tiling_meta(s)?.classes.as_ref().map(SurveyClasses::of)))
            .collect::<Result<_>>()?,
    };
    let removed = |s: usize| -> Result<Option<u64>> {
        match plan.find(&Spec::survey(super::cleared::ClearedStage::KIND, s)) {
            Some(u) => Ok(Some(ctx.meta::<super::cleared::ClearedStage>(u)?.removed)),
            None => Ok(None),
        }
    };
    let vegetation_removed = match (removed(p.before)?, removed(p.after)?) {
        (Some(b), Some(a)) => Some([b, a]),
        _ => None,
    };
    Ok(Summary {
        vegetation_removed,
        tool: "talus".into(),
        version: env!("CARGO_PKG_VERSION").into(),
        inputs,
        core_points_file: plan.core_points.as_ref().map(|c| c.path.clone()),
        spacing: plan.spacing.clone(),
        parameters: params,
        stable,
        stable_areas,
        tiles: plan.layout.len(),
        tile_size: plan.layout.tile_size,
        core_points: written.core_points,
        computed_points: written.computed,
        significant_points: written.significant,
        kept_points: kept,
        events: records.len(),
        gain_events: gains,
        loss_events: losses,
        significant_events: significant().count(),
        vegetation_events: records.iter().filter(|e| e.vegetation).count(),
        total_gain_m3: gain,
        total_loss_m3: loss,
        totals,
        reach,
        alignment,
        classes,
        stages,
        m3c2_only: plan.m3c2_only,
    })
}
