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
use crate::pipeline::progress::Stage;
use crate::pipeline::tiles::{self, tiling_error, Epoch, Layout, TilePoints, Tiled};
use crate::pipeline::workdir::WorkDir;
use crate::spatial::Columns;

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

impl M3c2Results {
    /// How many core points the results hold, from the chunk headers alone.
    pub fn count(&self) -> Result<u64> {
        let mut n = 0;
        for &(id, chunks) in &self.chunks {
            for k in 0..chunks {
                n += talus_tiling::read_tile_header(&chunk_path(&self.dir, id, k))
                    .map_err(tiling_error)?
                    .point_count;
            }
        }
        Ok(n)
    }
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

/// Why the reader thread stopped early.
enum ReadFailure {
    /// A tile file of this epoch is damaged: redo its split.
    Corrupt(Epoch, talus_tiling::Error),
    Other(Error),
}

/// How one sweep over the tiles to do ended.
enum Sweep {
    Finished,
    /// The split of this epoch is damaged; the tiles before it in the list are done.
    Resplit(Epoch, talus_tiling::Error),
}

/// The hash a tile's M3C2 unit is made from: the tile sets, the layout and the parameters of
/// pass 2 only (so a changed threshold, eps or smoothing reuses every unit).
fn units_hash(layout: &Layout, tiled: &Tiled, params: &Params) -> String {
    let m = params.m3c2();
    format!(
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
    )
}

fn unit_name(id: TileId) -> String {
    format!("m3c2:{}", id.name())
}

/// The number of chunk files recorded for a finished unit whose files all still carry their
/// recorded checksum; None when the unit must be (re)done.
fn reusable(wd: &WorkDir, dir: &Path, id: TileId, hash: &str) -> Option<usize> {
    let e = wd.intact(&unit_name(id), hash, |e| {
        chunks_checksum(dir, id, e.file.parse().ok()?).ok()
    })?;
    e.file.parse().ok()
}

/// FNV-1a over the CRC-32 of every chunk file of a tile.
fn chunks_checksum(dir: &Path, id: TileId, n: usize) -> talus_tiling::Result<String> {
    let mut h = talus_tiling::Fnv64::new();
    h.write_u64(n as u64);
    for k in 0..n {
        h.write_str(&talus_tiling::file_checksum(&chunk_path(dir, id, k))?);
    }
    Ok(format!("fnv-crc32:{}", h.hex()))
}

/// Run pass 2 over every tile not already done. A tile file found damaged (checksum) makes the
/// split of its epoch be redone, then the pass goes on; a damaged result chunk makes its tile be
/// redone.
pub fn run(
    wd: &mut WorkDir,
    layout: &Layout,
    tiled: &Tiled,
    params: &Params,
    user_cores: Option<&UserCores>,
    stage: &Stage,
) -> Result<M3c2Results> {
    let dir = wd.sub("m3c2")?;
    let hash = units_hash(layout, tiled, params);
    let mut chunks = Vec::new();
    let mut todo = Vec::new();
    for id in layout.grid.tiles() {
        match reusable(wd, &dir, id, &hash) {
            Some(n) => chunks.push((id, n)),
            None => {
                todo.push(id);
                chunks.push((id, 0));
            }
        }
    }
    let reused = todo.is_empty();
    // Resplit each epoch at most once per run: damage that survives a fresh split is not
    // something a redo can fix.
    let mut resplit = [false; 2];
    let mut next = 0;
    while next < todo.len() {
        match sweep(
            wd,
            &dir,
            layout,
            tiled,
            params,
            user_cores,
            &hash,
            &todo[next..],
            &mut chunks,
            &mut next,
            stage,
        )? {
            Sweep::Finished => break,
            Sweep::Resplit(epoch, err) => {
                let k = epoch as usize;
                if resplit[k] {
                    return Err(tiling_error(err));
                }
                resplit[k] = true;
                eprintln!(
                    "talus: {err}; cutting the {} epoch into tiles again",
                    epoch.name()
                );
                let src = match epoch {
                    Epoch::Before => &tiled.before_src,
                    Epoch::After => &tiled.after_src,
                };
                let hash = tiles::split_hash(layout, src)?;
                let redo =
                    Stage::log_only(&format!("pass 1 again: tiling {}", epoch.name()), "points");
                tiles::split(wd, layout, epoch, src, &hash, tiled.split_budget, &redo)?;
                redo.finish("after damage");
            }
        }
    }
    Ok(M3c2Results {
        dir,
        chunks,
        hash,
        reused,
    })
}

/// Compute the tiles of `todo` in order (`next` counts those done, into the whole list),
/// with a reader thread decoding the next tile meanwhile.
#[allow(clippy::too_many_arguments)]
fn sweep(
    wd: &mut WorkDir,
    dir: &Path,
    layout: &Layout,
    tiled: &Tiled,
    params: &Params,
    user_cores: Option<&UserCores>,
    hash: &str,
    todo: &[TileId],
    chunks: &mut [(TileId, usize)],
    next: &mut usize,
    stage: &Stage,
) -> Result<Sweep> {
    let (tx, rx) = bounded::<std::result::Result<Work, ReadFailure>>(1);
    let before_dir = tiled.before.clone();
    let after_dir = tiled.after.clone();
    let todo_ids = todo.to_vec();
    std::thread::scope(|s| -> Result<Sweep> {
        s.spawn(move || {
            let read = |epoch: Epoch, dir: &Path, id: TileId| {
                tiles::read_tile_raw(dir, id).map_err(|e| {
                    if e.is_corrupt() {
                        ReadFailure::Corrupt(epoch, e)
                    } else {
                        ReadFailure::Other(tiling_error(e))
                    }
                })
            };
            for id in todo_ids {
                // Both epochs at once: decompressing a tile is one thread's work.
                let (before, after) = std::thread::scope(|s| {
                    let after = s.spawn(|| read(Epoch::After, &after_dir, id));
                    let before = read(Epoch::Before, &before_dir, id);
                    let after = after.join().unwrap_or_else(|_| {
                        Err(ReadFailure::Other(Error::Internal(
                            "a tile reader panicked".into(),
                        )))
                    });
                    (before, after)
                });
                let w = before.and_then(|before| {
                    Ok(Work {
                        id,
                        before,
                        after: after?,
                    })
                });
                let failed = w.is_err();
                // A closed channel means the consumer stopped (error): stop reading.
                if tx.send(w).is_err() || failed {
                    return;
                }
            }
        });
        // The receiver is moved in and so dropped when this returns, error or not: a reader
        // blocked on a full channel then wakes up with a send error and the scope can join it.
        consume(
            rx, wd, dir, layout, params, user_cores, hash, chunks, next, stage,
        )
    })
}

#[allow(clippy::too_many_arguments)]
fn consume(
    rx: crossbeam_channel::Receiver<std::result::Result<Work, ReadFailure>>,
    wd: &mut WorkDir,
    dir: &Path,
    layout: &Layout,
    params: &Params,
    user_cores: Option<&UserCores>,
    hash: &str,
    chunks: &mut [(TileId, usize)],
    next: &mut usize,
    stage: &Stage,
) -> Result<Sweep> {
    for w in rx.iter() {
        let w = match w {
            Ok(w) => w,
            Err(ReadFailure::Corrupt(epoch, e)) => return Ok(Sweep::Resplit(epoch, e)),
            Err(ReadFailure::Other(e)) => return Err(e),
        };
        let cores = user_cores.map(|u| u.by_tile[layout.grid.index(w.id)].as_slice());
        let results = compute_tile(&w, layout, params, cores);
        let unit = unit_name(w.id);
        // Forget the old entry before its chunk files are overwritten (see `WorkDir::forget`).
        wd.forget(&unit)?;
        let n = write_chunks(dir, w.id, &results)?;
        let checksum = chunks_checksum(dir, w.id, n).map_err(tiling_error)?;
        wd.done(&unit, &n.to_string(), hash, &checksum)?;
        if let Some(c) = chunks.iter_mut().find(|c| c.0 == w.id) {
            c.1 = n;
        }
        *next += 1;
        let owned = |t: &TilePoints| t.owned.iter().filter(|&&o| o).count() as u64;
        stage.inc(owned(&w.before) + owned(&w.after));
    }
    Ok(Sweep::Finished)
}

/// Normals and M3C2 for the core points tile `w` owns, sorted by key.
fn compute_tile(
    w: &Work,
    layout: &Layout,
    params: &Params,
    user_cores: Option<&[(u64, Point3)]>,
) -> Vec<KeyedResult> {
    // One local frame for every tile (the core-point anchor), not one per tile: the local
    // coordinates, and so every rounding in the sums and the top-surface cells of `auto`
    // orientation, are then the same whatever the tiling, and a tiled run gives the bytes of a
    // whole-cloud run.
    let origin = layout.anchor;
    let m = params.m3c2();
    let cell = m3c2::column_width(&m);
    let index = |t: &TilePoints| Columns::from_fn(t.len(), |i| t.point(i), origin, cell);
    let (before, after) = rayon::join(|| index(&w.before), || index(&w.after));
    let keyed: Vec<(u64, Point3)> = match user_cores {
        Some(c) => c.to_vec(),
        None => core_points::thin(
            w.before.len(),
            |i| w.before.point(i),
            &layout.anchor,
            layout.core_spacing,
            |i| w.before.owned[i],
        )
        .into_iter()
        .map(|(k, i)| (k, w.before.point(i)))
        .collect(),
    };
    if keyed.is_empty() {
        return Vec::new();
    }
    let local: Vec<Point3> = keyed.iter().map(|(_, p)| before.to_local(p)).collect();
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
