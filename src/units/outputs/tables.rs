//! events.geojson, event_regions.geojson and events.csv (SPEC.md §2).

use serde_json::{json, Value};

use super::EventRecord;
use crate::error::{Error, Result};
use crate::io::Crs;
use crate::store::UnitWriter;
use crate::units::write_bytes;

fn opt(v: Option<f64>) -> Value {
    match v {
        Some(x) if x.is_finite() => json!(x),
        _ => Value::Null,
    }
}

/// The properties of one event (GeoJSON and CSV share them).
fn properties(r: &EventRecord) -> Value {
    let e = &r.event;
    json!({
        "id": e.id,
        "kind": e.kind.as_str(),
        "volume_m3": opt(r.volume_m3),
        "volume_uncertainty_m3": opt(r.volume_uncertainty_m3),
        "significant": r.significant,
        "uncertainty_parts_m3": r.uncertainty.map(|u| json!({
            "random": u.random_m3,
            "correlated": u.correlated_m3,
            "systematic": u.systematic_m3,
            "sampling": u.sampling_m3,
        })),
        "gain_m3": opt(r.gain_m3),
        "loss_m3": opt(r.loss_m3),
        "n_points": e.n_points,
        "area_m2": e.area_m2,
        "footprint_area_m2": opt(r.footprint_area_m2),
        "region_area_m2": opt(r.region_area_m2),
        "coverage": opt(r.coverage),
        "mean_distance_m": e.mean_distance,
        "max_abs_distance_m": e.max_abs_distance,
        "mean_lod95_m": e.mean_lod95,
        "obb": {
            "center": e.obb.center,
            "axes": e.obb.axes,
            "half_extents": e.obb.half_extents,
        },
        "complete": r.complete,
        "volume_note": r.volume_note,
    })
}

/// Is `name` a mesh file talus writes (`event_NNNN_before.ply` / `event_NNNN_after.ply`)?
pub fn is_event_mesh(name: &str) -> bool {
    let Some(rest) = name.strip_prefix("event_") else {
        return false;
    };
    let (digits, tail) = rest.split_at(rest.find('_').unwrap_or(rest.len()));
    !digits.is_empty()
        && digits.bytes().all(|b| b.is_ascii_digit())
        && (tail == "_before.ply" || tail == "_after.ply")
}

/// Write event_regions.geojson: per event the outline of the region its volume was integrated
/// over (Polygon or MultiPolygon, 3-D coordinates in the footprint plane; null geometry for an
/// event without a volume).
pub fn write_regions(out: &mut UnitWriter, events: &[EventRecord], crs: &Crs) -> Result<()> {
    let features: Vec<Value> = events
        .iter()
        .map(|r| {
            let geometry = match r.region.len() {
                0 => Value::Null,
                1 => json!({ "type": "Polygon", "coordinates": r.region[0] }),
                _ => json!({ "type": "MultiPolygon", "coordinates": r.region }),
            };
            json!({
                "type": "Feature",
                "geometry": geometry,
                "properties": {
                    "id": r.event.id,
                    "kind": r.event.kind.as_str(),
                    "volume_m3": opt(r.volume_m3),
                    "region_area_m2": opt(r.region_area_m2),
                    "coverage": opt(r.coverage),
                },
            })
        })
        .collect();
    let fc = json!({
        "type": "FeatureCollection",
        "crs_name": crs.describe(),
        "features": features,
    });
    let text = serde_json::to_string(&fc).map_err(|e| Error::Internal(e.to_string()))?;
    write_bytes(out, "event_regions.geojson", text.as_bytes())
}

/// Write events.geojson and events.csv.
pub fn write_tables(out: &mut UnitWriter, events: &[EventRecord], crs: &Crs) -> Result<()> {
    let features: Vec<Value> = events
        .iter()
        .map(|r| {
            json!({
                "type": "Feature",
                "geometry": { "type": "Point", "coordinates": r.event.centroid },
                "properties": properties(r),
            })
        })
        .collect();
    let fc = json!({
        "type": "FeatureCollection",
        "crs_name": crs.describe(),
        "features": features,
    });
    let text = serde_json::to_string_pretty(&fc).map_err(|e| Error::Internal(e.to_string()))?;
    write_bytes(out, "events.geojson", text.as_bytes())?;

    let mut csv = String::from(
        "id,kind,x,y,z,volume_m3,volume_uncertainty_m3,significant,gain_m3,loss_m3,n_points,area_m2,\
         mean_distance_m,max_abs_distance_m,mean_lod95_m,coverage,region_area_m2,obb_center_x,obb_center_y,obb_center_z,\
         obb_axis1_x,obb_axis1_y,obb_axis1_z,obb_axis2_x,obb_axis2_y,obb_axis2_z,\
         obb_axis3_x,obb_axis3_y,obb_axis3_z,obb_half_1,obb_half_2,obb_half_3,complete,volume_note\n",
    );
    let f = |v: Option<f64>| v.map(|x| format!("{x:.6}")).unwrap_or_default();
    for r in events {
        let e = &r.event;
        let o = &e.obb;
        let mut row = vec![
            e.id.to_string(),
            e.kind.as_str().to_string(),
            format!("{:.4}", e.centroid[0]),
            format!("{:.4}", e.centroid[1]),
            format!("{:.4}", e.centroid[2]),
            f(r.volume_m3),
            f(r.volume_uncertainty_m3),
            r.significant.to_string(),
            f(r.gain_m3),
            f(r.loss_m3),
            e.n_points.to_string(),
            format!("{:.6}", e.area_m2),
            format!("{:.6}", e.mean_distance),
            format!("{:.6}", e.max_abs_distance),
            format!("{:.6}", e.mean_lod95),
            f(r.coverage),
            f(r.region_area_m2),
        ];
        row.extend(o.center.iter().map(|v| format!("{v:.4}")));
        for a in &o.axes {
            row.extend(a.iter().map(|v| format!("{v:.6}")));
        }
        row.extend(o.half_extents.iter().map(|v| format!("{v:.4}")));
        row.push(r.complete.to_string());
        row.push(csv_text(r.volume_note.as_deref().unwrap_or("")));
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    write_bytes(out, "events.csv", csv.as_bytes())
}

/// A CSV field: quoted (quotes doubled) when it holds a comma, a quote or a line break.
pub fn csv_text(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}
