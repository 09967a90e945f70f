//! A DEM of difference (DoD), the standard reference for 2.5-D volumes, written for the tests
//! independently of talus's volume code: each epoch's points triangulated in global x, y (spade's
//! Delaunay, heights z), both TINs sampled at the centres of a fine square grid, and a cell
//! counted only where both epochs cover it (inside both triangulations and a point of each within
//! two point spacings of the centre: no interpolation across holes). The volume of a polygon is
//! Σ (z₂ − z₁) × cell area over the covered cells whose centre lies inside it (even–odd rule, so
//! holes are out).
#![allow(dead_code)]

use std::collections::HashMap;

use spade::{DelaunayTriangulation, FloatTriangulation, HasPosition, Point2, Triangulation};

/// One epoch: its TIN and a bucket grid of its points for the coverage test.
pub struct Epoch {
    tin: DelaunayTriangulation<Vertex>,
    buckets: HashMap<(i64, i64), Vec<[f64; 2]>>,
    bucket: f64,
    origin: [f64; 2],
}

#[derive(Clone, Copy)]
struct Vertex {
    p: Point2<f64>,
    z: f64,
}

impl HasPosition for Vertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.p
    }
}

impl Epoch {
    /// Triangulate `points` (global); coordinates are taken relative to `origin` for precision.
    pub fn new(points: &[[f64; 3]], origin: [f64; 2], reach: f64) -> Epoch {
        let verts: Vec<Vertex> = points
            .iter()
            .map(|p| Vertex {
                p: Point2::new(p[0] - origin[0], p[1] - origin[1]),
                z: p[2],
            })
            .collect();
        let tin = DelaunayTriangulation::bulk_load(verts).expect("triangulation");
        let mut buckets: HashMap<(i64, i64), Vec<[f64; 2]>> = HashMap::new();
        for p in points {
            let q = [p[0] - origin[0], p[1] - origin[1]];
            buckets
                .entry(((q[0] / reach).floor() as i64, (q[1] / reach).floor() as i64))
                .or_default()
                .push(q);
        }
        Epoch {
            tin,
            buckets,
            bucket: reach,
            origin,
        }
    }

    /// The TIN's height at global (x, y) if a point lies within the reach given to `new`.
    pub fn height(&self, x: f64, y: f64) -> Option<f64> {
        let q = [x - self.origin[0], y - self.origin[1]];
        let (bx, by) = (
            (q[0] / self.bucket).floor() as i64,
            (q[1] / self.bucket).floor() as i64,
        );
        let r2 = self.bucket * self.bucket;
        let near = (bx - 1..=bx + 1).any(|i| {
            (by - 1..=by + 1).any(|j| {
                self.buckets.get(&(i, j)).is_some_and(|v| {
                    v.iter()
                        .any(|p| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) <= r2)
                })
            })
        });
        if !near {
            return None;
        }
        self.tin
            .barycentric()
            .interpolate(|v| v.data().z, Point2::new(q[0], q[1]))
    }
}

/// A polygon with holes: rings of (x, y).
pub type Polygon = Vec<Vec<[f64; 2]>>;

/// Whether `p` lies inside `poly` (even–odd rule over its rings).
pub fn contains(poly: &Polygon, p: [f64; 2]) -> bool {
    let mut n = 0;
    for ring in poly {
        for k in 0..ring.len() {
            let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
            if (a[1] > p[1]) != (b[1] > p[1]) {
                let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                if p[0] < x {
                    n += 1;
                }
            }
        }
    }
    n % 2 == 1
}

/// The covered cells of a grid of side `cell` (aligned to multiples of it) inside `polys`, with
/// their height differences: (cell key, z₂ − z₁).
pub fn cells(
    before: &Epoch,
    after: &Epoch,
    polys: &[Polygon],
    cell: f64,
) -> Vec<((i64, i64), f64)> {
    let mut out = Vec::new();
    for poly in polys {
        let (mut x0, mut y0, mut x1, mut y1) = (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        );
        for p in poly.iter().flatten() {
            x0 = x0.min(p[0]);
            y0 = y0.min(p[1]);
            x1 = x1.max(p[0]);
            y1 = y1.max(p[1]);
        }
        let (i0, i1) = ((x0 / cell).floor() as i64, (x1 / cell).ceil() as i64);
        let (j0, j1) = ((y0 / cell).floor() as i64, (y1 / cell).ceil() as i64);
        for j in j0..j1 {
            for i in i0..i1 {
                let c = [(i as f64 + 0.5) * cell, (j as f64 + 0.5) * cell];
                if !contains(poly, c) {
                    continue;
                }
                if let (Some(z1), Some(z2)) = (before.height(c[0], c[1]), after.height(c[0], c[1]))
                {
                    out.push(((i, j), z2 - z1));
                }
            }
        }
    }
    out
}

/// The regions of event_regions.geojson: id → polygons projected on x, y.
pub fn regions(geojson: &serde_json::Value) -> Vec<(u64, Vec<Polygon>)> {
    let ring = |r: &serde_json::Value| -> Vec<[f64; 2]> {
        let mut v: Vec<[f64; 2]> = r
            .as_array()
            .expect("ring")
            .iter()
            .map(|p| [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()])
            .collect();
        v.pop(); // closed rings repeat their first vertex
        v
    };
    let polygon = |p: &serde_json::Value| -> Polygon {
        p.as_array().expect("polygon").iter().map(ring).collect()
    };
    geojson["features"]
        .as_array()
        .expect("features")
        .iter()
        .filter_map(|f| {
            let id = f["properties"]["id"].as_u64()?;
            let g = &f["geometry"];
            let polys = match g["type"].as_str()? {
                "Polygon" => vec![polygon(&g["coordinates"])],
                "MultiPolygon" => g["coordinates"].as_array()?.iter().map(polygon).collect(),
                _ => return None,
            };
            Some((id, polys))
        })
        .collect()
}
