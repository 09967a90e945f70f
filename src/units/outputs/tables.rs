//! events.geojson, event_regions.geojson and events.csv (SPEC.md §2).

use serde::{Deserialize, Deserializer, Serialize};
use serde_json::Value;

use super::EventRecord;
use crate::error::{Error, Result};
use crate::events::{Kind, Obb};
use crate::geom::Point3;
use crate::io::Crs;
use crate::store::UnitWriter;
use crate::units::write_bytes;

/// A finite value, or none (written `null`).
fn finite(v: Option<f64>) -> Option<f64> {
    v.filter(|x| x.is_finite())
}

/// A number written as `null` when it is not finite (serde_json writes NaN so), read back as
/// NaN.
fn nan_if_null<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// The parts of an event's 95 % volume interval (SPEC.md §1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct UncertaintyParts {
    #[serde(deserialize_with = "nan_if_null")]
    pub(crate) random: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub(crate) correlated: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub(crate) systematic: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub(crate) sampling: f64,
}

/// The properties of one event: what events.geojson holds (events.csv the same, flattened), and
/// what a campaign reads back from its pairs. Written through a JSON value, so the keys come
/// out in name order whatever the order here.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct EventProperties {
    pub(crate) id: u32,
    pub(crate) kind: Kind,
    pub(crate) volume_m3: Option<f64>,
    pub(crate) volume_uncertainty_m3: Option<f64>,
    /// |V| exceeds its 95 % half-width.
    pub(crate) significant: bool,
    pub(crate) uncertainty_parts_m3: Option<UncertaintyParts>,
    pub(crate) gain_m3: Option<f64>,
    pub(crate) loss_m3: Option<f64>,
    pub(crate) n_points: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub(crate) area_m2: f64,
    pub(crate) footprint_area_m2: Option<f64>,
    pub(crate) region_area_m2: Option<f64>,
    pub(crate) coverage: Option<f64>,
    #[serde(deserialize_with = "nan_if_null")]
    pub(crate) mean_distance_m: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub(crate) max_abs_distance_m: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub(crate) mean_lod95_m: f64,
    pub(crate) obb: Obb,
    /// False where a limit cut the event's measurement short (`volume_note` says which).
    pub(crate) complete: bool,
    pub(crate) volume_note: Option<String>,
    /// The share of its core points that look like vegetation in either epoch (null: not
    /// judged, the volume came from the user's surfaces). Absent from older results.
    #[serde(default)]
    pub(crate) vegetation_fraction: Option<f64>,
    /// Most of its core points look like vegetation: listed, but left out of totals, tracks and
    /// the magnitude–frequency fit unless `--vegetation keep`.
    #[serde(default)]
    pub(crate) vegetation: bool,
    /// The data decides which side of the surface is out over most of it (false: a face near
    /// vertical scanned alone, its gain and loss may be the reverse; `complete` is false and
    /// `volume_note` says so). Absent from older results: true.
    #[serde(default = "known")]
    pub(crate) sign_known: bool,
}

fn known() -> bool {
    true
}

impl EventProperties {
    /// The properties of event `r`.
    pub(crate) fn of(r: &EventRecord) -> EventProperties {
        let e = &r.event;
        EventProperties {
            id: e.id,
            kind: e.kind,
            volume_m3: finite(r.volume_m3),
            volume_uncertainty_m3: finite(r.volume_uncertainty_m3),
            significant: r.significant,
            uncertainty_parts_m3: r.uncertainty.map(|u| UncertaintyParts {
                random: u.random_m3,
                correlated: u.correlated_m3,
                systematic: u.systematic_m3,
                sampling: u.sampling_m3,
            }),
            gain_m3: finite(r.gain_m3),
            loss_m3: finite(r.loss_m3),
            n_points: e.n_points,
            area_m2: e.area_m2,
            footprint_area_m2: finite(r.footprint_area_m2),
            region_area_m2: finite(r.region_area_m2),
            coverage: finite(r.coverage),
            mean_distance_m: e.mean_distance,
            max_abs_distance_m: e.max_abs_distance,
            mean_lod95_m: e.mean_lod95,
            obb: e.obb,
            complete: r.complete,
            volume_note: r.volume_note.clone(),
            vegetation_fraction: finite(r.vegetation_fraction),
            vegetation: r.vegetation,
            sign_known: r.sign_known,
        }
    }
}

/// A point's geometry.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", content = "coordinates")]
pub(crate) enum PointGeometry {
    Point(Point3),
}

/// GeoJSON's `"type": "Feature"` of a feature.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) enum Feature {
    #[default]
    Feature,
}

/// GeoJSON's `"type": "FeatureCollection"` of a collection.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) enum Collection {
    #[default]
    FeatureCollection,
}

/// An event of events.geojson.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct EventFeature {
    #[serde(rename = "type")]
    pub(crate) kind: Feature,
    pub(crate) geometry: PointGeometry,
    pub(crate) properties: EventProperties,
}

/// An event's region outline: one polygon, or several.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", content = "coordinates")]
pub(crate) enum RegionGeometry {
    Polygon(Vec<Vec<Point3>>),
    MultiPolygon(Vec<Vec<Vec<Point3>>>),
}

impl RegionGeometry {
    /// Its polygons.
    pub(crate) fn polygons(self) -> Vec<Vec<Vec<Point3>>> {
        match self {
            RegionGeometry::Polygon(p) => vec![p],
            RegionGeometry::MultiPolygon(ps) => ps,
        }
    }
}

/// What event_regions.geojson says of an event beside its outline.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct RegionProperties {
    pub(crate) id: u32,
    pub(crate) kind: Kind,
    pub(crate) volume_m3: Option<f64>,
    pub(crate) region_area_m2: Option<f64>,
    pub(crate) coverage: Option<f64>,
}

/// An event's region (no geometry for an event without a volume).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct RegionFeature {
    #[serde(rename = "type")]
    pub(crate) kind: Feature,
    pub(crate) geometry: Option<RegionGeometry>,
    pub(crate) properties: RegionProperties,
}

/// A GeoJSON FeatureCollection of features `F`, with the CRS's name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct FeatureCollection<F> {
    #[serde(rename = "type")]
    pub(crate) kind: Collection,
    pub(crate) crs_name: String,
    pub(crate) features: Vec<F>,
}

impl<F: Serialize> FeatureCollection<F> {
    /// The collection of `features`.
    pub(crate) fn new(crs_name: String, features: Vec<F>) -> FeatureCollection<F> {
        FeatureCollection {
            kind: Collection::FeatureCollection,
            crs_name,
            features,
        }
    }

    /// As a JSON value: keys in name order, as every talus JSON file writes them.
    pub(crate) fn to_value(&self) -> Result<Value> {
        serde_json::to_value(self).map_err(|e| Error::Internal(e.to_string()))
    }
}

/// Is `name` a mesh file talus writes (`event_NNNN_before.ply` / `event_NNNN_after.ply`)?
pub(crate) fn is_event_mesh(name: &str) -> bool {
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
pub(crate) fn write_regions(out: &mut UnitWriter, events: &[EventRecord], crs: &Crs) -> Result<()> {
    let features: Vec<RegionFeature> = events
        .iter()
        .map(|r| RegionFeature {
            kind: Feature::Feature,
            geometry: match r.region.len() {
                0 => None,
                1 => Some(RegionGeometry::Polygon(r.region[0].clone())),
                _ => Some(RegionGeometry::MultiPolygon(r.region.clone())),
            },
            properties: RegionProperties {
                id: r.event.id,
                kind: r.event.kind,
                volume_m3: finite(r.volume_m3),
                region_area_m2: finite(r.region_area_m2),
                coverage: finite(r.coverage),
            },
        })
        .collect();
    let fc = FeatureCollection::new(crs.describe(), features).to_value()?;
    let text = serde_json::to_string(&fc).map_err(|e| Error::Internal(e.to_string()))?;
    write_bytes(out, "event_regions.geojson", text.as_bytes())
}

/// Write events.geojson and events.csv.
pub(crate) fn write_tables(out: &mut UnitWriter, events: &[EventRecord], crs: &Crs) -> Result<()> {
    let features: Vec<EventFeature> = events
        .iter()
        .map(|r| EventFeature {
            kind: Feature::Feature,
            geometry: PointGeometry::Point(r.event.centroid),
            properties: EventProperties::of(r),
        })
        .collect();
    let fc = FeatureCollection::new(crs.describe(), features).to_value()?;
    let text = serde_json::to_string_pretty(&fc).map_err(|e| Error::Internal(e.to_string()))?;
    write_bytes(out, "events.geojson", text.as_bytes())?;

    let mut csv = String::from(
        "id,kind,x,y,z,volume_m3,volume_uncertainty_m3,significant,gain_m3,loss_m3,n_points,area_m2,\
         mean_distance_m,max_abs_distance_m,mean_lod95_m,coverage,region_area_m2,obb_center_x,obb_center_y,obb_center_z,\
         obb_axis1_x,obb_axis1_y,obb_axis1_z,obb_axis2_x,obb_axis2_y,obb_axis2_z,\
         obb_axis3_x,obb_axis3_y,obb_axis3_z,obb_half_1,obb_half_2,obb_half_3,complete,volume_note,\
         vegetation_fraction,vegetation,sign_known\n",
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
        row.push(f(r.vegetation_fraction));
        row.push(r.vegetation.to_string());
        row.push(r.sign_known.to_string());
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    write_bytes(out, "events.csv", csv.as_bytes())
}

/// A CSV field: quoted (quotes doubled) when it holds a comma, a quote or a line break.
pub(crate) fn csv_text(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}
