//! `--stable AREAS.geojson` (SPEC.md §1 "Stable ground the user knows"): the stable ground is the
//! core points inside the user's polygons; bad areas are refused before anything runs (or, when
//! only the M3C2 results can tell, with the file named), exit 2, nothing published.

mod common;

use std::path::Path;

use serde_json::{json, Value};

fn json_file(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// A FeatureCollection of one polygon per rectangle [x0, y0, x1, y1], named in EPSG `epsg`.
fn rects(rects: &[[f64; 4]], epsg: Option<u32>) -> Value {
    let features: Vec<Value> = rects
        .iter()
        .map(|r| {
            json!({"type": "Feature", "properties": {}, "geometry": {"type": "Polygon",
                "coordinates": [[[r[0], r[1]], [r[2], r[1]], [r[2], r[3]], [r[0], r[3]], [r[0], r[1]]]]}})
        })
        .collect();
    let mut v = json!({"type": "FeatureCollection", "features": features});
    if let Some(e) = epsg {
        v["crs"] =
            json!({"type": "name", "properties": {"name": format!("urn:ogc:def:crs:EPSG::{e}")}});
    }
    v
}

/// The cliff scene's beach west of the debris fan and the plateau between the two scars: ground
/// that does not change (scene frame: x 500000–500060, the face at y = 5000000, the beach south
/// of it, the plateau north).
const STABLE: [[f64; 4]; 2] = [
    [500002.0, 4999982.0, 500018.0, 4999994.0],
    [500018.0, 5000002.0, 500034.0, 5000009.0],
];

/// Polygons over unchanged beach and plateau: summary.json says `stable.source` = user, names
/// the file, and counts as stable at least 90 % of the core points inside (the robust fit may
/// leave out a few) and no more; σ_d is the automatic one's within 25 %; the events are the same
/// ones with the same volumes within 1 %.
#[test]
fn polygons_over_stable_ground_are_the_stable_ground() {
    let tmp = common::tempdir();
    let (b, a) = common::synth_cliff(tmp.path(), 120_000);
    let areas = tmp.path().join("stable.geojson");
    std::fs::write(&areas, rects(&STABLE, Some(32633)).to_string()).unwrap();
    let auto = tmp.path().join("auto");
    let mine = tmp.path().join("areas");
    for (out, extra) in [
        (&auto, vec![]),
        (&mine, vec!["--stable", areas.to_str().unwrap()]),
    ] {
        let o = common::run_compare(&b, &a, out, &extra);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let (sa, sm) = (
        json_file(&auto.join("summary.json")),
        json_file(&mine.join("summary.json")),
    );
    assert_eq!(sa["stable"]["source"], "auto");
    assert_eq!(sm["stable"]["source"], "user");
    assert!(sm["stable"]["file"]
        .as_str()
        .unwrap()
        .ends_with("stable.geojson"));
    // The core points inside the polygons with a distance, from m3c2.laz.
    let (_, pts) = talus::io::read_all(&mine.join("m3c2.laz")).unwrap();
    let polys = talus::spatial::areas::Areas::read(&areas).unwrap();
    let inside = pts.iter().filter(|p| polys.contains(p[0], p[1])).count();
    let stable = sm["stable"]["stable_points"].as_u64().unwrap() as usize;
    assert!(inside > 500, "{inside} core points inside");
    assert!(
        stable <= inside && stable as f64 >= 0.9 * inside as f64,
        "{stable} stable of {inside} inside"
    );
    let sigma = |s: &Value| s["stable"]["sigma_d"].as_f64().unwrap();
    assert!(
        (sigma(&sm) / sigma(&sa) - 1.0).abs() < 0.25,
        "σ_d {} with the areas, {} automatic",
        sigma(&sm),
        sigma(&sa)
    );
    let volumes = |dir: &Path| -> Vec<f64> {
        let e = json_file(&dir.join("events.geojson"));
        let mut v: Vec<f64> = e["features"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|f| f["properties"]["significant"] == true)
            .filter_map(|f| f["properties"]["volume_m3"].as_f64())
            .collect();
        v.sort_by(|a, b| a.total_cmp(b));
        v
    };
    let (va, vm) = (volumes(&auto), volumes(&mine));
    assert_eq!(va.len(), 3, "{va:?}");
    assert_eq!(vm.len(), va.len(), "{vm:?} vs {va:?}");
    for (x, y) in va.iter().zip(&vm) {
        assert!((x - y).abs() <= 0.01 * x.abs(), "{vm:?} vs {va:?}");
    }
}

/// Each bad file is refused with exit 2 and a message naming the file and the problem, and no
/// summary.json is published: a file that is not JSON, a line among the polygons, a CRS other
/// than the surveys', a polygon wholly outside the surveys, a missing file, and polygons that hold
/// no core point (known only once M3C2 has run).
#[test]
fn bad_stable_areas_are_refused_naming_the_file() {
    let tmp = common::tempdir();
    let (b, a) = common::synth_cliff(tmp.path(), 120_000);
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "notjson.geojson",
            "{ this is not json".into(),
            "not GeoJSON",
        ),
        (
            "line.geojson",
            json!({"type": "FeatureCollection", "features": [
                rects(&STABLE[..1], None)["features"][0].clone(),
                {"type": "Feature", "geometry": {"type": "LineString",
                    "coordinates": [[500010.0, 4999990.0], [500020.0, 4999990.0]]}}]})
            .to_string(),
            "feature 1 is a LineString",
        ),
        (
            "crs.geojson",
            rects(&STABLE, Some(32755)).to_string(),
            "EPSG:32755",
        ),
        (
            "outside.geojson",
            rects(&[[300000.0, 5773000.0, 300010.0, 5773010.0]], None).to_string(),
            "polygon 0",
        ),
        (
            "nocore.geojson",
            // 2 mm wide: inside the surveys, but between core points.
            rects(&[[500010.0, 4999985.0, 500010.002, 4999985.002]], None).to_string(),
            "none with a distance",
        ),
    ];
    for (k, (name, content, words)) in cases.iter().enumerate() {
        let path = tmp.path().join(name);
        std::fs::write(&path, content).unwrap();
        let out = tmp.path().join(format!("out{k}"));
        let o = common::run_compare(&b, &a, &out, &["--stable", path.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert!(
            err.contains(name),
            "{name}: the message names the file: {err}"
        );
        assert!(err.contains(words), "{name}: '{words}' in: {err}");
        assert!(!out.join("summary.json").exists(), "{name}: published");
        assert!(path.exists(), "{name}: the user's file is kept");
    }
    let missing = tmp.path().join("missing.geojson");
    let o = common::run_compare(
        &b,
        &a,
        &tmp.path().join("out_missing"),
        &["--stable", missing.to_str().unwrap()],
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("missing.geojson") && err.contains("no such file"),
        "{err}"
    );
}

/// The CRS a survey's WKT names (its outermost AUTHORITY), which the check above compares.
#[test]
fn a_surveys_wkt_names_its_epsg_code() {
    let tmp = common::tempdir();
    let (b, _) = common::synth_cliff(tmp.path(), 120_000);
    let r = talus::io::open(&b).unwrap();
    assert_eq!(r.info().crs.epsg_code(), Some(32633));
}
