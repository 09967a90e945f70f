//! A tiling unit: one survey streamed into the layout's tiles (pass 1 of SPEC.md §3). The survey
//! is read in chunks and never whole; every tile of the grid gets a file (an empty one where no
//! point falls in its halo box), so a missing file always means damage. A survey tiled once
//! serves every pair it belongs to.

use talus_tiling::{Quantisation, TileId, TileSplitter, WriteOptions};

use super::stage::{Line, Planner, Scope, Stage, TilesOf, Total};
use super::Ctx;
use crate::error::Result;
use crate::io;
use crate::io::classes::ClassCounts;
use crate::plan::Spec;
use crate::sampling::MIN_DISTINCT;
use crate::store::UnitWriter;

/// The file of tile `id` in a tiling unit.
pub(crate) fn tile_file(id: TileId) -> String {
    format!("{}.tile", id.name())
}

/// Share of the memory budget the splitter's buffers may take. Two tilings may run at once (one
/// per survey of a pair: decoding is one thread's work, so on two cores that halves pass 1).
pub(crate) const SPLIT_BUDGET_SHARE: u64 = 8;

/// Resident bytes of a tiling unit beside its splitter's buffers: the reader's chunk and
/// decoder, a tile being encoded (its columns and compressed bytes), the writer's buffer.
/// Measured: 115–120 MiB at a 300 MiB budget (37.5 MiB of buffers), i.e. about 2 × the buffers
/// more; counted as that plus a fixed part.
pub(crate) fn need(buffers: u64) -> u64 {
    3 * buffers + crate::memory::IO_HEADROOM
}

/// Bytes of a tiling unit's splitter buffers under the plan's memory budget.
pub(crate) fn split_budget(plan: &crate::plan::Plan) -> u64 {
    split_budget_of(plan.params.memory_bytes.value)
}

/// Bytes of a tiling unit's splitter buffers under a memory budget of `memory_bytes`.
pub(crate) fn split_budget_of(memory_bytes: u64) -> u64 {
    (memory_bytes / SPLIT_BUDGET_SHARE).max(8 << 20)
}

/// Points per frame of the tile files of a survey split into `tiles` tiles (see
/// `talus_tiling::splitter`): part of the tiling unit's key.
pub(crate) fn frame_points(plan: &crate::plan::Plan, tiles: usize) -> usize {
    talus_tiling::splitter::frame_points(split_budget(plan), tiles)
}

/// How a survey's tiles are written: a LAS/LAZ survey's coordinates as the integers of its
/// (first) file's coordinate transform, which is exact (a value that does not come back bit for
/// bit keeps its column as f64) and takes a third of the bytes, so that tiles compress, are
/// written and read in a fraction of the time (`talus_tiling::tile_file`'s measurements).
pub(crate) fn write_options(transform: Option<[[f64; 2]; 3]>) -> WriteOptions {
    WriteOptions {
        quantise: transform.map(|t| Quantisation {
            scale: t.map(|a| a[0]),
            offset: t.map(|a| a[1]),
        }),
        ..WriteOptions::default()
    }
}

/// A survey cut into the layout's tiles: one unit per survey, serving every pair it is in.
pub struct TilingStage;

/// What a tiling unit records.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct TilingMeta {
    /// The survey's points.
    pub(crate) points: u64,
    /// Points per tile (halo included), in grid order: what the pair's M3C2 units check the
    /// budget against before the first of them holds anything (`units::m3c2::fit`).
    pub(crate) tile_points: Vec<u64>,
    /// Points read and left out per LAS class (`--classes`); None when no class was read (text
    /// or PLY input, or every class kept).
    pub(crate) classes: Option<ClassCounts>,
    /// A part's first distinct positions (at most [`MIN_DISTINCT`]; None for a whole survey,
    /// which checks them itself): a survey tiled in parts is refused for too few positions
    /// once its parts' records are read together ([`TilingMeta::merge`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) distinct: Option<Vec<crate::geom::Point3>>,
}

impl TilingMeta {
    /// The record of a survey tiled in parts, from its parts' records in order: a tile's points
    /// are its parts' files of that tile one after the other. A survey whose parts together
    /// show fewer than [`MIN_DISTINCT`] distinct positions is refused here, as a whole
    /// survey's tiling refuses it.
    pub(crate) fn merge(ctx: &Ctx, survey: usize, parts: Vec<TilingMeta>) -> Result<TilingMeta> {
        let mut it = parts.into_iter();
        let Some(mut all) = it.next() else {
            return Err(crate::error::Error::Internal(format!(
                "survey {survey}'s tiling without a part"
            )));
        };
        let mut seen = FewPositions(all.distinct.take().unwrap_or_default());
        for m in it {
            all.points += m.points;
            for (t, n) in all.tile_points.iter_mut().zip(&m.tile_points) {
                *t += n;
            }
            all.classes = match (all.classes, m.classes) {
                (Some(a), Some(b)) => Some(a.merge(&b)),
                (a, b) => a.or(b),
            };
            seen.see(m.distinct.as_deref().unwrap_or_default());
        }
        seen.check(ctx, survey, all.classes.as_ref(), all.points)?;
        Ok(all)
    }
}

/// Most parts a survey is tiled in (as many as a Slurm array's tasks): a smaller `--tiling-part`
/// is refused rather than planned as millions of units.
pub(crate) const MAX_PARTS: usize = 1000;

/// A part of a survey's tiling: its points `start..end`, the survey's files one after the other
/// in name order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Part {
    pub start: u64,
    pub end: u64,
}

/// The parts survey `s` of `plan` is tiled in: ranges of [`crate::plan::Plan::tiling_part`]
/// points (the last one shorter); none — one unit for the whole survey — when it holds no more
/// than that, or when it is not all LAS/LAZ (whose headers count the points: text and PLY are
/// read whole). A part's tile files hold its points of the tile in the order it reads them,
/// so the parts' files one after the other are the whole survey's tile, bit for bit.
pub fn parts(plan: &crate::plan::Plan, s: usize) -> Vec<Part> {
    let sv = &plan.surveys[s];
    let total: u64 = sv.file_points.iter().sum();
    let size = plan.tiling_part.max(1);
    if sv.file_points.len() != sv.files.len() || total != sv.points || total <= size {
        return Vec::new();
    }
    (0..total.div_ceil(size))
        .map(|k| Part {
            start: k * size,
            end: ((k + 1) * size).min(total),
        })
        .collect()
}

impl Stage for TilingStage {
    const KIND: &'static str = "tiling";
    const SCOPE: Scope = Scope::Survey;
    const VERSION: u32 = 1;
    const INTERMEDIATE: bool = true;
    const LINE: Line = Line {
        name: "pass 1: tiling",
        counts: "points",
        total: Total::SurveyPoints,
    };
    type Meta = TilingMeta;
    const TILES: Option<TilesOf<TilingMeta>> = Some(|m| Some(m.clone()));

    /// The tiling of each pair's two surveys, once each.
    fn plan(p: &mut Planner) -> Result<()> {
        for k in 0..p.plan.pairs.len() {
            let (b, a) = (p.plan.pairs[k].before, p.plan.pairs[k].after);
            for s in [b, a] {
                let survey = &p.plan.surveys[s];
                let (key, label, layout) = (
                    survey.key.clone(),
                    survey.label.clone(),
                    p.plan.layout.key(),
                );
                // The frames a tile file is written in (their size comes from the memory budget):
                // the same points in other frames are other bytes.
                let frames = match p.plan.layout.grid() {
                    Ok(g) => format!("frame {}", frame_points(p.plan, g.len())),
                    Err(_) => String::new(),
                };
                let classes = format!("classes {}", p.plan.params.classes.value);
                let parts = parts(p.plan, s);
                if parts.len() > MAX_PARTS {
                    return Err(crate::error::Error::Usage(format!(
                        "--tiling-part {}: survey {} ({} points) would be tiled by {} units, \
                         more than {MAX_PARTS}: give a larger part",
                        p.plan.tiling_part,
                        p.plan.surveys[s].arg.display(),
                        p.plan.surveys[s].points,
                        parts.len()
                    )));
                }
                if parts.is_empty() {
                    p.add(
                        Spec::survey(Self::KIND, s),
                        &label,
                        &[&key, &layout, &frames, &classes],
                        Vec::new(),
                    );
                }
                for (k, part) in parts.iter().enumerate() {
                    let range = format!("points {}..{}", part.start, part.end);
                    p.add(
                        Spec::survey_part(Self::KIND, s, k as u32),
                        &format!("{label}-p{k}"),
                        &[&key, &layout, &frames, &classes, &range],
                        Vec::new(),
                    );
                }
            }
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<TilingMeta> {
        let s = ctx.survey(unit)?;
        let part = match ctx.plan.units[unit].spec.part {
            Some(k) => Some(*parts(ctx.plan, s).get(k as usize).ok_or_else(|| {
                crate::error::Error::Internal(format!("survey {s} has no tiling part {k}"))
            })?),
            None => None,
        };
        split_part(ctx, s, part, None, out)
    }
}

/// A change of every chunk of points before it is tiled (an alignment: `super::aligned`).
pub(crate) type Transform<'a> = &'a dyn Fn(&mut [crate::geom::Point3]);

/// Cut survey `survey` into `out`, each chunk of points passed through `transform` first.
pub fn split(
    ctx: &Ctx,
    survey: usize,
    transform: Option<Transform>,
    out: &mut UnitWriter,
) -> Result<TilingMeta> {
    split_part(ctx, survey, None, transform, out)
}

/// [`split`] for part `part` of the survey (None: all of it).
pub fn split_part(
    ctx: &Ctx,
    survey: usize,
    part: Option<Part>,
    transform: Option<Transform>,
    out: &mut UnitWriter,
) -> Result<TilingMeta> {
    let plan = ctx.plan;
    let sv = &plan.surveys[survey];
    let mut splitting = Splitting::new(ctx, survey, out)?;
    // Every part writes its coordinates in the survey's first file's quantum.
    splitting.quantum(ctx.quantum(survey)?);
    let mut buf = Vec::new();
    let keep = plan.params.classes();
    let mut classes: Option<ClassCounts> = None;
    let mut positions = FewPositions::default();
    // A survey delivered as tiles: its files one after the other, in name order; a part reads
    // the range of each file that falls in it.
    let mut first = 0u64;
    for (k, f) in sv.files.iter().enumerate() {
        let mut reader = match part {
            None => io::open_with(&f.path, Some(&keep))?,
            Some(part) => {
                let n = sv.file_points[k];
                let (start, end) = (part.start.max(first), part.end.min(first + n));
                first += n;
                if start >= end {
                    continue;
                }
                io::open_range(&f.path, Some(&keep), start - (first - n), end - start)?
            }
        };
        let mut left_out = 0;
        while reader.fill(&mut buf, 1 << 16)? > 0 {
            if let Some(f) = transform {
                f(&mut buf);
            }
            positions.see(&buf);
            splitting.push(&buf)?;
            // The points read, those left out by class included: the line counts up to the
            // survey's points.
            let out = reader.left_out();
            (ctx.progress)(buf.len() as u64 + out - left_out);
            left_out = out;
            crate::interrupt::check()?;
        }
        if let Some(c) = reader.class_counts() {
            classes = Some(match classes {
                Some(all) => all.merge(&c),
                None => c,
            });
        }
    }
    if part.is_none() {
        positions.check(ctx, survey, classes.as_ref(), splitting.points)?;
    }
    let mut meta = splitting.finish(out, classes)?;
    meta.distinct = part.map(|_| positions.0);
    Ok(meta)
}

/// The first [`MIN_DISTINCT`] distinct positions of a survey's points (of the classes
/// compared): a survey with fewer describes no surface. The before survey's spacing pass refuses
/// such a survey before anything runs; an after survey (or a tile of a survey in several files)
/// is only read here, so it is refused here, with the same words — it was taken as AFTER and
/// gave a few distances at the core points it touched, or "the epochs do not overlap" when the
/// classes left none of its points.
#[derive(Default)]
struct FewPositions(Vec<crate::geom::Point3>);

impl FewPositions {
    /// Note `points` (cheap: once [`MIN_DISTINCT`] positions are seen, nothing more is done).
    fn see(&mut self, points: &[crate::geom::Point3]) {
        for p in points {
            if self.0.len() >= MIN_DISTINCT {
                return;
            }
            if !self.0.contains(p) {
                self.0.push(*p);
            }
        }
    }

    /// Refuse survey `survey` when it showed fewer than [`MIN_DISTINCT`] positions (`points`
    /// kept, `classes` its class counts).
    fn check(
        &self,
        ctx: &Ctx,
        survey: usize,
        classes: Option<&ClassCounts>,
        points: u64,
    ) -> Result<()> {
        if self.0.len() >= MIN_DISTINCT {
            return Ok(());
        }
        let keep = ctx.plan.params.classes();
        let problem = match classes {
            Some(c) if c.kept() == 0 => c.none_kept(&keep),
            _ => format!(
                "{points} points{} at only {} distinct position(s): a survey needs at least \
                 {MIN_DISTINCT} to describe a surface",
                if classes.is_some_and(|c| c.left_out() > 0) {
                    " of the classes compared"
                } else {
                    ""
                },
                self.0.len()
            ),
        };
        Err(crate::error::Error::input(
            &ctx.plan.surveys[survey].arg,
            problem,
        ))
    }
}

/// Points being cut into the run's tiles (square + halo, owned flag) in a unit's directory,
/// within the splitting budget reserved from the pool: [`split`]'s, and any stage that writes a
/// survey's tiling of its own (`--vegetation remove`'s cleared survey).
pub(crate) struct Splitting<'a> {
    splitter: TileSplitter,
    points: u64,
    _held: crate::memory::Reservation<'a>,
}

impl<'a> Splitting<'a> {
    /// Start the tiling of survey `survey` in `out`'s directory.
    pub(crate) fn new(ctx: &'a Ctx, survey: usize, out: &mut UnitWriter) -> Result<Splitting<'a>> {
        Self::with(ctx, survey, out, 0, "")
    }

    /// [`Splitting::new`] for a unit that also holds up to `extra` bytes of its own while it
    /// splits (`what` they are for): reserved with the splitter's in one reservation, since a
    /// unit may wait only while it holds none.
    pub(crate) fn with(
        ctx: &'a Ctx,
        survey: usize,
        out: &mut UnitWriter,
        extra: u64,
        what: &str,
    ) -> Result<Splitting<'a>> {
        let plan = ctx.plan;
        let layout = &plan.layout;
        let budget = split_budget(plan);
        let held = ctx.reserve(
            need(budget) + extra,
            &format!("tiling survey {}{what}", plan.surveys[survey].label),
        )?;
        // The unit's own directory: where the splitter writes its tile files.
        let dir = out
            .path("tile")?
            .parent()
            .map(|d| d.to_path_buf())
            .ok_or_else(|| crate::error::Error::Internal("a unit without a directory".into()))?;
        Ok(Splitting {
            splitter: TileSplitter::new(&dir, layout.grid()?, layout.halo, budget)?,
            points: 0,
            _held: held,
        })
    }

    /// The coordinate quantum of the survey's file (scale, offset per axis), which the tiles
    /// keep as their exact integer encoding.
    pub(crate) fn quantum(&mut self, transform: Option<[[f64; 2]; 3]>) {
        self.splitter.set_options(write_options(transform));
    }

    pub(crate) fn push(&mut self, points: &[crate::geom::Point3]) -> Result<()> {
        self.splitter.push(points)?;
        self.points += points.len() as u64;
        Ok(())
    }

    /// Write the last frames and record every tile file in `out` (an empty file for a tile
    /// without points).
    pub(crate) fn finish(
        self,
        out: &mut UnitWriter,
        classes: Option<ClassCounts>,
    ) -> Result<TilingMeta> {
        let grid = *self.splitter.grid();
        // Points per tile (halo included), in grid order. A tile without points has no file
        // from the splitter.
        let mut tile_points = vec![0u64; grid.len()];
        for (id, n, digest) in self.splitter.finish_with_digests()? {
            tile_points[grid.index(id)] = n;
            out.add(&tile_file(id), digest.crc32, digest.size);
        }
        for id in grid.tiles() {
            if tile_points[grid.index(id)] == 0 {
                let name = tile_file(id);
                let digest =
                    talus_tiling::write_tile(&out.path(&name)?, &talus_tiling::empty_columns())?;
                out.add(&name, digest.crc32, digest.size);
            }
        }
        Ok(TilingMeta {
            points: self.points,
            tile_points,
            classes,
            distinct: None,
        })
    }
}
