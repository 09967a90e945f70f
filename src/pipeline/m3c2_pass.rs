//! Pass 2: normals and M3C2 for the core points each tile owns.
//!
//! Tiles are processed one at a time (all cores work inside a tile, through rayon), while a reader
//! thread decodes the next tile: a crossbeam channel of capacity one bounds what is in memory to
//! the tile being computed plus the one being read. Each tile's results are written as immutable
//! chunk files sorted by core-point key, then recorded in the manifest.

use std::path::{Path, PathBuf};

use crossbeam_channel::bounded;
use talus_tiling::{Column, ColumnData, TileColumns, TileId};

use crate::error::{Error, Result};
use crate::io::Point3;
use crate::m3c2::{self, core_points, CoreResult};
use crate::params::Params;
use crate::pipeline::tiles::{self, tiling_error, Layout, TilePoints, Tiled};
use crate::pipeline::workdir::WorkDir;
use crate::spatial::Index;

/// Rows per result chunk file: the final merge holds one chunk per tile.
pub const CHUNK_ROWS: usize = 8192;

/// The per-tile results of pass 2.
pub struct M3c2Results {
    pub dir: PathBuf,
    /// (tile, number of chunk files) in grid order.
    pub chunks: Vec<(TileId, usize)>,
    pub hash: String,
    pub reused: bool,
}

/// One core point's result with its global sort key.
#[derive(Debug, Clone, Copy)]
pub struct KeyedResult {
    pub key: u64,
    pub xyz: Point3,
    pub r: CoreResult,
}

/// User core points, in memory with their input order as key (see module `tiles`: a core-point
/// file is far smaller than the epochs; 10M core points take ≈ 320 MB).
pub struct UserCores {
    pub by_tile: Vec<Vec<(u64, Point3)>>,
}

impl UserCores {
    pub fn load(path: &Path, layout: &Layout) -> Result<UserCores> {
        let (_, pts) = crate::io::read_all(path)?;
        let mut by_tile = vec![Vec::new(); layout.grid.len()];
        for (i, p) in pts.into_iter().enumerate() {
            let id = layout.grid.owner(p[0], p[1]);
            by_tile[layout.grid.index(id)].push((i as u64, p));
        }
        Ok(UserCores { by_tile })
    }
}

struct Work {
    id: TileId,
    before: TilePoints,
    after: TilePoints,
}

/// Run pass 2 over every tile not already done.
pub fn run(
    wd: &mut WorkDir,
    layout: &Layout,
    tiled: &Tiled,
    params: &Params,
    user_cores: Option<&UserCores>,
) -> Result<M3c2Results> {
    let dir = wd.sub("m3c2")?;
    let m = params.m3c2();
    let hash = format!(
        "{:016x}",
        talus_tiling::hash64(
            format!(
                "{}|{}|{:?}|{}",
                tiled.hash,
                layout.key(),
                m,
                params.core_spacing.value
            )
            .as_bytes()
        )
    );
    let mut chunks = Vec::new();
    let mut todo = Vec::new();
    for id in layout.grid.tiles() {
        let unit = format!("m3c2:{}", id.name());
        match wd.manifest.units.get(&unit) {
            Some(e) if e.inputs_hash == hash => {
                let n: usize = e.file.parse().unwrap_or(usize::MAX);
                if n != usize::MAX && (0..n).all(|k| chunk_path(&dir, id, k).exists()) {
                    chunks.push((id, n));
                    continue;
                }
                todo.push(id);
            }
            _ => todo.push(id),
        }
        chunks.push((id, 0));
    }
    let reused = todo.is_empty();
    let (tx, rx) = bounded::<Result<Work>>(1);
    let before_dir = tiled.before.clone();
    let after_dir = tiled.after.clone();
    let todo_ids = todo.clone();
    std::thread::scope(|s| -> Result<()> {
        s.spawn(move || {
            for id in todo_ids {
                let w = tiles::read_tile(&before_dir, id).and_then(|before| {
                    Ok(Work {
                        id,
                        before,
                        after: tiles::read_tile(&after_dir, id)?,
                    })
                });
                let failed = w.is_err();
                if tx.send(w).is_err() || failed {
                    return;
                }
            }
        });
        for w in rx.iter() {
            let w = w?;
            let cores = user_cores.map(|u| u.by_tile[layout.grid.index(w.id)].as_slice());
            let results = compute_tile(&w, layout, params, cores);
            let n = write_chunks(&dir, w.id, &results)?;
            wd.done(&format!("m3c2:{}", w.id.name()), &n.to_string(), &hash)?;
            if let Some(c) = chunks.iter_mut().find(|c| c.0 == w.id) {
                c.1 = n;
            }
        }
        Ok(())
    })?;
    Ok(M3c2Results {
        dir,
        chunks,
        hash,
        reused,
    })
}

/// Normals and M3C2 for the core points tile `w` owns, sorted by key.
fn compute_tile(
    w: &Work,
    layout: &Layout,
    params: &Params,
    user_cores: Option<&[(u64, Point3)]>,
) -> Vec<KeyedResult> {
    let sq = layout.grid.square(w.id);
    let origin = [
        0.5 * (sq.min[0] + sq.max[0]),
        0.5 * (sq.min[1] + sq.max[1]),
        layout.anchor[2],
    ];
    let before = Index::new(&w.before.points, origin);
    let after = Index::new(&w.after.points, origin);
    let keyed: Vec<(u64, Point3)> = match user_cores {
        Some(c) => c.to_vec(),
        None => core_points::thin(&w.before.points, &layout.anchor, layout.core_spacing, |i| {
            w.before.owned[i]
        })
        .into_iter()
        .map(|(k, i)| (k, w.before.points[i]))
        .collect(),
    };
    if keyed.is_empty() {
        return Vec::new();
    }
    let local: Vec<Point3> = keyed.iter().map(|(_, p)| before.to_local(p)).collect();
    let m = params.m3c2();
    let normals = m3c2::normals(&before, &local, &m);
    let results = m3c2::distances(&before, &after, &local, &normals, &m);
    let mut out: Vec<KeyedResult> = keyed
        .iter()
        .zip(results)
        .map(|(&(key, xyz), r)| KeyedResult { key, xyz, r })
        .collect();
    out.sort_by_key(|k| k.key);
    out
}

/// The file of chunk `k` of tile `id`.
pub fn chunk_path(dir: &Path, id: TileId, k: usize) -> PathBuf {
    dir.join(format!("{}.{k:05}.tile", id.name()))
}

fn write_chunks(dir: &Path, id: TileId, results: &[KeyedResult]) -> Result<usize> {
    let mut n = 0;
    for (k, part) in results.chunks(CHUNK_ROWS).enumerate() {
        talus_tiling::write_tile(&chunk_path(dir, id, k), &to_columns(part))
            .map_err(tiling_error)?;
        n = k + 1;
    }
    Ok(n)
}

fn f64col(name: &str, v: Vec<f64>) -> Column {
    Column {
        name: name.into(),
        data: ColumnData::F64(v),
    }
}
fn u32col(name: &str, v: Vec<u32>) -> Column {
    Column {
        name: name.into(),
        data: ColumnData::U32(v),
    }
}

fn to_columns(rs: &[KeyedResult]) -> TileColumns {
    let col = |f: &dyn Fn(&KeyedResult) -> f64| rs.iter().map(f).collect::<Vec<f64>>();
    TileColumns {
        x: col(&|r| r.xyz[0]),
        y: col(&|r| r.xyz[1]),
        z: col(&|r| r.xyz[2]),
        extra: vec![
            u32col("key_hi", rs.iter().map(|r| (r.key >> 32) as u32).collect()),
            u32col("key_lo", rs.iter().map(|r| r.key as u32).collect()),
            f64col("distance", col(&|r| r.r.distance)),
            f64col("uncertainty", col(&|r| r.r.uncertainty)),
            Column {
                name: "significant".into(),
                data: ColumnData::U8(rs.iter().map(|r| r.r.significant as u8).collect()),
            },
            f64col("std_dev1", col(&|r| r.r.std_dev1)),
            f64col("std_dev2", col(&|r| r.r.std_dev2)),
            u32col("count1", rs.iter().map(|r| r.r.count1).collect()),
            u32col("count2", rs.iter().map(|r| r.r.count2).collect()),
            f64col("normal_x", col(&|r| r.r.normal[0])),
            f64col("normal_y", col(&|r| r.r.normal[1])),
            f64col("normal_z", col(&|r| r.r.normal[2])),
        ],
    }
}

/// Read one result chunk back.
pub fn read_chunk(path: &Path) -> Result<Vec<KeyedResult>> {
    let c = talus_tiling::read_tile(path).map_err(tiling_error)?;
    let f = |name: &str| -> Result<&Vec<f64>> {
        match c.column(name) {
            Some(ColumnData::F64(v)) => Ok(v),
            _ => Err(Error::Internal(format!(
                "{}: no column {name}",
                path.display()
            ))),
        }
    };
    let u = |name: &str| -> Result<&Vec<u32>> {
        match c.column(name) {
            Some(ColumnData::U32(v)) => Ok(v),
            _ => Err(Error::Internal(format!(
                "{}: no column {name}",
                path.display()
            ))),
        }
    };
    let sig = match c.column("significant") {
        Some(ColumnData::U8(v)) => v,
        _ => {
            return Err(Error::Internal(format!(
                "{}: no column significant",
                path.display()
            )))
        }
    };
    let (hi, lo) = (u("key_hi")?, u("key_lo")?);
    let (d, unc, s1, s2) = (
        f("distance")?,
        f("uncertainty")?,
        f("std_dev1")?,
        f("std_dev2")?,
    );
    let (n1, n2) = (u("count1")?, u("count2")?);
    let (nx, ny, nz) = (f("normal_x")?, f("normal_y")?, f("normal_z")?);
    Ok((0..c.len())
        .map(|i| KeyedResult {
            key: (hi[i] as u64) << 32 | lo[i] as u64,
            xyz: [c.x[i], c.y[i], c.z[i]],
            r: CoreResult {
                distance: d[i],
                uncertainty: unc[i],
                significant: sig[i] == 1,
                std_dev1: s1[i],
                std_dev2: s2[i],
                count1: n1[i],
                count2: n2[i],
                normal: [nx[i], ny[i], nz[i]],
            },
        })
        .collect())
}
