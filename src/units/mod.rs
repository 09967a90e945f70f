//! What each kind of unit does (SPEC.md §3 "Units"), one module per stage, in pipeline order:
//! [`tiling`] (a survey → tile files) → `cores` (the user's core points, or a campaign's) →
//! [`m3c2`] (a tile's normals and distances for a pair) → [`stable`] (a pair's noise and
//! registration error) → `events` (a pair's filter, smoothing, clustering, description) →
//! `volumes` (a tile's events' volumes) → `outputs` (a pair's files, ready to publish) →
//! `campaign` (a campaign's files). Each module's stage type implements [`stage::Stage`] and is
//! registered in `stage::default_stages`.
//!
//! The unit contract: a unit reads only the plan and the files of the units it depends on, and
//! writes only into its own [`UnitWriter`]; it returns its stage's typed meta, kept in its record
//! beside the executor's [`stage::Timing`]. It is a pure function of those inputs — whichever
//! process, machine or run executes it, and in whatever order the units run, its files are the
//! same bytes.

pub(crate) mod align;
pub(crate) mod aligned;
pub(crate) mod campaign;
pub mod cleared;
pub(crate) mod cores;
pub(crate) mod events;
pub(crate) mod field;
pub mod m3c2;
pub(crate) mod merged;
pub(crate) mod orient;
pub(crate) mod outputs;
pub(crate) mod sample;
pub(crate) mod sampled;
pub(crate) mod scratch;
pub(crate) mod series;
pub(crate) mod solids;
pub mod stable;
pub mod stage;
pub mod tiling;
pub(crate) mod volumes;

use std::path::{Path, PathBuf};

use talus_tiling::TileId;

use crate::error::{Error, Result};
use crate::io::Point3;
use crate::plan::{Plan, Spec};
use crate::store::{Store, UnitRef, UnitWriter};
use stage::Stage;

/// What a unit sees while it runs.
pub struct Ctx<'a> {
    pub plan: &'a Plan,
    pub store: &'a Store,
    /// Counts the unit's work (points, core points, events) for its stage's progress line.
    pub progress: &'a (dyn Fn(u64) + Sync),
    /// The process's memory pool: reserve before holding anything large.
    pub pool: &'a crate::memory::Pool,
    /// The unit running, whose files `Ctx::input` grants: its dependencies' only (None: a
    /// reader outside any unit, such as the Python package reading a finished run).
    pub reader: Option<usize>,
}

impl Ctx<'_> {
    /// Reserve `need` bytes for `what` from the pool (waiting for other units; exit 2 when the
    /// budget could never hold it).
    pub(crate) fn reserve(&self, need: u64, what: &str) -> Result<crate::memory::Reservation<'_>> {
        crate::memory::reserve(self.pool, need, self.plan.params.memory_bytes.value, what)
    }

    /// The store's name of unit `i`.
    pub(crate) fn unit_ref(&self, i: usize) -> UnitRef {
        unit_ref(self.plan, i)
    }

    /// The path of `file` in finished unit `i`, a dependency of the unit running, or one of the
    /// files any unit's release keeps ([`stage::Stage::KEPT`]). Reading any other unit's files is
    /// refused: the executor releases a unit's files once every unit that depends on it is done
    /// (`exec::EarlyRelease`), so a file read beyond the declared dependencies could be gone.
    pub(crate) fn input(&self, i: usize, file: &str) -> Result<PathBuf> {
        if let Some(r) = self.reader {
            let kept = || {
                stage::registry()
                    .get(self.plan.units[i].kind())
                    .is_ok_and(|s| s.kept().contains(&file))
            };
            if !self.plan.units[r].deps.contains(&i) && !kept() {
                return Err(Error::Internal(format!(
                    "unit {} reads {file} of unit {}, which it does not depend on",
                    self.plan.units[r].name, self.plan.units[i].name
                )));
            }
        }
        Ok(self.store.unit_dir(&self.unit_ref(i))?.join(file))
    }

    /// The record of finished unit `i`.
    fn record(&self, i: usize) -> Result<crate::store::Record> {
        self.store
            .done(&self.unit_ref(i))
            .ok_or_else(|| Error::Internal(format!("unit {} is not done", self.plan.units[i].name)))
    }

    /// The typed meta of finished unit `i`, of stage `S`. A record whose meta is not `S`'s (a
    /// field missing) is damaged: the executor redoes that unit.
    pub(crate) fn meta<S: Stage>(&self, i: usize) -> Result<S::Meta> {
        let u = &self.plan.units[i];
        if u.kind() != S::KIND {
            return Err(Error::Internal(format!(
                "unit {} is a {} unit, not {}",
                u.name,
                u.kind(),
                S::KIND
            )));
        }
        self.record_meta(i)
    }

    /// What the executor recorded of finished unit `i` beside its meta: its seconds and peak
    /// memory.
    pub(crate) fn timing(&self, i: usize) -> Result<stage::Timing> {
        stage::timing_of(self.store, &self.unit_ref(i), &self.record(i)?)
    }

    /// Unit `i`'s record's meta as `M`. A record that lacks a field is damaged, naming the
    /// record: the executor then computes unit `i` again and the unit that read it.
    fn record_meta<M: serde::de::DeserializeOwned>(&self, i: usize) -> Result<M> {
        let rec = self.record(i)?;
        M::deserialize(&rec.meta).map_err(|e| self.damaged_record(i, e))
    }

    /// The pair unit `i` is for.
    pub(crate) fn pair(&self, i: usize) -> Result<usize> {
        let u = &self.plan.units[i];
        u.spec
            .pair
            .ok_or_else(|| Error::Internal(format!("unit {} without a pair", u.name)))
    }

    /// The part unit `i` is (of a survey's or a pair's units in parts).
    pub(crate) fn part(&self, i: usize) -> Result<usize> {
        let u = &self.plan.units[i];
        u.spec
            .part
            .map(|k| k as usize)
            .ok_or_else(|| Error::Internal(format!("unit {} without a part", u.name)))
    }

    /// The survey unit `i` is for.
    pub fn survey(&self, i: usize) -> Result<usize> {
        let u = &self.plan.units[i];
        u.spec
            .survey
            .ok_or_else(|| Error::Internal(format!("unit {} without a survey", u.name)))
    }

    /// The tile unit `i` is for.
    pub(crate) fn tile(&self, i: usize) -> Result<TileId> {
        let u = &self.plan.units[i];
        u.spec
            .tile
            .map(crate::plan::tile_id)
            .ok_or_else(|| Error::Internal(format!("unit {} without a tile", u.name)))
    }

    /// The units whose tile files hold survey `survey` in the run's frame, and their record:
    /// the last stage in the registry that provides tiles ([`stage::Stage::TILES`]) and whose
    /// units of the survey hold them — its cleared tiling with `--vegetation remove`, else its
    /// aligned tiling where the alignment applied, else its own tiling (in parts where it is
    /// large: [`Tiles`]).
    pub(crate) fn tiles(&self, survey: usize) -> Result<(Tiles, tiling::TilingMeta)> {
        self.tiles_before(survey, None)
    }

    /// [`Ctx::tiles`] as the stages before stage `kind` leave them (a stage that provides
    /// tiles reads the ones it replaces), or all of them (`None`).
    pub(crate) fn tiles_before(
        &self,
        survey: usize,
        kind: Option<&str>,
    ) -> Result<(Tiles, tiling::TilingMeta)> {
        let stages = stage::registry().stages();
        let end = kind
            .and_then(|k| stages.iter().position(|s| s.kind() == k))
            .unwrap_or(stages.len());
        for st in stages[..end].iter().rev().filter(|s| s.provides_tiles()) {
            let tiles = Tiles(self.plan.survey_units(st.kind(), survey));
            if let Some(meta) = self.tiles_meta(&tiles)? {
                return Ok((tiles, meta));
            }
        }
        Err(Error::Internal(format!(
            "no unit holds survey {survey}'s tiles"
        )))
    }

    /// The units whose tile files hold survey `survey` in the run's frame ([`Ctx::tiles`]).
    pub(crate) fn tiling(&self, survey: usize) -> Result<Tiles> {
        Ok(self.tiles(survey)?.0)
    }

    /// Survey `survey`'s own tiling, as delivered (not aligned, not cleared): its unit or its
    /// parts.
    pub fn own_tiling(&self, survey: usize) -> Result<Tiles> {
        let units = self.plan.survey_units(tiling::TilingStage::KIND, survey);
        if units.is_empty() {
            return Err(Error::Internal(format!("survey {survey} has no tiling")));
        }
        Ok(Tiles(units))
    }

    /// The coordinate quantum (scale, offset per axis) of survey `survey`'s first file, which
    /// a stage that tiles the survey anew keeps (None for text and PLY).
    pub fn quantum(&self, survey: usize) -> Result<Option<[[f64; 2]; 3]>> {
        let sv = &self.plan.surveys[survey];
        // A LAS survey (it has a scale) planned before the plan kept the transform.
        if sv.transform.is_none() && sv.scale.is_some() {
            return Ok(sv
                .files
                .first()
                .map(|f| crate::io::open(&f.path))
                .transpose()?
                .and_then(|r| r.info().transform));
        }
        Ok(sv.transform)
    }

    /// The tiling record of survey `survey` in the run's frame (see [`Ctx::tiles`]).
    pub(crate) fn tiling_meta(&self, survey: usize) -> Result<tiling::TilingMeta> {
        Ok(self.tiles(survey)?.1)
    }

    /// The tiling record of the units `tiles` (its parts' records merged:
    /// [`tiling::TilingMeta::merge`]), each record read once; None when they hold no tiles (no
    /// unit, or an aligned tiling whose alignment did not apply).
    pub(crate) fn tiles_meta(&self, tiles: &Tiles) -> Result<Option<tiling::TilingMeta>> {
        let mut metas = Vec::with_capacity(tiles.0.len());
        for &u in &tiles.0 {
            match self.tiles_of(u)? {
                Some(m) => metas.push(m),
                None => return Ok(None),
            }
        }
        match tiles.0.as_slice() {
            [] => Ok(None),
            [_] => Ok(metas.pop()),
            [first, ..] => tiling::TilingMeta::merge(self, self.survey(*first)?, metas).map(Some),
        }
    }

    /// The tiles' record unit `u` holds, if its stage provides tiles and its meta says it
    /// holds them; a meta that does not read is damaged, naming the record.
    fn tiles_of(&self, u: usize) -> Result<Option<tiling::TilingMeta>> {
        let st = stage::registry().get(self.plan.units[u].kind())?;
        if !st.provides_tiles() {
            return Ok(None);
        }
        st.tiles(&self.record(u)?.meta)
            .map_err(|e| self.damaged_record(u, e))
    }

    /// Unit `u`'s record is damaged: its meta does not read (`e`).
    fn damaged_record(&self, u: usize, e: impl std::fmt::Display) -> Error {
        stage::damaged_record(self.store, &self.unit_ref(u), e)
    }

    /// The dependency of unit `i` of stage `S`, if it has one.
    pub(crate) fn dep<S: Stage>(&self, i: usize) -> Option<usize> {
        self.plan.units[i]
            .deps
            .iter()
            .copied()
            .find(|&d| self.plan.units[d].kind() == S::KIND)
    }

    /// The index of the unit of `spec` (it must be in the plan).
    pub fn unit(&self, spec: &Spec) -> Result<usize> {
        self.plan
            .find(spec)
            .ok_or_else(|| Error::Internal(format!("no unit {spec:?} in the plan")))
    }
}

/// The store's name of the plan's unit `i`.
pub(crate) fn unit_ref(plan: &Plan, i: usize) -> UnitRef {
    let u = &plan.units[i];
    UnitRef {
        kind: u.kind().to_string(),
        name: u.name.clone(),
    }
}

/// Run unit `i` of the plan, writing its files into `out`; returns the meta for its record.
pub(crate) fn run(ctx: &Ctx, i: usize, out: &mut UnitWriter) -> Result<serde_json::Value> {
    stage::registry()
        .get(ctx.plan.units[i].kind())?
        .run(ctx, i, out)
}

/// A damaged file of a finished unit: the executor throws that unit away and redoes it (a tile
/// file's checksums do not match, it is truncated, ...).
pub(crate) fn damaged(path: &Path, e: talus_tiling::Error) -> Error {
    match e {
        talus_tiling::Error::Corrupt { reason, .. } => Error::Damaged {
            path: path.to_path_buf(),
            problem: reason,
        },
        other => other.into(),
    }
}

/// The points of one tile: global coordinates, as the columns the tile file holds (no copy into
/// another layout), and whether the tile owns each one.
#[derive(Default)]
pub struct TilePoints {
    pub(crate) x: Vec<f64>,
    pub(crate) y: Vec<f64>,
    pub z: Vec<f64>,
    pub owned: Vec<bool>,
}

impl TilePoints {
    /// Add `more`'s points after these.
    fn append(&mut self, more: TilePoints) {
        self.x.extend(more.x);
        self.y.extend(more.y);
        self.z.extend(more.z);
        self.owned.extend(more.owned);
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when the tile holds no point.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Point `i`.
    #[inline]
    pub(crate) fn point(&self, i: usize) -> Point3 {
        [self.x[i], self.y[i], self.z[i]]
    }

    /// The columns as M3C2's tile kernel reads an epoch.
    pub(crate) fn epoch(&self) -> crate::m3c2::tile::EpochPoints<'_> {
        crate::m3c2::tile::EpochPoints {
            x: &self.x,
            y: &self.y,
            z: &self.z,
            owned: &self.owned,
        }
    }
}

/// The units whose tile files hold a survey's tiles: one unit, or a tiling's parts in order
/// (`units::tiling::parts`) — a tile's points are then the parts' files of that tile one after
/// the other, the whole survey's tile bit for bit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tiles(pub Vec<usize>);

impl Tiles {
    /// The units' keys, as one (what a cache of results computed from the tiles is keyed by).
    pub(crate) fn key(&self, plan: &crate::plan::Plan) -> String {
        let keys: Vec<&str> = self.0.iter().map(|&u| plan.units[u].key.as_str()).collect();
        keys.join("+")
    }
}

/// Read tile `id` of the survey whose tiles `tiles` hold.
pub fn read_tile(ctx: &Ctx, tiles: &Tiles, id: TileId) -> Result<TilePoints> {
    let paths = tiles
        .0
        .iter()
        .map(|&u| ctx.input(u, &tiling::tile_file(id)))
        .collect::<Result<Vec<_>>>()?;
    let read = |p: &Path| talus_tiling::read_tile(p).map_err(|e| damaged(p, e));
    if let [one] = paths.as_slice() {
        return Ok(tile_points(read(one)?));
    }
    // The whole tile's columns sized once from the parts' headers: what is held is the tile
    // and one part, as the per-point needs counted on a whole tile allow.
    let mut n = 0;
    for p in &paths {
        n += talus_tiling::read_tile_header(p)
            .map_err(|e| damaged(p, e))?
            .point_count as usize;
    }
    let mut t = TilePoints {
        x: Vec::with_capacity(n),
        y: Vec::with_capacity(n),
        z: Vec::with_capacity(n),
        owned: Vec::with_capacity(n),
    };
    for p in &paths {
        t.append(tile_points(read(p)?));
    }
    Ok(t)
}

/// The points of tile `id` of the survey whose tiles `tiles` hold, in the frames of its files
/// that reach any of `boxes` ([x0, y0, x1, y1]), in their order: every point inside the boxes,
/// and others beside them (the rest of those frames); the frames that do not reach them are not
/// decoded.
pub(crate) fn read_tile_near(
    ctx: &Ctx,
    tiles: &Tiles,
    id: TileId,
    boxes: &[[f64; 4]],
) -> Result<TilePoints> {
    let mut t = TilePoints::default();
    for_each_frame_near(ctx, tiles, id, boxes, |f| t.append(f))?;
    Ok(t)
}

/// [`read_tile_near`] a frame at a time, for a reader that keeps only some of each frame's
/// points: `f` gets the points of each frame that reaches `boxes`, in order.
pub(crate) fn for_each_frame_near(
    ctx: &Ctx,
    tiles: &Tiles,
    id: TileId,
    boxes: &[[f64; 4]],
    mut f: impl FnMut(TilePoints),
) -> Result<()> {
    let want = |b: &crate::geom::Bounds| reaches(b, boxes);
    for &u in &tiles.0 {
        let path = ctx.input(u, &tiling::tile_file(id))?;
        let mut frames = talus_tiling::TileFrames::open(&path).map_err(|e| damaged(&path, e))?;
        while let Some(cols) = frames
            .next_frame_where(&want)
            .map_err(|e| damaged(&path, e))?
        {
            f(tile_points(cols));
        }
    }
    Ok(())
}

/// Do bounds `b` reach one of `boxes` ([x0, y0, x1, y1] each) in plan?
pub(crate) fn reaches(b: &crate::geom::Bounds, boxes: &[[f64; 4]]) -> bool {
    boxes
        .iter()
        .any(|w| b.min[0] <= w[2] && w[0] <= b.max[0] && b.min[1] <= w[3] && w[1] <= b.max[1])
}

/// A tile file's columns as points with their owned flags.
fn tile_points(cols: talus_tiling::TileColumns) -> TilePoints {
    let owned = match cols.column(talus_tiling::OWNED_COLUMN) {
        Some(talus_tiling::ColumnData::U8(v)) => v.iter().map(|&o| o == 1).collect(),
        _ => vec![true; cols.len()],
    };
    TilePoints {
        x: cols.x,
        y: cols.y,
        z: cols.z,
        owned,
    }
}

/// Serialize `value` as JSON into `file` of `out`, recorded with its digest.
pub fn write_json(out: &mut UnitWriter, file: &str, value: &impl serde::Serialize) -> Result<()> {
    let bytes = serde_json::to_vec(value).map_err(|e| Error::Internal(format!("{file}: {e}")))?;
    write_bytes(out, file, &bytes)
}

/// Write `bytes` into `file` of `out`, recorded with its digest.
pub(crate) fn write_bytes(out: &mut UnitWriter, file: &str, bytes: &[u8]) -> Result<()> {
    write_streamed(out, file, |w| w.write_all(bytes))
}

/// Write `file` of `out` with `body` through a buffer, recorded with the CRC-32 and size computed
/// on the way: plainly (the unit's commit makes it durable), never read back, never held whole.
pub(crate) fn write_streamed(
    out: &mut UnitWriter,
    file: &str,
    body: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
) -> Result<()> {
    use std::io::Write;
    struct Digest<W> {
        inner: W,
        crc: crc32fast::Hasher,
        size: u64,
    }
    impl<W: Write> Write for Digest<W> {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            let n = self.inner.write(buf)?;
            self.crc.update(&buf[..n]);
            self.size += n as u64;
            Ok(n)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            self.inner.flush()
        }
    }
    let path = out.path(file)?;
    let write = || -> std::io::Result<(u32, u64)> {
        let mut d = Digest {
            inner: std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(&path)?),
            crc: crc32fast::Hasher::new(),
            size: 0,
        };
        body(&mut d)?;
        d.flush()?;
        Ok((d.crc.finalize(), d.size))
    };
    let (crc, size) = write().map_err(|e| Error::output(&path, e))?;
    out.add(file, crc, size);
    Ok(())
}

/// Read `file` of finished unit `i` as JSON.
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(
    ctx: &Ctx,
    i: usize,
    file: &str,
) -> Result<T> {
    let path = ctx.input(i, file)?;
    let bytes = std::fs::read(&path).map_err(|e| Error::Damaged {
        path: path.clone(),
        problem: e.to_string(),
    })?;
    serde_json::from_slice(&bytes).map_err(|e| Error::Damaged {
        path,
        problem: e.to_string(),
    })
}

/// Write tile-file columns into `file` of `out`, recorded with their digest.
pub(crate) fn write_columns(
    out: &mut UnitWriter,
    file: &str,
    cols: &talus_tiling::TileColumns,
) -> Result<()> {
    let path = out.path(file)?;
    let d = talus_tiling::write_tile(&path, cols)?;
    out.add(file, d.crc32, d.size);
    Ok(())
}

/// Read tile-file columns `file` of finished unit `i`.
pub(crate) fn read_columns(ctx: &Ctx, i: usize, file: &str) -> Result<talus_tiling::TileColumns> {
    let path = ctx.input(i, file)?;
    talus_tiling::read_tile(&path).map_err(|e| damaged(&path, e))
}

#[cfg(test)]
mod tests {
    use super::{merged, outputs, stable, tiling};

    /// The units' fixed needs against the smallest budget (`memory::MIN_BUDGET`): here, not in
    /// `memory`, which sits below the units and names none of them.
    #[test]
    fn the_smallest_budget_holds_the_fixed_needs() {
        let pool = crate::memory::pool_bytes(crate::memory::MIN_BUDGET);
        assert!(outputs::points::need(1) <= pool, "m3c2.laz does not fit");
        assert!(outputs::NEED <= pool, "the outputs do not fit");
        // The stable ground's fixed sample, beside the largest merge a later stage holds.
        let stable = stable::need(stable::SAMPLES, merged::FAN_IN);
        assert!(stable <= pool, "the stable sample does not fit");
        let split = tiling::split_budget_of(crate::memory::MIN_BUDGET);
        // Two tilings run at once (one per survey of a pair).
        assert!(2 * tiling::need(split) <= pool, "two tilings do not fit");
    }
}
