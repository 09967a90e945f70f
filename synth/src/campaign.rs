//! `talus synth campaign`: N surveys of one site, every three months, with the exact truth of
//! every interval's changes and of the changes accumulated since the first survey.
//!
//! The site is the cliff scenes' frame stretched along x: a beach (y ∈ [−26, 0], sloping 2 %
//! seaward to −y) at the foot of a 30 m vertical face in the plane y = 0 (rock at y > 0), a 10 m
//! deep plateau on top; 13 (N − 1) + 5 m wide, one 13 m cell along x per interval, whose changes
//! stay in the cell's middle 8 m (so changes of different intervals are ≥ 5 m apart along x, and
//! ≥ 5 m from the ends of the site). Survey k is survey k − 1 plus interval k's changes (interval k
//! lies between surveys k − 1 and k, 1-based): changes accumulate.
//!
//! Interval k plants, in cell k:
//! - a rockfall scar in the face (loss): a half-ellipsoid (odd k; semi-axes a along x, 0.8a along
//!   z, depth 0.5a) or a box (even k; w wide, 0.75w high, 0.3w deep), centred 12 m (odd k) or 19 m
//!   (even k) above the foot (so ≥ 5 m from the foot and from the top);
//! - a debris deposit on the beach (gain), 2 m in front of the foot (never touching the face): a
//!   cos² bump (h = 0.4R), a cone (H = 0.6R) or a spherical cap (h = 0.4a), by k mod 3;
//! - on even k, a pit dug in the beach (loss) whose far edge lies 5.5 m from the beach's seaward
//!   border: a box (w × 0.8w, 0.25w deep) or a spherical dent (h = 0.45a), by k/2 mod 2;
//! - in interval R = min(3, N − 1) no pit but the recurring change instead: interval 1's scar (a
//!   half-ellipsoid with semi-axes 2 m, 1.6 m, 0.8 m deep) grows deeper and wider into a concentric
//!   one (3 m, 2.4 m, 1.3 m deep) containing it. Its interval-R volume is the difference of the two
//!   half-ellipsoids, −(2/3)π(3·2.4·1.3 − 2·1.6·0.8) ≈ −14.24 m³; both its events share a track.
//!
//! So every interval has two or three events. The other volumes are fixed (the seed only draws the
//! points): the j-th other change has |V| = 1.5 · 12^frac(0.5 + j/φ) m³, a low-discrepancy spread
//! over [1.5, 18] m³, and its shape is solved for that volume from the fixed aspect. Truth volumes
//! are the closed forms of `surface` and `scenes`: box w·d·h,
//! half-ellipsoid (2/3)πabc, bump h·R²(π/2 − 2/π), cone πR²H/3, cap ±πh²(3R − h)/3; a pair
//! (i, j)'s event at one place is the difference of its last shape up to survey j and up to
//! survey i.
//!
//! Files: `survey_YYYYMMDD.laz` (2021-03-01, 2021-06-01, …), each survey sampled like a pair's
//! epoch (its own random streams (seed, k, strip), noise along the normal, LAS 1.4 point format 6,
//! 1 mm scale, point source id k + 1, the WKT of EPSG:32633), and `truth.json`
//! ([`CampaignTruth`]).

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::output::{self, UTM33N_WKT};
use super::sampling::{Chunks, Placement};
use super::scenes::{ground, scar_event, CliffFrame, ModelEvent, Scar, SceneModel};
use super::surface::{box_walls_on, bump_volume, Feature, Patch};
use super::{check_noise, check_points, truth_events, write_json, TruthEvent, CRS_EPSG, ORIGIN};
use talus_base::{Error, Result};

/// Surveys when none are asked for.
pub const DEFAULT_EPOCHS: usize = 5;
/// Fewest surveys: two intervals, so that a change can recur.
pub const MIN_EPOCHS: usize = 3;
/// Most surveys: a hundred years of quarterly surveys (2021-03-01 to 2121-03-01), the 400 pairs
/// of the time series' format tests (a campaign past what a LAS extra-bytes VLR describes).
pub const MAX_EPOCHS: usize = 401;

/// Width (m, along x) of one interval's cell.
const PITCH: f64 = 13.0;
/// Least distance (m) between two changes, and from a change to the border of the site.
const GAP: f64 = 5.0;
/// Depth (m) of the beach in front of the face.
const BEACH: f64 = 26.0;
/// Distance (m) from the face foot to the near edge of every deposit.
const FOOT_GAP: f64 = 2.0;
/// Distance (m) from the face foot to the far edge of every pit.
const PIT_EDGE: f64 = 20.5;
/// Heights (m above the foot) of the scars' centres: odd intervals, even intervals.
const SCAR_ROWS: [f64; 2] = [12.0, 19.0];
/// Points per m² of the site's surface (beach, face and plateau, scars aside): about 0.1 m
/// spacing.
const DENSITY: f64 = 100.0;
/// Range of the volumes (m³, absolute) of the changes other than the recurring one.
const VOLUMES: [f64; 2] = [1.5, 18.0];
/// 1/φ: the step of the volumes' low-discrepancy sequence.
const INV_GOLDEN: f64 = 0.618_033_988_749_894_9;
/// The recurring scar's semi-axes (a along x, depth b, cz along z) when it opens in interval 1
/// and after it grows; it is centred in cell 1, in the lower row.
const RECURRING: [[f64; 3]; 2] = [[2.0, 0.8, 1.6], [3.0, 1.3, 2.4]];
/// The recurring change's track.
pub const RECURRING_TRACK: u32 = 1;

/// Options of [`write`](fn@write).
#[derive(Debug, Clone, PartialEq)]
pub struct CampaignOptions {
    /// Number of surveys (3 to 401).
    pub epochs: usize,
    pub seed: u64,
    /// Points per survey; None = 100 per m² of the site's surface (≈ 0.1 m spacing).
    pub points: Option<u64>,
    /// Noise standard deviation (m) along the surface normal; None = 5 mm.
    pub noise: Option<f64>,
    /// Write LAZ (true) or LAS.
    pub laz: bool,
    /// Every survey after the first misregistered (`misregistration`): a registration error,
    /// not a change (the truth volumes ignore it).
    pub misregister: bool,
}

impl Default for CampaignOptions {
    fn default() -> Self {
        CampaignOptions {
            epochs: DEFAULT_EPOCHS,
            seed: 1,
            points: None,
            noise: None,
            laz: true,
            misregister: false,
        }
    }
}

/// The misregistration of survey `k` ≥ 1 with `--misregister`: a shift (m) of 1 to 8 cm and a turn
/// (degrees) of 0.02 to 0.1° about x and y and 0.02 to 0.3° about z, each component's size drawn
/// from a low-discrepancy sequence of (k, axis) and its sign alternating — fixed, not drawn from
/// the seed, so that a test knows its range. Survey 0 is the reference: none.
pub(crate) fn misregistration(k: usize) -> ([f64; 3], [f64; 3]) {
    if k == 0 {
        return ([0.0; 3], [0.0; 3]);
    }
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let u = |j: usize| ((3 * k + j) as f64 / phi + 0.5).fract();
    let sign = |j: usize| if (k + j).is_multiple_of(2) { 1.0 } else { -1.0 };
    let shift = std::array::from_fn(|j| sign(j) * (0.01 + 0.07 * u(j)));
    let turn = std::array::from_fn(|j| {
        let top = if j == 2 { 0.3 } else { 0.1 };
        -sign(j) * (0.02 + (top - 0.02) * u(j + 7))
    });
    (shift, turn)
}

/// One survey in `truth.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CampaignEpoch {
    /// The survey's file, relative to the directory of truth.json.
    pub file: PathBuf,
    /// ISO date (YYYY-MM-DD); the file name holds it as YYYYMMDD.
    pub date: String,
    /// Points written.
    pub points: u64,
    /// The survey's misregistration (`--misregister`): every point shifted by `shift_m` (m) and
    /// turned by `turn_deg` (degrees about x, then y, then z through `turn_centre`). Absent:
    /// none.
    #[serde(default, skip_serializing_if = "super::truth::is_zero")]
    pub shift_m: [f64; 3],
    #[serde(default, skip_serializing_if = "super::truth::is_zero")]
    pub turn_deg: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn_centre: Option<[f64; 3]>,
}

/// A true event of a pair of surveys, with the track of its place.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CampaignEvent {
    #[serde(flatten)]
    pub event: TruthEvent,
    /// The place's number: the same for the events of every pair at one place (the recurring
    /// scar), distinct for every other planted change.
    pub track: u32,
}

/// A pair of surveys (indices into `epochs`) and its true events.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CampaignPair {
    pub before: usize,
    pub after: usize,
    /// 1-based ids within the pair, in the order the changes were planted.
    pub events: Vec<CampaignEvent>,
    /// Sum of the positive volumes, m³.
    pub total_gain_m3: f64,
    /// Sum of the negative volumes, m³ (≤ 0).
    pub total_loss_m3: f64,
}

/// `truth.json` of a campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CampaignTruth {
    /// "campaign".
    pub scene: String,
    pub summary: String,
    pub seed: u64,
    /// Standard deviation of the noise (m).
    pub noise_m: f64,
    pub noise_model: String,
    /// EPSG code of the CRS written in every survey.
    pub crs_epsg: u32,
    /// The OGC WKT (version 1) written in every survey's WKT CRS VLR.
    pub crs_wkt: String,
    /// The surveys in date order.
    pub epochs: Vec<CampaignEpoch>,
    /// Each consecutive pair (k, k + 1): interval k + 1's changes.
    pub pairs: Vec<CampaignPair>,
    /// Each later survey against the first, (0, k) for k ≥ 2 ((0, 1) is `pairs[0]`): the changes
    /// accumulated over intervals 1..=k, one event per place.
    pub baseline_pairs: Vec<CampaignPair>,
}

/// A planted change: a scar in the face or a feature on the beach, in local coordinates.
#[derive(Debug, Clone, Copy)]
enum Change {
    Scar(Scar),
    Ground(Feature),
}

impl Change {
    /// Signed volume against the intact site (a scar's is negative).
    fn volume(&self) -> f64 {
        match self {
            Change::Scar(s) => -s.volume(),
            Change::Ground(f) => f.volume(),
        }
    }
}

/// One shape of a place, reached in `interval` (1-based: between surveys interval − 1 and
/// interval).
#[derive(Debug, Clone)]
struct Stage {
    interval: usize,
    track: u32,
    change: Change,
    description: String,
}

/// A pair of surveys as a two-epoch scene: the surfaces of surveys `before` and `after`, the
/// events between them and each event's track.
#[derive(Debug, Clone)]
pub struct PairModel {
    pub before: usize,
    pub after: usize,
    pub model: SceneModel,
    /// The track of each of `model.events()`, in the same order.
    pub tracks: Vec<u32>,
}

/// The analytic model of a campaign of `epochs` surveys.
#[derive(Debug, Clone)]
pub struct CampaignModel {
    epochs: usize,
    frame: CliffFrame,
    /// In the order planted (by interval).
    stages: Vec<Stage>,
}

/// The volume of the j-th change other than the recurring one.
fn volume_of(j: usize) -> f64 {
    let [v0, v1] = VOLUMES;
    v0 * (v1 / v0).powf((0.5 + j as f64 * INV_GOLDEN).fract())
}

/// A half-ellipsoid scar centred at face coordinates c.
fn ellipsoid(c: [f64; 2], [a, b, cz]: [f64; 3]) -> (Scar, String) {
    (
        Scar::HalfEllipsoid { c, a, b, cz },
        format!("rockfall scar: half-ellipsoid {a:.3} m × {cz:.3} m semi-axes, {b:.3} m deep"),
    )
}

/// Interval k's scar of volume v at face coordinates c.
fn scar(k: usize, c: [f64; 2], v: f64) -> (Scar, String) {
    if k % 2 == 1 {
        // (2/3)π·a·(0.5a)·(0.8a)
        let a = (v / (2.0 / 3.0 * PI * 0.4)).cbrt();
        ellipsoid(c, [a, 0.5 * a, 0.8 * a])
    } else {
        let w = (v / (0.75 * 0.3)).cbrt();
        let (h, d) = (0.75 * w, 0.3 * w);
        (
            Scar::Box {
                min: [c[0] - w / 2.0, c[1] - h / 2.0],
                max: [c[0] + w / 2.0, c[1] + h / 2.0],
                depth: d,
            },
            format!("rockfall scar: box {w:.3} m wide, {h:.3} m high, {d:.3} m deep"),
        )
    }
}

/// Interval k's deposit of volume v centred at the origin.
fn deposit(k: usize, v: f64) -> (Feature, String) {
    let c = [0.0; 2];
    match k % 3 {
        1 => {
            let radius = (v / (bump_volume(1.0, 1.0) * 0.4)).cbrt();
            let height = 0.4 * radius;
            (
                Feature::Bump { c, radius, height },
                format!("debris deposit: cos² bump R = {radius:.3} m, h = {height:.3} m"),
            )
        }
        2 => {
            let radius = (v / (PI * 0.6 / 3.0)).cbrt();
            let height = 0.6 * radius;
            (
                Feature::Cone { c, radius, height },
                format!("debris cone: R = {radius:.3} m, H = {height:.3} m"),
            )
        }
        _ => cap(v, 0.4, "debris deposit: spherical cap"),
    }
}

/// A spherical cap (v > 0) or dent (v < 0) of footprint radius a and height t·a centred at the
/// origin: |V| = πh(3a² + h²)/6 = πa³t(3 + t²)/6.
fn cap(v: f64, t: f64, what: &str) -> (Feature, String) {
    let a = (6.0 * v.abs() / (PI * t * (3.0 + t * t))).cbrt();
    let h = t * a;
    let sphere_radius = (a * a + h * h) / (2.0 * h);
    (
        Feature::Cap {
            c: [0.0; 2],
            sphere_radius,
            height: v.signum() * h,
        },
        format!("{what} R = {sphere_radius:.3} m, h = {h:.3} m"),
    )
}

/// Interval k's pit of volume v (> 0, dug) centred at the origin.
fn pit(k: usize, v: f64) -> (Feature, String) {
    if (k / 2) % 2 == 1 {
        let w = (v / (0.8 * 0.25)).cbrt();
        let (d, h) = (0.8 * w, 0.25 * w);
        (
            Feature::Block {
                min: [-w / 2.0, -d / 2.0],
                max: [w / 2.0, d / 2.0],
                height: -h,
            },
            format!("pit dug in the beach: box {w:.3} × {d:.3} m, {h:.3} m deep"),
        )
    } else {
        cap(-v, 0.45, "pit dug in the beach: spherical dent")
    }
}

/// Radius of the circle about a feature's centre that holds its footprint.
fn feature_radius(f: &Feature) -> f64 {
    let (min, max) = f.bbox();
    let half = [(max[0] - min[0]) / 2.0, (max[1] - min[1]) / 2.0];
    match f {
        Feature::Block { .. } => half[0].hypot(half[1]),
        _ => half[0],
    }
}

impl CampaignModel {
    /// The model of a campaign of `epochs` surveys (3 to 401).
    pub fn new(epochs: usize) -> Result<Self> {
        if !(MIN_EPOCHS..=MAX_EPOCHS).contains(&epochs) {
            return Err(Error::Usage(format!(
                "synth campaign: --epochs must be between {MIN_EPOCHS} and {MAX_EPOCHS}, got \
                 {epochs}"
            )));
        }
        let frame = CliffFrame {
            width: PITCH * (epochs - 1) as f64 + GAP,
            height: 30.0,
            beach: BEACH,
            plateau: 10.0,
            z0: 100.0,
        };
        let recur = 3.min(epochs - 1);
        let mut stages = Vec::new();
        // The changes other than the recurring one: the j-th gets volume_of(j) and track j + 2.
        let mut others = 0;
        let mut next = || {
            others += 1;
            (volume_of(others - 1), RECURRING_TRACK + others as u32)
        };
        for k in 1..epochs {
            let x = GAP + PITCH * (k - 1) as f64 + (PITCH - GAP) / 2.0;
            let face = [x, frame.z0 + SCAR_ROWS[(k - 1) % 2]];
            let mut plant = |track, change, description| {
                stages.push(Stage {
                    interval: k,
                    track,
                    change,
                    description,
                })
            };
            let (track, (s, description)) = if k == 1 {
                (RECURRING_TRACK, ellipsoid(face, RECURRING[0]))
            } else {
                let (v, t) = next();
                (t, scar(k, face, v))
            };
            plant(track, Change::Scar(s), description);
            // Deposits' near edges FOOT_GAP in front of the foot, pits' far edges PIT_EDGE.
            let (v, track) = next();
            let (f, what) = deposit(k, v);
            let y = -(FOOT_GAP + f.bbox().1[1]);
            plant(
                track,
                Change::Ground(f.moved([x, y])),
                format!("{what}, {FOOT_GAP} m in front of the face foot"),
            );
            if k == recur {
                // Concentric with interval 1's scar (cell 1, lower row).
                let first = [GAP + (PITCH - GAP) / 2.0, frame.z0 + SCAR_ROWS[0]];
                let (s, what) = ellipsoid(first, RECURRING[1]);
                plant(
                    RECURRING_TRACK,
                    Change::Scar(s),
                    format!("{what}: interval 1's scar grown deeper and wider"),
                );
            } else if k % 2 == 0 {
                let (v, track) = next();
                let (f, description) = pit(k, v);
                let y = -PIT_EDGE + f.bbox().1[1];
                plant(track, Change::Ground(f.moved([x, y])), description);
            }
        }
        Ok(CampaignModel {
            epochs,
            frame,
            stages,
        })
    }

    /// Number of surveys.
    pub fn epochs(&self) -> usize {
        self.epochs
    }

    /// The interval (1-based) in which the recurring scar grows.
    pub fn recurring_interval(&self) -> usize {
        self.stages
            .iter()
            .filter(|s| s.track == RECURRING_TRACK)
            .map(|s| s.interval)
            .max()
            .unwrap_or(1)
    }

    /// The site's extent along x (m; from x = 0), the beach's depth in front of the face (m) and
    /// the face's foot and top (z).
    pub fn site(&self) -> ([f64; 2], f64, [f64; 2]) {
        let f = &self.frame;
        ([0.0, f.width], f.beach, [f.z0, f.z0 + f.height])
    }

    /// Default points per survey: 100 per m² of beach, face and plateau (≈ 0.1 m spacing).
    pub fn default_points(&self) -> u64 {
        let f = &self.frame;
        (DENSITY * f.width * (f.beach + f.height + f.plateau)).round() as u64
    }

    /// The last stage of every place reached by survey k, in the order planted.
    fn state(&self, k: usize) -> Vec<&Stage> {
        let mut last: Vec<&Stage> = Vec::new();
        for s in self.stages.iter().filter(|s| s.interval <= k) {
            match last.iter_mut().find(|l| l.track == s.track) {
                Some(l) => *l = s,
                None => last.push(s),
            }
        }
        last
    }

    /// Survey k's sampling patches and scars.
    fn survey(&self, k: usize) -> (Vec<Patch>, Vec<Scar>) {
        let (mut scars, mut features) = (Vec::new(), Vec::new());
        for s in self.state(k) {
            match s.change {
                Change::Scar(x) => scars.push(x),
                Change::Ground(f) => features.push(f),
            }
        }
        let base = self.frame.beach_base();
        let walls: Vec<Patch> = features
            .iter()
            .filter_map(|f| match *f {
                Feature::Block { min, max, height } => Some(box_walls_on(
                    &base,
                    min,
                    max,
                    [height.min(0.0), height.max(0.0)],
                )),
                _ => None,
            })
            .flatten()
            .collect();
        let holes = scars.iter().map(|s| s.hole(self.frame.z0)).collect();
        let mut patches = self.frame.patches(features, holes);
        patches.extend(scars.iter().flat_map(Scar::patches));
        patches.extend(walls);
        (patches, scars)
    }

    /// Surveys `before` < `after` as a two-epoch scene whose events are the changes between
    /// them: for each place changed in intervals before + 1..=after, its last shape by `after`
    /// less its last shape by `before` (if any).
    pub fn pair(&self, before: usize, after: usize) -> Result<PairModel> {
        if !(before < after && after < self.epochs) {
            return Err(Error::Usage(format!(
                "a campaign pair needs surveys before < after < {}, got ({before}, {after})",
                self.epochs
            )));
        }
        let (p0, s0) = self.survey(before);
        let (p1, s1) = self.survey(after);
        let mut model = self.frame.model(
            [p0, p1],
            [s0, s1],
            Vec::new(),
            &format!("campaign surveys {before} and {after}"),
        );
        let (old, new) = (self.state(before), self.state(after));
        let (mut events, mut tracks) = (Vec::new(), Vec::new());
        for s in new.iter().filter(|s| s.interval > before) {
            let was = old.iter().find(|o| o.track == s.track);
            let intervals: Vec<String> = self
                .stages
                .iter()
                .filter(|t| t.track == s.track && t.interval > before && t.interval <= after)
                .map(|t| t.interval.to_string())
                .collect();
            let mut description = s.description.clone();
            if let Some(w) = was {
                description += &format!(" (the difference from: {})", w.description);
            }
            if intervals.len() > 1 {
                description += &format!(" (intervals {} accumulated)", intervals.join(", "));
            }
            let mut ev = match s.change {
                Change::Scar(x) => scar_event(&x, description),
                Change::Ground(f) => {
                    let (min, max) = f.bbox();
                    let c = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
                    let z = model.height(0, c[0], c[1]).unwrap_or(self.frame.z0);
                    ModelEvent {
                        volume_m3: f.volume(),
                        centre: [c[0], c[1], z],
                        radius_m: feature_radius(&f),
                        footprint: ground(min, max),
                        covered_volume_m3: None,
                        description,
                    }
                }
            };
            ev.volume_m3 = s.change.volume() - was.map_or(0.0, |w| w.change.volume());
            events.push(ev);
            tracks.push(s.track);
        }
        model.events = events;
        Ok(PairModel {
            before,
            after,
            model,
            tracks,
        })
    }

    /// Where the local coordinates go: moved to the global origin, about the site's centre (no
    /// rotation).
    fn placement(&self) -> Placement {
        Placement::new(self.centre(), 0.0, ORIGIN)
    }

    /// The site's centre (local x, y).
    fn centre(&self) -> [f64; 2] {
        [
            self.frame.width / 2.0,
            (self.frame.plateau - self.frame.beach) / 2.0,
        ]
    }

    /// The local height misregistered surveys turn about: half-way up the face.
    fn turn_height(&self) -> f64 {
        self.frame.z0 + self.frame.height / 2.0
    }

    /// Survey `k`'s misregistration when `misregister` (`misregistration`): its shift, its
    /// turn and the global point it turns about; none for the first survey or without it.
    fn misregistered(&self, k: usize, misregister: bool) -> Option<([f64; 3], [f64; 3], [f64; 3])> {
        if !misregister || k == 0 {
            return None;
        }
        let (shift, turn) = misregistration(k);
        let c = self.centre();
        let about = [
            ORIGIN[0] + c[0],
            ORIGIN[1] + c[1],
            ORIGIN[2] + self.turn_height(),
        ];
        Some((shift, turn, about))
    }

    /// Survey `k`'s placement: [`Self::placement`], misregistered by [`Self::misregistered`].
    fn survey_placement(&self, k: usize, misregister: bool) -> Placement {
        match self.misregistered(k, misregister) {
            None => self.placement(),
            Some((shift, turn, _)) => {
                let origin = [0, 1, 2].map(|j| ORIGIN[j] + shift[j]);
                Placement::new(self.centre(), 0.0, origin).turned(turn, self.turn_height())
            }
        }
    }
}

/// Survey k's date: 2021-03-01 plus 3k months, as (year, month).
fn year_month(k: usize) -> (usize, usize) {
    let m = 2 + 3 * k;
    (2021 + m / 12, m % 12 + 1)
}

/// Survey k's date, YYYY-MM-DD.
pub fn date(k: usize) -> String {
    let (y, m) = year_month(k);
    format!("{y:04}-{m:02}-01")
}

/// Survey k's file name: `survey_YYYYMMDD.laz` (or `.las`).
pub fn file_name(k: usize, laz: bool) -> String {
    let (y, m) = year_month(k);
    format!("survey_{y:04}{m:02}01.{}", if laz { "laz" } else { "las" })
}

/// The checked parameters of a run.
struct Resolved {
    model: CampaignModel,
    points: u64,
    noise: f64,
}

fn resolve(opts: &CampaignOptions) -> Result<Resolved> {
    let model = CampaignModel::new(opts.epochs)?;
    let points = opts.points.unwrap_or_else(|| model.default_points());
    check_points("synth campaign", points, super::MIN_POINTS)?;
    let noise = opts.noise.unwrap_or(0.005);
    check_noise(noise)?;
    Ok(Resolved {
        model,
        points,
        noise,
    })
}

/// The model [`write`](fn@write) would build for `opts`.
pub fn model(opts: &CampaignOptions) -> Result<CampaignModel> {
    Ok(resolve(opts)?.model)
}

fn chunks_of(r: &Resolved, opts: &CampaignOptions, k: usize) -> Chunks {
    Chunks::new(
        r.model.survey(k).0,
        r.points,
        opts.seed,
        k as u64,
        r.noise,
        r.model.survey_placement(k, opts.misregister),
    )
}

/// The points of survey k as [`write`](fn@write) writes them (global coordinates, before 1 mm
/// quantisation), in chunks of at most [`CHUNK_POINTS`](super::CHUNK_POINTS).
pub fn survey_chunks(opts: &CampaignOptions, k: usize) -> Result<Chunks> {
    let r = resolve(opts)?;
    if k >= r.model.epochs {
        return Err(Error::Usage(format!(
            "survey must be below {}, got {k}",
            r.model.epochs
        )));
    }
    Ok(chunks_of(&r, opts, k))
}

fn truth_pair(model: &CampaignModel, before: usize, after: usize) -> Result<CampaignPair> {
    let p = model.pair(before, after)?;
    let events: Vec<CampaignEvent> = truth_events(p.model.events(), &model.placement())
        .into_iter()
        .zip(&p.tracks)
        .map(|(event, &track)| CampaignEvent { event, track })
        .collect();
    Ok(CampaignPair {
        before,
        after,
        total_gain_m3: events.iter().map(|e| e.event.volume_m3.max(0.0)).sum(),
        total_loss_m3: events.iter().map(|e| e.event.volume_m3.min(0.0)).sum(),
        events,
    })
}

/// Generate the campaign into `out_dir` (created if missing): one `survey_YYYYMMDD.laz` (`.las`
/// when `opts.laz` is false) per survey and `truth.json`, each written atomically (truth.json
/// last). Returns the truth.
pub fn write(out_dir: &Path, opts: &CampaignOptions) -> Result<CampaignTruth> {
    let r = resolve(opts)?;
    let n = r.model.epochs;
    // Only files synth wrote there itself are replaced (`super::owned`).
    let written: Vec<String> = (0..n)
        .map(|k| file_name(k, opts.laz))
        .chain(["truth.json".to_string()])
        .collect();
    super::owned::take(out_dir, &written)?;
    let mut epochs = Vec::with_capacity(n);
    for k in 0..n {
        let file = PathBuf::from(file_name(k, opts.laz));
        let points = output::write_epoch(
            &out_dir.join(&file),
            chunks_of(&r, opts, k).map(|c| (c, 2)),
            ORIGIN,
            k as u16 + 1,
            opts.laz,
        )?;
        if points != r.points {
            return Err(Error::Internal(format!(
                "synth campaign wrote {points} points, planned {}",
                r.points
            )));
        }
        let (shift_m, turn_deg, turn_centre) = match r.model.misregistered(k, opts.misregister) {
            Some((shift, turn, about)) => (shift, turn, Some(about)),
            None => ([0.0; 3], [0.0; 3], None),
        };
        epochs.push(CampaignEpoch {
            file,
            date: date(k),
            points,
            shift_m,
            turn_deg,
            turn_centre,
        });
    }
    let truth = CampaignTruth {
        scene: "campaign".into(),
        summary: format!(
            "vertical cliff with beach and plateau surveyed {n} times, every 3 months: rockfall \
             scars in the face, debris deposits and dug pits on the beach, one scar that grows \
             again in interval {}",
            r.model.recurring_interval()
        ),
        seed: opts.seed,
        noise_m: r.noise,
        noise_model: "gaussian along the true surface normal".into(),
        crs_epsg: CRS_EPSG,
        crs_wkt: UTM33N_WKT.into(),
        epochs,
        pairs: (1..n)
            .map(|k| truth_pair(&r.model, k - 1, k))
            .collect::<Result<_>>()?,
        baseline_pairs: (2..n)
            .map(|k| truth_pair(&r.model, 0, k))
            .collect::<Result<_>>()?,
    };
    write_json(&out_dir.join("truth.json"), &truth)?;
    Ok(truth)
}
