//! `talus synth`: synthetic pairs of epochs with exactly known ground truth.
//!
//! Each scene is two analytic surfaces (`scenes`) whose difference has a closed-form volume per
//! change event. Each epoch is sampled independently (its own random streams), uniformly by area
//! over its true surface including vertical faces (box walls, the cliff face, scar walls), with
//! Gaussian noise of standard deviation `noise` applied along the surface normal (so a flat
//! surface gets vertical noise and a cliff face horizontal noise, as a scanner's range noise
//! would roughly do). Points are generated and written in chunks of at most
//! [`CHUNK_POINTS`] (`sampling`), so the 120M-point scene never sits in memory.
//!
//! Outputs in the directory: `before.laz` and `after.laz` (or `.las`): LAS 1.4, point format 6,
//! scale 1 mm, offsets at the scene origin (x = 500 000, y = 5 000 000, z = 0: UTM-like, ground at
//! z ≈ 100), a WKT CRS VLR for WGS 84 / UTM zone 33N (EPSG:32633); and `truth.json`
//! ([`Truth`]). Every file is written under a temporary name and renamed when complete.
//!
//! Evaluating the scenes is the point: the volumes follow Gorup & Bohak's synthetic tests (a hill,
//! a cube, spheres, mixed cubes) plus a cliff with rockfall scars and a debris fan, the same cliff
//! with a debris deposit on the beach just clear of the face (`deposit`), a bump half hidden from
//! epoch 1 by a hole in its coverage (`hole`: truth gives the whole and the observed volume), a
//! dozen small events laid out by the seed for calibration statistics (`events`), a stable pair
//! (false-positive check) and a large pair for the out-of-core path. `--shift` moves every epoch-2
//! point rigidly (a registration error the comparison must absorb; the truth is unchanged).
//!
//! [`campaign`] (`talus synth campaign`) writes N surveys of one site instead of a pair, with the
//! truth of every consecutive pair and of every survey against the first.

pub mod campaign;
pub(crate) mod face;
mod output;
pub(crate) mod owned;
mod plants;
mod sampling;
pub(crate) mod scenes;
mod surface;
mod truth;

use std::path::{Path, PathBuf};
use std::str::FromStr;

pub use output::UTM33N_WKT;
pub use sampling::{Chunks, CHUNK_POINTS};
pub use scenes::{Footprint, ModelEvent, SceneModel};
pub use truth::{Truth, TruthEvent};

use sampling::Placement;
use surface::V3;
use talus_base::{Error, Result};

/// Global origin of the local scene coordinates (UTM-like easting, northing; z kept as is).
pub const ORIGIN: [f64; 3] = [500_000.0, 5_000_000.0, 0.0];

/// EPSG code of the CRS written in every synthetic file.
pub const CRS_EPSG: u32 = 32633;

/// The synthetic scenes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SceneKind {
    Hill,
    Cube,
    Spheres,
    Cubes,
    Cliff,
    Deposit,
    Hole,
    Events,
    Stable,
    Large,
    Dense,
    Beach,
    Vegetation,
    Face,
    FaceVertical,
}

impl SceneKind {
    /// All scenes, in the order of their names.
    pub const ALL: [SceneKind; 15] = [
        SceneKind::Hill,
        SceneKind::Cube,
        SceneKind::Spheres,
        SceneKind::Cubes,
        SceneKind::Cliff,
        SceneKind::Deposit,
        SceneKind::Hole,
        SceneKind::Events,
        SceneKind::Stable,
        SceneKind::Large,
        SceneKind::Dense,
        SceneKind::Beach,
        SceneKind::Vegetation,
        SceneKind::Face,
        SceneKind::FaceVertical,
    ];

    /// The scene's name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Hill => "hill",
            SceneKind::Cube => "cube",
            SceneKind::Spheres => "spheres",
            SceneKind::Cubes => "cubes",
            SceneKind::Cliff => "cliff",
            SceneKind::Deposit => "deposit",
            SceneKind::Hole => "hole",
            SceneKind::Events => "events",
            SceneKind::Stable => "stable",
            SceneKind::Large => "large",
            SceneKind::Dense => "dense",
            SceneKind::Beach => "beach",
            SceneKind::Vegetation => "vegetation",
            SceneKind::Face => "face",
            SceneKind::FaceVertical => "face-vertical",
        }
    }

    /// Points per epoch when none are asked for.
    pub fn default_points(self) -> u64 {
        scenes::default_points(self)
    }

    /// Noise standard deviation (m) when none is asked for: 1 cm for `stable` and `events`, else
    /// 5 mm.
    pub(crate) fn default_noise(self) -> f64 {
        scenes::default_noise(self)
    }
}

impl std::fmt::Display for SceneKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SceneKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let lower = s.trim().to_ascii_lowercase();
        SceneKind::ALL
            .into_iter()
            .find(|k| k.name() == lower)
            .ok_or_else(|| {
                let names: Vec<&str> = SceneKind::ALL.iter().map(|k| k.name()).collect();
                Error::Usage(format!(
                    "unknown scene '{s}': expected one of {} (or campaign: many surveys)",
                    names.join(", ")
                ))
            })
    }
}

/// Options of [`synth`].
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    /// Points per epoch (epoch 2 gets `points · density2`; an epoch with holes its observed share
    /// of them); None = the scene's default.
    pub points: Option<u64>,
    pub seed: u64,
    /// Noise standard deviation (m) along the surface normal; None = the scene's default.
    pub noise: Option<f64>,
    /// Rotate the whole scene about the vertical axis through its centre (degrees, CCW).
    pub rotate_deg: f64,
    /// Epoch-2 density relative to epoch 1.
    pub density2: f64,
    /// Rigid translation (m, global axes) of every epoch-2 point after sampling and rotation: a
    /// registration error between the surveys, not a change (the truth volumes ignore it).
    pub shift_m: [f64; 3],
    /// Rigid turn (degrees about x, y, z through the scene's centre) of every epoch-2 point: a
    /// registration error with `shift_m`, not a change.
    pub turn_deg: [f64; 3],
    /// A slow landslide under the whole scene between the surveys (m): every epoch-2 point
    /// settles by this times a smooth field between 0.25 and 1 (`sampling::creep_share`); not
    /// a change of the planted events (the truth volumes ignore it), nor rigid.
    pub creep_m: f64,
    /// Write LAZ (true) or LAS.
    pub laz: bool,
    /// A scene with plants (`vegetation`) delivered classified: ground 2, grass 3, shrubs 4,
    /// trees 5; otherwise every point of it is unclassified (1). Other scenes are ground (2).
    pub classified: bool,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            points: None,
            seed: 1,
            noise: None,
            rotate_deg: 0.0,
            density2: 1.0,
            shift_m: [0.0; 3],
            turn_deg: [0.0; 3],
            creep_m: 0.0,
            laz: true,
            classified: false,
        }
    }
}

/// Largest point count per epoch accepted (keeps the large scene's coordinates far inside the
/// LAS i32 range at 1 mm scale).
const MAX_POINTS: u64 = 100_000_000_000;
/// Smallest point count per epoch accepted for the small scenes.
const MIN_POINTS: u64 = 100;
/// Largest accepted |component| of `--shift` (m): a registration error, not a relocation.
const MAX_SHIFT: f64 = 1000.0;

/// Largest accepted |angle| of `--turn` (degrees): a registration error, not a relocation.
const MAX_TURN: f64 = 10.0;

/// Parse `--shift DX,DY,DZ` (metres).
pub fn parse_shift(s: &str) -> Result<[f64; 3]> {
    parse_triple(s, "DX,DY,DZ in metres")
}

/// Parse `--turn RX,RY,RZ` (degrees).
pub fn parse_turn(s: &str) -> Result<[f64; 3]> {
    parse_triple(s, "RX,RY,RZ in degrees")
}

/// Three comma-separated numbers (`what` says which, for the message).
fn parse_triple(s: &str, what: &str) -> Result<[f64; 3]> {
    let bad = || Error::Usage(format!("expected {what}, got '{s}'"));
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().map_err(|_| bad()))
        .collect::<Result<_>>()?;
    <[f64; 3]>::try_from(v).map_err(|_| bad())
}

/// The checked, resolved parameters of a run.
struct Resolved {
    points: [u64; 2],
    noise: f64,
}

/// `--points` of command `what` (e.g. "synth hill") must lie in [min, MAX_POINTS].
fn check_points(what: &str, n: u64, min: u64) -> Result<()> {
    if !(min..=MAX_POINTS).contains(&n) {
        return Err(Error::Usage(format!(
            "{what}: --points must be between {min} and {MAX_POINTS}, got {n}"
        )));
    }
    Ok(())
}

fn check_noise(noise: f64) -> Result<()> {
    if !(noise.is_finite() && (0.0..=1.0).contains(&noise)) {
        return Err(Error::Usage(format!(
            "synth: --noise must be between 0 and 1 m, got {noise}"
        )));
    }
    Ok(())
}

fn resolve(kind: SceneKind, opts: &SynthOptions) -> Result<Resolved> {
    let n1 = opts.points.unwrap_or_else(|| kind.default_points());
    let min = if kind == SceneKind::Large {
        scenes::LARGE_MIN_POINTS
    } else {
        MIN_POINTS
    };
    check_points(&format!("synth {kind}"), n1, min)?;
    let noise = opts.noise.unwrap_or_else(|| kind.default_noise());
    check_noise(noise)?;
    if !opts
        .shift_m
        .iter()
        .all(|d| d.is_finite() && d.abs() <= MAX_SHIFT)
    {
        return Err(Error::Usage(format!(
            "synth: --shift components must be finite and at most {MAX_SHIFT} m, got {:?}",
            opts.shift_m
        )));
    }
    if !opts
        .turn_deg
        .iter()
        .all(|d| d.is_finite() && d.abs() <= MAX_TURN)
    {
        return Err(Error::Usage(format!(
            "synth: --turn angles must be finite and at most {MAX_TURN}°, got {:?}",
            opts.turn_deg
        )));
    }
    if !opts.creep_m.is_finite() || opts.creep_m.abs() > MAX_SHIFT {
        return Err(Error::Usage(format!(
            "synth: --creep must be finite and at most {MAX_SHIFT} m, got {}",
            opts.creep_m
        )));
    }
    if !opts.rotate_deg.is_finite() {
        return Err(Error::Usage(
            "synth: --rotate must be a finite angle".into(),
        ));
    }
    if !(opts.density2.is_finite() && opts.density2 > 0.0) {
        return Err(Error::Usage(format!(
            "synth: --density2 must be positive, got {}",
            opts.density2
        )));
    }
    let n2 = (n1 as f64 * opts.density2).round();
    if !(1.0..=MAX_POINTS as f64).contains(&n2) {
        return Err(Error::Usage(format!(
            "synth: epoch 2 would have {n2} points (--points × --density2); must be 1 to {MAX_POINTS}"
        )));
    }
    Ok(Resolved {
        points: [n1, n2 as u64],
        noise,
    })
}

/// The analytic model of a scene as [`synth`] would build it for `opts` (the large scene's size
/// depends on the point count, the events scene's layout on the seed).
pub fn scene_model(kind: SceneKind, opts: &SynthOptions) -> Result<SceneModel> {
    let r = resolve(kind, opts)?;
    Ok(SceneModel::new(kind, r.points[0], opts.seed))
}

/// The points of epoch `epoch` (0 = before, 1 = after) as [`synth`] writes them (global
/// coordinates, before 1 mm quantisation), as a lazy sequence of chunks of at most
/// [`CHUNK_POINTS`] points.
pub fn epoch_chunks(kind: SceneKind, opts: &SynthOptions, epoch: usize) -> Result<Chunks> {
    if epoch > 1 {
        return Err(Error::Usage(format!("epoch must be 0 or 1, got {epoch}")));
    }
    let r = resolve(kind, opts)?;
    let model = SceneModel::new(kind, r.points[0], opts.seed);
    if model.has_plants() || model.scanned.is_some() {
        return Err(Error::Usage(format!(
            "the {kind} scene's points are not samples of surface patches (plants, a scanner's \
             rays): its epochs are what `synth` writes"
        )));
    }
    Ok(chunks_of(
        &model,
        &r,
        opts,
        epoch,
        turn_height(&model, &r, opts),
    ))
}

/// The height (local) of the axis `--turn` turns about: the before survey's mean height, so that
/// the turn moves the scene by its angle times the scene's size, as a misregistered survey is
/// turned about its own centre (not about a datum far below it). Zero without a turn.
fn turn_height(model: &SceneModel, r: &Resolved, opts: &SynthOptions) -> f64 {
    if opts.turn_deg == [0.0; 3] {
        return 0.0;
    }
    if let Some(face) = &model.scanned {
        return face.centre_height();
    }
    let (mut n, mut sum) = (0u64, 0.0);
    for chunk in chunks_of(model, r, opts, 0, 0.0) {
        n += chunk.len() as u64;
        sum += chunk.iter().map(|p| p[2] - ORIGIN[2]).sum::<f64>();
    }
    sum / n.max(1) as f64
}

/// Where epoch `epoch`'s local points go: rotated about the scene's centre, moved to the global
/// origin, and for epoch 2 shifted by `--shift`.
fn placement(model: &SceneModel, opts: &SynthOptions, epoch: usize, turn_z: f64) -> Placement {
    let shift = if epoch == 1 { opts.shift_m } else { [0.0; 3] };
    let origin = [0, 1, 2].map(|k| ORIGIN[k] + shift[k]);
    let placement = Placement::new(model.centre, opts.rotate_deg, origin);
    if epoch == 1 {
        placement
            .turned(opts.turn_deg, turn_z)
            .creeping(opts.creep_m)
    } else {
        placement
    }
}

/// Points of epoch `epoch`: the requested count times the share of its surface that is observed
/// (so that holes keep the density of the rest).
fn epoch_points(model: &SceneModel, r: &Resolved, epoch: usize) -> u64 {
    (r.points[epoch] as f64 * model.observed[epoch]).round() as u64
}

fn chunks_of(
    model: &SceneModel,
    r: &Resolved,
    opts: &SynthOptions,
    epoch: usize,
    turn_z: f64,
) -> Chunks {
    Chunks::new(
        model.patches[epoch].clone(),
        epoch_points(model, r, epoch),
        opts.seed,
        epoch as u64,
        r.noise,
        placement(model, opts, epoch, turn_z),
    )
}

/// Generate scene `kind` into `out_dir` (created if missing): `before.laz`, `after.laz` (`.las`
/// when `opts.laz` is false) and `truth.json`, each written atomically. Returns the truth.
pub fn synth(kind: SceneKind, opts: &SynthOptions, out_dir: &Path) -> Result<Truth> {
    let r = resolve(kind, opts)?;
    let ext = if opts.laz { "laz" } else { "las" };
    let names = [
        PathBuf::from(format!("before.{ext}")),
        PathBuf::from(format!("after.{ext}")),
    ];
    // Only files synth wrote there itself are replaced (`owned`).
    let written: Vec<String> = names
        .iter()
        .map(|n| n.display().to_string())
        .chain(["truth.json".to_string()])
        .collect();
    let model = SceneModel::new(kind, r.points[0], opts.seed);
    if opts.classified && !model.has_plants() {
        // It was accepted and did nothing: the scene's points are ground, class 2, either way.
        return Err(Error::Usage(format!(
            "synth {}: --classified is for a scene with plants (vegetation): this one's points \
             are all ground, class 2, already",
            kind.name()
        )));
    }
    owned::take(out_dir, &written)?;
    let mut written = [0u64; 2];
    let turn_z = turn_height(&model, &r, opts);
    // Scenes without plants are ground, as before; a scene with plants is unclassified unless
    // asked for classified.
    let classified = !model.has_plants() || opts.classified;
    for epoch in 0..2 {
        if let Some(face) = &model.scanned {
            // A terrestrial scan of a face: delivered unclassified (1), as scans are.
            let place = placement(&model, opts, epoch, turn_z);
            let points: Vec<V3> = face
                .scan(epoch, r.points[epoch], r.noise, opts.seed)
                .into_iter()
                .map(|p| place.apply(p))
                .collect();
            let n = points.len() as u64;
            written[epoch] = output::write_epoch(
                &out_dir.join(&names[epoch]),
                std::iter::once((points, 1)),
                ORIGIN,
                epoch as u16 + 1,
                opts.laz,
            )?;
            if written[epoch] != n {
                return Err(Error::Internal(format!(
                    "synth wrote {} points, scanned {n}",
                    written[epoch]
                )));
            }
            continue;
        }
        let chunks = chunks_of(&model, &r, opts, epoch, turn_z).behind(model.plants[epoch].clone());
        let density = epoch_points(&model, &r, epoch) as f64 / chunks.area();
        let place = placement(&model, opts, epoch, turn_z);
        let ground = chunks.map(move |c| (c, if classified { 2 } else { 1 }));
        // A few thousand points a plant: held whole.
        let plants: Vec<(Vec<V3>, u8)> = model.plants[epoch]
            .iter()
            .map(|p| {
                let points = p
                    .points(density, opts.seed, epoch as u64)
                    .into_iter()
                    .map(|q| place.apply(q))
                    .collect();
                (points, if classified { p.class() } else { 1 })
            })
            .collect();
        let plant_points: u64 = plants.iter().map(|p| p.0.len() as u64).sum();
        written[epoch] = output::write_epoch(
            &out_dir.join(&names[epoch]),
            ground.chain(plants),
            ORIGIN,
            epoch as u16 + 1,
            opts.laz,
        )?;
        let planned = epoch_points(&model, &r, epoch) + plant_points;
        if written[epoch] != planned {
            return Err(Error::Internal(format!(
                "synth wrote {} points, planned {planned}",
                written[epoch]
            )));
        }
    }
    let events = truth_events(&model.events, &placement(&model, opts, 0, 0.0));
    let truth = Truth {
        scene: kind.name().into(),
        summary: model.summary.clone(),
        seed: opts.seed,
        epochs: names,
        points: written,
        noise_m: r.noise,
        noise_model: "gaussian along the true surface normal".into(),
        rotate_deg: opts.rotate_deg,
        rotation_centre: [ORIGIN[0] + model.centre[0], ORIGIN[1] + model.centre[1]],
        density2: opts.density2,
        shift_m: opts.shift_m,
        turn_deg: opts.turn_deg,
        turn_centre: (opts.turn_deg != [0.0; 3]).then(|| {
            [
                ORIGIN[0] + model.centre[0],
                ORIGIN[1] + model.centre[1],
                ORIGIN[2] + turn_z,
            ]
        }),
        creep_m: opts.creep_m,
        scanner: model
            .scanned
            .as_ref()
            .map(|f| placement(&model, opts, 0, 0.0).apply(f.scanner)),
        crs_epsg: CRS_EPSG,
        crs_wkt: UTM33N_WKT.into(),
        total_gain_m3: events.iter().map(|e| e.volume_m3.max(0.0)).sum(),
        total_loss_m3: events.iter().map(|e| e.volume_m3.min(0.0)).sum(),
        events,
    };
    write_json(&out_dir.join("truth.json"), &truth)?;
    Ok(truth)
}

/// The truth of a model's events, ids from 1, centres placed in global coordinates.
fn truth_events(events: &[ModelEvent], place: &Placement) -> Vec<TruthEvent> {
    events
        .iter()
        .enumerate()
        .map(|(i, e)| TruthEvent {
            id: i as u32 + 1,
            kind: if e.volume_m3 >= 0.0 { "gain" } else { "loss" }.into(),
            volume_m3: e.volume_m3,
            covered_volume_m3: e.covered_volume_m3,
            centre: place.apply(e.centre),
            radius_m: e.radius_m,
            description: e.description.clone(),
        })
        .collect()
}

/// Write `truth` as pretty JSON to `path` (atomically).
fn write_json(path: &Path, truth: &impl serde::Serialize) -> Result<()> {
    let json = serde_json::to_vec_pretty(truth)
        .map_err(|e| Error::Internal(format!("truth.json: {e}")))?;
    Ok(talus_tiling::atomic_write(path, &json)?)
}
