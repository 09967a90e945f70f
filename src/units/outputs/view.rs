//! The compact files the web viewer reads (`view.json`, `terrain.bin`): the core points thinned
//! to at most [`MAX_TERRAIN_POINTS`] whatever the input size, as float32 offsets from a local
//! origin (UTM-sized values would jitter in float32), with their M3C2 distance.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::io::{Crs, Point3};
use crate::m3c2::tile::KeyedResult;
use crate::store::UnitWriter;
use crate::units::{write_bytes, write_streamed};

/// Upper bound on the terrain points the viewer gets.
pub(crate) const MAX_TERRAIN_POINTS: u64 = 2_000_000;

/// Mesh files of one event, relative to DIR.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct EventMeshes {
    pub(crate) before: String,
    pub(crate) after: String,
}

#[derive(Serialize)]
struct ViewJson<'a> {
    version: u32,
    crs: String,
    units: &'a str,
    origin: Point3,
    points: usize,
    distance_range: [f64; 2],
    facing: Point3,
    terrain: &'a str,
    /// Where the terrain's positions are when terrain.bin holds its distances alone (a lean
    /// campaign's pair: `points::shared_positions`).
    #[serde(skip_serializing_if = "Option::is_none")]
    positions: Option<&'a str>,
    meshes: std::collections::BTreeMap<String, EventMeshes>,
}

/// What a campaign reads of a pair's view.json (written as `ViewJson`): the pair's colour range,
/// from which the campaign's one scale for every pair is drawn.
#[derive(Debug, Clone, Deserialize)]
pub(crate) struct ViewRange {
    pub(crate) distance_range: [f64; 2],
}

/// The terrain the viewer gets: every `stride`-th core point of the canonical order, collected
/// while m3c2.laz is written (one pass over the results for both).
pub(crate) struct TerrainSample {
    stride: u64,
    /// Where the positions are when not collected here ([`Terrain::positions`]): a lean
    /// campaign's pair after the first, whose series unit holds these very distances when the
    /// sample is every core point ([`Terrain::series`]).
    positions: Option<String>,
    origin: Point3,
    seen: u64,
    pos: Vec<f32>,
    dist: Vec<f32>,
    /// The sum of the sample's oriented normals (of known sign).
    normals: Point3,
    /// A piece of the sample (`from_rank`): its oriented normals themselves, which the joined
    /// sample sums in order as one pass would (a sum of the pieces' sums would round otherwise).
    each_normal: Option<Vec<Point3>>,
}

/// A sample's piece, as a segment unit writes it (`terrain.part`: three u64 counts, then the
/// positions and distances as f32 and the normals as f64, little-endian).
pub(crate) const PIECE: &str = "terrain.part";

impl TerrainSample {
    /// A sample of at most [`MAX_TERRAIN_POINTS`] of `total` core points, relative to `origin`.
    /// Its columns are allocated whole, at the size the stride gives: grown by doubling they
    /// would hold up to twice that, and three times while a doubling copies.
    pub(crate) fn new(total: u64, origin: Point3, positions: Option<String>) -> Self {
        let stride = total.div_ceil(MAX_TERRAIN_POINTS).max(1);
        let n = total.div_ceil(stride) as usize;
        let own = if positions.is_none() { 3 * n } else { 0 };
        TerrainSample {
            stride,
            positions,
            origin,
            seen: 0,
            pos: Vec::with_capacity(own),
            dist: Vec::with_capacity(n),
            normals: [0.0; 3],
            each_normal: None,
        }
    }

    /// The piece of the sample [`TerrainSample::new`] takes from the core points of canonical
    /// ranks `from..to` (pushed in that order): the same points, for [`TerrainSample::joined`].
    pub(crate) fn piece(total: u64, origin: Point3, from: u64, to: u64) -> Self {
        let stride = total.div_ceil(MAX_TERRAIN_POINTS).max(1);
        let n = (to.div_ceil(stride) - from.div_ceil(stride).min(to.div_ceil(stride))) as usize;
        TerrainSample {
            stride,
            positions: None,
            origin,
            seen: from,
            pos: Vec::with_capacity(3 * n),
            dist: Vec::with_capacity(n),
            normals: [0.0; 3],
            each_normal: Some(Vec::with_capacity(n)),
        }
    }

    /// Write this piece as [`PIECE`].
    pub(crate) fn write_piece(self, out: &mut UnitWriter) -> Result<()> {
        let normals = self.each_normal.unwrap_or_default();
        write_streamed(out, PIECE, |w| {
            for n in [self.pos.len(), self.dist.len(), normals.len()] {
                w.write_all(&(n as u64).to_le_bytes())?;
            }
            let mut bytes = Vec::with_capacity(1 << 16);
            for run in self.pos.chunks(1 << 14).chain(self.dist.chunks(1 << 14)) {
                bytes.clear();
                bytes.extend(run.iter().flat_map(|v| v.to_le_bytes()));
                w.write_all(&bytes)?;
            }
            for run in normals.chunks(1 << 12) {
                bytes.clear();
                bytes.extend(run.iter().flatten().flat_map(|v| v.to_le_bytes()));
                w.write_all(&bytes)?;
            }
            Ok(())
        })
    }

    /// The sample of `total` core points about `origin` from its pieces' files, in order: the
    /// sample one pass over every core point takes, bit for bit.
    pub(crate) fn joined(
        total: u64,
        origin: Point3,
        pieces: &[std::path::PathBuf],
    ) -> Result<Self> {
        let mut s = TerrainSample::new(total, origin, None);
        for path in pieces {
            let bytes = std::fs::read(path).map_err(|e| Error::Damaged {
                path: path.clone(),
                problem: e.to_string(),
            })?;
            let bad = || Error::Damaged {
                path: path.clone(),
                problem: "a terrain piece of another length than its counts say".into(),
            };
            let count = |k: usize| -> Result<usize> {
                let b = bytes.get(8 * k..8 * k + 8).ok_or_else(bad)?;
                usize::try_from(u64::from_le_bytes(b.try_into().map_err(|_| bad())?))
                    .map_err(|_| bad())
            };
            let (np, nd, nn) = (count(0)?, count(1)?, count(2)?);
            if np != 3 * nd {
                return Err(bad());
            }
            let body = &bytes[24..];
            if body.len() != 4 * (np + nd) + 24 * nn {
                return Err(bad());
            }
            let f32s = |b: &[u8]| -> Vec<f32> {
                b.chunks_exact(4)
                    .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .collect()
            };
            s.pos.extend(f32s(&body[..4 * np]));
            s.dist.extend(f32s(&body[4 * np..4 * (np + nd)]));
            for n in body[4 * (np + nd)..].chunks_exact(24) {
                for (i, v) in n.chunks_exact(8).enumerate() {
                    s.normals[i] += f64::from_le_bytes(v.try_into().map_err(|_| bad())?);
                }
            }
        }
        s.seen = total;
        Ok(s)
    }

    /// The next core point in canonical order.
    pub(crate) fn push(&mut self, k: &KeyedResult) {
        if self.seen.is_multiple_of(self.stride) {
            let o = self.origin;
            if self.positions.is_none() {
                self.pos
                    .extend(k.xyz.iter().zip(&o).map(|(x, o)| (x - o) as f32));
            }
            self.dist.push(k.r.measured() as f32);
            let n = k.r.normal;
            if k.r.sign_known && n.iter().all(|v| v.is_finite()) {
                match self.each_normal.as_mut() {
                    Some(each) => each.push(n),
                    None => (0..3).for_each(|i| self.normals[i] += n[i]),
                }
            }
        }
        self.seen += 1;
    }

    /// Write terrain.bin (unless the series unit holds it: [`Terrain::series`]); what view.json
    /// says of it.
    pub(crate) fn write(self, out: &mut UnitWriter) -> Result<Terrain> {
        let TerrainSample {
            stride,
            origin,
            positions,
            pos,
            mut dist,
            normals,
            ..
        } = self;
        let series = positions.is_some() && stride == 1;
        if !series {
            // Streamed, a run of values at a time (a byte copy would be as large as the terrain).
            write_streamed(out, "terrain.bin", |w| {
                let mut bytes = Vec::with_capacity(1 << 16);
                for run in pos.chunks(1 << 14).chain(dist.chunks(1 << 14)) {
                    bytes.clear();
                    bytes.extend(run.iter().flat_map(|v| v.to_le_bytes()));
                    w.write_all(&bytes)?;
                }
                Ok(())
            })?;
        }
        let points = dist.len();
        drop(pos);
        // The colour range from the distances themselves (written already): no copy of them.
        dist.retain(|d| d.is_finite());
        let distance_range = if dist.is_empty() {
            [0.0, 0.0]
        } else {
            let mut q = |f: f64| {
                let k = ((dist.len() - 1) as f64 * f).round() as usize;
                *dist.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1 as f64
            };
            [q(0.02), q(0.98)]
        };
        let len = normals.iter().map(|v| v * v).sum::<f64>().sqrt();
        let facing = if len > 0.0 {
            normals.map(|v| v / len)
        } else {
            [0.0, 0.0, 1.0]
        };
        Ok(Terrain {
            origin,
            points,
            distance_range,
            facing,
            positions,
            series,
        })
    }
}

/// What view.json says of terrain.bin.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct Terrain {
    /// The local origin the float32 offsets are from.
    pub(crate) origin: Point3,
    pub(crate) points: usize,
    /// The 2nd and 98th percentiles of the sample's distances (the viewer's colour range).
    pub(crate) distance_range: [f64; 2],
    /// The direction the surface faces: the mean of its oriented normals (of known sign),
    /// normalised; up where there is none. The viewer looks at a steep face along it.
    #[serde(default = "up")]
    pub(crate) facing: Point3,
    /// Where the positions are when terrain.bin holds the distances alone (relative to the
    /// pair's folder); None: terrain.bin holds both.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) positions: Option<String>,
    /// terrain.bin is the pair's series column (every core point's distance as f32 in key
    /// order: the same bytes), published from the series unit rather than written twice.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub(crate) series: bool,
}

fn up() -> Point3 {
    [0.0, 0.0, 1.0]
}

/// Write view.json: the terrain sample `terrain` (published beside it as terrain.bin) and the
/// events' meshes.
pub(crate) fn write_view(
    out: &mut UnitWriter,
    crs: &Crs,
    terrain: &Terrain,
    meshes: &[(u32, EventMeshes)],
) -> Result<()> {
    let view = ViewJson {
        // 2: terrain.bin holds the distances alone, the positions are where `positions` says.
        version: if terrain.positions.is_some() { 2 } else { 1 },
        crs: crs.describe(),
        units: "m",
        origin: terrain.origin,
        points: terrain.points,
        distance_range: terrain.distance_range,
        facing: terrain.facing,
        terrain: "terrain.bin",
        positions: terrain.positions.as_deref(),
        meshes: meshes
            .iter()
            .map(|(id, m)| (id.to_string(), m.clone()))
            .collect(),
    };
    let text = serde_json::to_string_pretty(&view).map_err(|e| Error::Internal(e.to_string()))?;
    write_bytes(out, "view.json", text.as_bytes())
}
