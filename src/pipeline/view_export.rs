//! The compact files the web viewer reads (`view.json`, `terrain.bin`): the core points thinned
//! to at most [`MAX_TERRAIN_POINTS`] whatever the input size, as float32 offsets from a local
//! origin (UTM-sized values would jitter in float32), with their M3C2 distance.

use serde::Serialize;

use crate::error::{Error, Result};
use crate::io::{Crs, Point3};
use crate::pipeline::m3c2_pass::M3c2Results;
use crate::pipeline::outputs::{write_atomic, MergedResults};
use crate::pipeline::workdir::WorkDir;

/// Upper bound on the terrain points the viewer gets.
pub const MAX_TERRAIN_POINTS: u64 = 2_000_000;

/// Mesh files of one event, relative to DIR.
#[derive(Debug, Clone, Serialize)]
pub struct EventMeshes {
    pub before: String,
    pub after: String,
}

#[derive(Serialize)]
struct ViewJson<'a> {
    version: u32,
    crs: String,
    units: &'a str,
    origin: Point3,
    points: usize,
    distance_range: [f64; 2],
    terrain: &'a str,
    meshes: std::collections::BTreeMap<String, EventMeshes>,
}

/// Write DIR/terrain.bin and DIR/view.json. `total` is the number of core points (to choose the
/// stride); `origin` the local origin of the rendering.
pub fn write(
    wd: &WorkDir,
    results: &M3c2Results,
    total: u64,
    crs: &Crs,
    origin: Point3,
    meshes: &[(u32, EventMeshes)],
) -> Result<()> {
    let stride = total.div_ceil(MAX_TERRAIN_POINTS).max(1);
    let mut merged = MergedResults::new(results)?;
    let mut pos: Vec<f32> = Vec::new();
    let mut dist: Vec<f32> = Vec::new();
    let mut i = 0u64;
    while let Some(k) = merged.next_result()? {
        if i.is_multiple_of(stride) {
            pos.extend(k.xyz.iter().zip(&origin).map(|(x, o)| (x - o) as f32));
            dist.push(k.r.distance as f32);
        }
        i += 1;
    }
    let mut finite: Vec<f32> = dist.iter().copied().filter(|d| d.is_finite()).collect();
    let range = if finite.is_empty() {
        [0.0, 0.0]
    } else {
        finite.sort_by(|a, b| a.total_cmp(b));
        let q = |f: f64| finite[((finite.len() - 1) as f64 * f).round() as usize] as f64;
        [q(0.02), q(0.98)]
    };
    let mut bytes = Vec::with_capacity((pos.len() + dist.len()) * 4);
    for v in pos.iter().chain(dist.iter()) {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    write_atomic(&wd.out.join("terrain.bin"), &bytes)?;
    let view = ViewJson {
        version: 1,
        crs: crs.describe(),
        units: "m",
        origin,
        points: dist.len(),
        distance_range: range,
        terrain: "terrain.bin",
        meshes: meshes
            .iter()
            .map(|(id, m)| (id.to_string(), m.clone()))
            .collect(),
    };
    let text = serde_json::to_string_pretty(&view).map_err(|e| Error::Internal(e.to_string()))?;
    write_atomic(&wd.out.join("view.json"), text.as_bytes())
}
