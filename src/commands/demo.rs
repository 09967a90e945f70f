//! `talus demo`: the cliff scene synthesized, compared with derived parameters only, and its
//! events printed beside the planted truth.

use std::path::Path;

use crate::error::{Error, Result};
use crate::synth::{SceneKind, SynthOptions};

/// `talus demo`: synthesize the cliff scene, compare it with derived parameters only, and print
/// each event beside the planted truth it matches (nearest centre of the same kind).
pub(crate) fn demo(out: &Path, view: bool) -> Result<()> {
    let scene = out.join("scene");
    let result = out.join("result");
    let truth = crate::synth::synth(SceneKind::Cliff, &SynthOptions::default(), &scene)?;
    let opts = crate::commands::compare::CompareOptions {
        before: scene.join(&truth.epochs[0]),
        after: scene.join(&truth.epochs[1]),
        out: result.clone(),
        force: true,
        ..Default::default()
    };
    let summary = crate::commands::compare::compare(&opts)?
        .ok_or_else(|| Error::Internal("demo: no summary".into()))?;
    let text = std::fs::read_to_string(result.join("events.geojson"))
        .map_err(|e| Error::Internal(format!("events.geojson: {e}")))?;
    let fc: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::Internal(e.to_string()))?;
    println!(
        "talus demo: {} — {} + {} points, {} planted change(s)",
        truth.summary,
        truth.points[0],
        truth.points[1],
        truth.events.len()
    );
    println!(
        "{:>3}  {:<5} {:>20}  {:>34}  {:>10}  {:>7}",
        "id", "kind", "volume m³", "centre (x, y, z)", "truth m³", "error"
    );
    let empty = vec![];
    for f in fc["features"].as_array().unwrap_or(&empty) {
        let p = &f["properties"];
        let c: Vec<f64> = f["geometry"]["coordinates"]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_f64()).collect())
            .unwrap_or_default();
        let kind = p["kind"].as_str().unwrap_or("?");
        let v = p["volume_m3"].as_f64();
        let u = p["volume_uncertainty_m3"].as_f64().unwrap_or(f64::NAN);
        let matched = truth
            .events
            .iter()
            .filter(|t| t.kind == kind && c.len() == 3)
            .min_by(|a, b| {
                let d = |t: &&crate::synth::TruthEvent| {
                    (t.centre[0] - c[0]).powi(2)
                        + (t.centre[1] - c[1]).powi(2)
                        + (t.centre[2] - c[2]).powi(2)
                };
                d(a).total_cmp(&d(b))
            });
        let (tv, err) = match (matched, v) {
            (Some(t), Some(v)) => (
                format!("{:+.3}", t.volume_m3),
                format!("{:+.2} %", 100.0 * (v - t.volume_m3) / t.volume_m3.abs()),
            ),
            _ => ("-".into(), "-".into()),
        };
        println!(
            "{:>3}  {:<5} {:>20}  {:>34}  {:>10}  {:>7}",
            p["id"].as_u64().unwrap_or(0),
            kind,
            v.map(|v| format!("{v:+.3} ± {u:.3}"))
                .unwrap_or_else(|| "-".into()),
            if c.len() == 3 {
                format!("{:.2}, {:.2}, {:.2}", c[0], c[1], c[2])
            } else {
                "-".into()
            },
            tv,
            err
        );
    }
    println!(
        "{} core points, {} tile(s); outputs in {} (m3c2.laz, events.geojson, event_regions.geojson, events.csv, meshes/, summary.json)",
        summary.core_points,
        summary.tiles,
        result.display()
    );
    if view {
        return super::view::command(&result, super::view::DEFAULT_BIND, 0);
    }
    println!("see them with: talus view {}", result.display());
    Ok(())
}
