//! Stable areas the user knows (SPEC.md §1 "Stable ground the user knows", `--stable
//! AREAS.geojson`): polygons in the surveys' CRS, read from GeoJSON (RFC 7946 §3.1.6–7: a
//! Polygon is an outer ring and holes, a MultiPolygon several), and whether a point lies inside
//! one of them.
//!
//! Inside: the even–odd rule over the outer ring and the holes together (a horizontal ray from
//! the point crosses the rings an odd number of times; Shimrat 1962, "Algorithm 112: Position of
//! point relative to polygon"), so a point in a hole is outside. A point exactly on an edge may
//! fall either way, as in any crossing test: a core point there is on the border of the stable
//! ground, which changes nothing measurable.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// One polygon: its rings (the first the outer one, the rest holes), each a closed list of (x, y)
/// vertices.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Polygon {
    pub rings: Vec<Vec<[f64; 2]>>,
    /// [x0, y0, x1, y1] of the outer ring.
    pub bbox: [f64; 4],
}

impl Polygon {
    fn new(rings: Vec<Vec<[f64; 2]>>) -> Polygon {
        let mut b = [
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ];
        for p in &rings[0] {
            b = [
                b[0].min(p[0]),
                b[1].min(p[1]),
                b[2].max(p[0]),
                b[3].max(p[1]),
            ];
        }
        Polygon { rings, bbox: b }
    }

    /// Whether (x, y) lies inside (the even–odd rule over all rings).
    pub(crate) fn contains(&self, x: f64, y: f64) -> bool {
        let b = &self.bbox;
        if x < b[0] || x > b[2] || y < b[1] || y > b[3] {
            return false;
        }
        let mut inside = false;
        for ring in &self.rings {
            let n = ring.len();
            for i in 0..n {
                let (a, c) = (ring[i], ring[(i + 1) % n]);
                if (a[1] > y) != (c[1] > y) {
                    let cross = a[0] + (y - a[1]) / (c[1] - a[1]) * (c[0] - a[0]);
                    if x < cross {
                        inside = !inside;
                    }
                }
            }
        }
        inside
    }
}

/// The stable areas of a run: the polygons of one GeoJSON file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Areas {
    pub polygons: Vec<Polygon>,
    /// The EPSG code the file's `crs` member names (GeoJSON 2008 named CRS, e.g.
    /// `urn:ogc:def:crs:EPSG::32755`); None without one (RFC 7946 drops the member: the
    /// coordinates are then taken to be in the surveys' CRS).
    pub epsg: Option<u32>,
}

impl Areas {
    /// Whether (x, y) lies in one of the polygons.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        self.polygons.iter().any(|p| p.contains(x, y))
    }

    /// The share, at most 1, of the rectangle `within` ([x0, y0, x1, y1]) the polygons' boxes
    /// cover (overlaps counted twice): an upper bound of the share of its points inside them.
    pub(crate) fn box_share(&self, within: [f64; 4]) -> f64 {
        let area = |b: [f64; 4]| (b[2] - b[0]).max(0.0) * (b[3] - b[1]).max(0.0);
        let covered: f64 = self
            .polygons
            .iter()
            .map(|p| {
                let b = p.bbox;
                area([
                    b[0].max(within[0]),
                    b[1].max(within[1]),
                    b[2].min(within[2]),
                    b[3].min(within[3]),
                ])
            })
            .sum();
        (covered / area(within).max(f64::MIN_POSITIVE)).min(1.0)
    }

    /// One core point in how many to take from the areas so that about `target` are taken,
    /// when `points` core points cover the rectangle `within`: its share the polygons' boxes
    /// cover bounds how many of them lie inside (at least 1: narrow areas give every one).
    pub(crate) fn one_in(&self, within: [f64; 4], points: f64, target: u64) -> u64 {
        ((self.box_share(within) * points / target as f64).ceil() as u64).max(1)
    }

    /// Whether the core point of `key` is one of the one in `n` taken ([`Areas::one_in`]): by a
    /// hash of the key (SplitMix64), so the choice has no pattern in space and is the same
    /// whatever the tiles.
    pub(crate) fn takes(key: u64, n: u64) -> bool {
        crate::rng::SplitMix64::new(key)
            .next_u64()
            .is_multiple_of(n)
    }

    /// [x0, y0, x1, y1] of every polygon.
    pub(crate) fn boxes(&self) -> Vec<[f64; 4]> {
        self.polygons.iter().map(|p| p.bbox).collect()
    }

    /// Read `path`: a FeatureCollection, a Feature or a bare geometry, of Polygons and
    /// MultiPolygons only. Every problem is an input error naming the file (and the feature).
    pub fn read(path: &Path) -> Result<Areas> {
        let bytes = std::fs::read(path)
            .map_err(|e| Error::input(path, format!("cannot read the stable areas: {e}")))?;
        let v: serde_json::Value = serde_json::from_slice(&bytes)
            .map_err(|e| Error::input(path, format!("not GeoJSON (not valid JSON: {e})")))?;
        Self::parse(&v).map_err(|m| Error::input(path, m))
    }

    /// [`Areas::read`] of a parsed document; the problem in words.
    pub(crate) fn parse(v: &serde_json::Value) -> std::result::Result<Areas, String> {
        let kind = v.get("type").and_then(|t| t.as_str()).unwrap_or("");
        let geometries: Vec<(String, &serde_json::Value)> = match kind {
            "FeatureCollection" => v
                .get("features")
                .and_then(|f| f.as_array())
                .ok_or("a FeatureCollection without a \"features\" array")?
                .iter()
                .enumerate()
                .map(|(i, f)| {
                    let g = f
                        .get("geometry")
                        .filter(|g| !g.is_null())
                        .ok_or(format!("feature {i} has no geometry"))?;
                    Ok((format!("feature {i}"), g))
                })
                .collect::<std::result::Result<_, String>>()?,
            "Feature" => vec![(
                "its feature".into(),
                v.get("geometry")
                    .filter(|g| !g.is_null())
                    .ok_or("its feature has no geometry")?,
            )],
            "" => return Err("not GeoJSON: no \"type\" member".into()),
            _ => vec![("its geometry".into(), v)],
        };
        let mut polygons = Vec::new();
        for (what, g) in geometries {
            let t = g.get("type").and_then(|t| t.as_str()).unwrap_or("(none)");
            let coords = g.get("coordinates");
            match t {
                "Polygon" => polygons.push(polygon(coords, &what)?),
                "MultiPolygon" => {
                    let parts = coords
                        .and_then(|c| c.as_array())
                        .ok_or(format!("{what}: a MultiPolygon without coordinates"))?;
                    for (k, p) in parts.iter().enumerate() {
                        polygons.push(polygon(Some(p), &format!("{what}, polygon {k}"))?);
                    }
                }
                other => {
                    return Err(format!(
                        "{what} is a {other}: stable areas are Polygons or MultiPolygons (a line \
                         or a point holds no ground; buffer it into a polygon)"
                    ))
                }
            }
        }
        if polygons.is_empty() {
            return Err("holds no polygon".into());
        }
        Ok(Areas {
            polygons,
            epsg: named_epsg(v)?,
        })
    }
}

/// A Polygon's rings from its `coordinates`.
fn polygon(coords: Option<&serde_json::Value>, what: &str) -> std::result::Result<Polygon, String> {
    let rings = coords
        .and_then(|c| c.as_array())
        .filter(|r| !r.is_empty())
        .ok_or(format!("{what}: a Polygon without rings"))?;
    let mut out = Vec::with_capacity(rings.len());
    for (r, ring) in rings.iter().enumerate() {
        let pts = ring
            .as_array()
            .ok_or(format!("{what}: ring {r} is not a list of positions"))?;
        let ring: Vec<[f64; 2]> = pts
            .iter()
            .map(|p| {
                let xy = p.as_array().filter(|a| a.len() >= 2).and_then(|a| {
                    Some([a[0].as_f64()?, a[1].as_f64()?])
                        .filter(|q| q.iter().all(|v| v.is_finite()))
                });
                xy.ok_or(format!(
                    "{what}: ring {r} holds a position that is not two numbers"
                ))
            })
            .collect::<std::result::Result<_, String>>()?;
        // A closed ring repeats its first position (RFC 7946 §3.1.6): at least 4 positions.
        if ring.len() < 4 {
            return Err(format!(
                "{what}: ring {r} has {} positions, a closed ring needs at least 4",
                ring.len()
            ));
        }
        out.push(ring);
    }
    Ok(Polygon::new(out))
}

/// The EPSG code of a GeoJSON 2008 named `crs` member (`EPSG:n`, `urn:ogc:def:crs:EPSG::n`,
/// `urn:ogc:def:crs:EPSG:v:n`); OGC CRS84 is EPSG:4326's axes swapped, named as 4326.
fn named_epsg(v: &serde_json::Value) -> std::result::Result<Option<u32>, String> {
    let Some(crs) = v.get("crs").filter(|c| !c.is_null()) else {
        return Ok(None);
    };
    let name = crs
        .get("properties")
        .and_then(|p| p.get("name"))
        .and_then(|n| n.as_str())
        .ok_or("its \"crs\" member names no CRS (properties.name)")?;
    if name.ends_with("CRS84") {
        return Ok(Some(4326));
    }
    let code = name
        .rsplit(':')
        .next()
        .filter(|_| name.to_ascii_uppercase().contains("EPSG"))
        .and_then(|c| c.parse::<u32>().ok());
    code.map(Some).ok_or(format!(
        "its \"crs\" member names '{name}', not an EPSG code"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn square(x0: f64, y0: f64, s: f64) -> serde_json::Value {
        json!([
            [x0, y0],
            [x0 + s, y0],
            [x0 + s, y0 + s],
            [x0, y0 + s],
            [x0, y0]
        ])
    }

    #[test]
    fn polygons_with_holes_and_multipolygons() {
        let v = json!({"type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::32755"}},
        "features": [
            {"type": "Feature", "properties": {}, "geometry":
                {"type": "Polygon", "coordinates": [square(0.0, 0.0, 10.0), square(4.0, 4.0, 2.0)]}},
            {"type": "Feature", "properties": {}, "geometry":
                {"type": "MultiPolygon", "coordinates": [[square(20.0, 0.0, 1.0)], [square(30.0, 0.0, 1.0)]]}}
        ]});
        let a = Areas::parse(&v).unwrap();
        assert_eq!(a.polygons.len(), 3);
        assert_eq!(a.epsg, Some(32755));
        assert!(a.contains(1.0, 1.0));
        assert!(!a.contains(5.0, 5.0), "in the hole");
        assert!(a.contains(20.5, 0.5) && a.contains(30.5, 0.5));
        assert!(!a.contains(25.0, 0.5) && !a.contains(-1.0, 1.0) && !a.contains(1.0, 11.0));
        // A concave polygon (an L): the notch is outside.
        let l = json!({"type": "Polygon", "coordinates": [[[0,0],[4,0],[4,1],[1,1],[1,4],[0,4],[0,0]]]});
        let l = Areas::parse(&l).unwrap();
        assert!(l.contains(0.5, 3.0) && l.contains(3.0, 0.5) && !l.contains(3.0, 3.0));
        assert_eq!(l.epsg, None);
    }

    #[test]
    fn box_share_bounds_the_share_inside() {
        let v = json!({"type": "MultiPolygon", "coordinates": [[square(0.0, 0.0, 10.0)], [square(95.0, 95.0, 10.0)]]});
        let a = Areas::parse(&v).unwrap();
        // 100 + 25 (the second box clipped to the rectangle) of 10,000.
        assert!((a.box_share([0.0, 0.0, 100.0, 100.0]) - 0.0125).abs() < 1e-12);
        assert_eq!(a.box_share([0.0, 0.0, 5.0, 5.0]), 1.0);
        assert_eq!(a.box_share([200.0, 200.0, 300.0, 300.0]), 0.0);
    }

    #[test]
    fn what_is_not_stable_ground_is_refused_in_words() {
        let line = json!({"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [square(0.0, 0.0, 1.0)]}},
            {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 1]]}}]});
        let e = Areas::parse(&line).unwrap_err();
        assert!(e.contains("feature 1 is a LineString"), "{e}");
        let open = json!({"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [0, 1]]]});
        assert!(Areas::parse(&open).unwrap_err().contains("at least 4"));
        let empty = json!({"type": "FeatureCollection", "features": []});
        assert!(Areas::parse(&empty).unwrap_err().contains("no polygon"));
        let crs = json!({"type": "Polygon", "coordinates": [square(0.0, 0.0, 1.0)],
            "crs": {"type": "name", "properties": {"name": "local grid"}}});
        assert!(Areas::parse(&crs).unwrap_err().contains("not an EPSG code"));
        assert!(Areas::parse(&json!({"a": 1}))
            .unwrap_err()
            .contains("no \"type\""));
    }
}
