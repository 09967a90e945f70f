//! The ground truth written next to a synthetic pair (`truth.json`).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// One true change event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthEvent {
    /// 1-based, in scene order.
    pub id: u32,
    /// "gain" or "loss" (the sign of `volume_m3`).
    pub kind: String,
    /// Signed volume change V(after) − V(before), m³ (loss < 0), from the closed-form formula.
    pub volume_m3: f64,
    /// The part of `volume_m3` over ground both epochs observed, closed form; only for events
    /// partly inside a hole of one epoch (the `hole` scene), where it is what the points can show.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covered_volume_m3: Option<f64>,
    /// Centre of the event's footprint on the epoch-1 surface, global coordinates.
    pub centre: [f64; 3],
    /// Radius (m) of a circle about `centre` containing the changed footprint.
    pub radius_m: f64,
    pub description: String,
}

/// Everything a comparison run is judged against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Scene name ("hill", "cube", ...).
    pub scene: String,
    /// One-line description of the scene.
    pub summary: String,
    pub seed: u64,
    /// The two epoch files, relative to the directory of truth.json: [before, after].
    pub epochs: [PathBuf; 2],
    /// Points written per epoch.
    pub points: [u64; 2],
    /// Standard deviation of the noise (m).
    pub noise_m: f64,
    /// How noise was applied.
    pub noise_model: String,
    /// Rotation of the whole scene about the vertical axis through `rotation_centre` (degrees,
    /// counter-clockwise seen from above).
    pub rotate_deg: f64,
    /// Global (x, y) of the rotation axis.
    pub rotation_centre: [f64; 2],
    /// Epoch-2 density relative to epoch 1.
    pub density2: f64,
    /// Rigid translation (m) of every epoch-2 point, applied after the rotation: a registration
    /// error, not a change (the volumes are the real changes). Absent in older files: zero.
    #[serde(default)]
    pub shift_m: [f64; 3],
    /// Rigid turn (degrees about x, then y, then z through `turn_centre`) of every epoch-2
    /// point, after the rotation and with the shift: a registration error, not a change. Absent:
    /// zero.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub turn_deg: [f64; 3],
    /// Global coordinates of the point `turn_deg` turns about: the scene's centre at the before
    /// survey's mean height. Absent without a turn.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turn_centre: Option<[f64; 3]>,
    /// A slow landslide's settling (m) of every epoch-2 point, times a smooth field between 0.25
    /// and 1 of its place: not a change of the planted events, nor rigid. Absent: none.
    #[serde(default, skip_serializing_if = "is_zero_f64")]
    pub creep_m: f64,
    /// Where the terrestrial scanner stood (global coordinates) for a scanned scene (`face`,
    /// `face-vertical`); absent for the others.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scanner: Option<[f64; 3]>,
    /// EPSG code of the CRS written in both files.
    pub crs_epsg: u32,
    /// The OGC WKT (version 1) written in both files' WKT CRS VLR.
    pub crs_wkt: String,
    pub events: Vec<TruthEvent>,
    /// Sum of the positive volumes, m³.
    pub total_gain_m3: f64,
    /// Sum of the negative volumes, m³ (≤ 0).
    pub total_loss_m3: f64,
}

fn is_zero_f64(v: &f64) -> bool {
    *v == 0.0
}

/// No shift or turn (serde's `skip_serializing_if` of truth files).
pub(super) fn is_zero(v: &[f64; 3]) -> bool {
    *v == [0.0; 3]
}
