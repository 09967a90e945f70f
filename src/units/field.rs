//! The orientation field's sample of one tile of a before survey (`--orientation auto`): the
//! survey's points thinned to one per cubic cell of the field spacing on the run's anchor, the
//! cells whose centre the tile holds (so each cell once, whatever the tiling), each with M3C2's
//! normal over a subset of the tile's points chosen by a hash of their coordinates (so also the
//! same whatever the tiling). The survey's `orient` unit gathers every tile's sample and orients
//! it as one ([`super::orient`]): the sampling, which reads every point of the survey, spreads
//! over the tiles' tasks, and what stays one task per survey is the sample alone.
//!
//! A sample point whose neighbourhood is no surface at that scale (an edge, a crest) is left out
//! ([`field::FLAT`]).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use talus_tiling::{Column, ColumnData, TileColumns};

use super::stage::{Line, Planner, Scope, Stage, Total};
use super::{read_tile, Ctx};
use crate::error::{Error, Result};
use crate::geom::Point3;
use crate::m3c2::field;
use crate::m3c2::normals::normal_at;
use crate::m3c2::Orientation;
use crate::plan::Spec;
use crate::spatial::Columns;
use crate::store::UnitWriter;

/// Most sample points of a survey's field (its spacing grows past that): the spanning tree and
/// its graph then hold ≈ 40 MB at most.
pub(crate) const FIELD_MAX: f64 = 200_000.0;
/// The field's spacing is at least this many core spacings.
const CORE_CELLS: f64 = 2.0;
/// Points of the ball's subset a field normal is fitted to, about.
const BALL_POINTS: f64 = 50.0;
/// Resident bytes per point of a tile while its field points are computed: the tile's columns
/// (25), the subset's index, the thinning.
pub(crate) const BYTES_PER_POINT: u64 = 48;

/// The file of a field unit: the tile's sample points, their cell keys and normals.
pub(crate) const FILE: &str = "sample.tile";

/// The geometry of a survey's field: its cell, its normals' radius and the share of points
/// they are fitted to (one in `every`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Geometry {
    pub(crate) spacing: f64,
    pub(crate) radius: f64,
    pub(crate) every: u64,
}

impl Geometry {
    /// The geometry as the field and orient units' keys hold it.
    pub(crate) fn key(&self, plan: &crate::plan::Plan) -> String {
        format!(
            "field 1|{}|{}|{}|{}",
            self.spacing, self.radius, self.every, plan.layout.anchor[0]
        )
    }
}

/// The field geometry of survey `s` of `plan`.
pub(crate) fn geometry(plan: &crate::plan::Plan, s: usize) -> Geometry {
    let p = &plan.params;
    let (ps, core) = (p.point_spacing.value, p.core_spacing.value);
    let n = plan.surveys[s].points as f64;
    // The halo holds every neighbourhood of the tile's owned points up to its width less the
    // core-point margin (`plan::layout::tile_halo`); a cell must fit in it from its centre.
    let room = plan.layout.halo - 2.0 * core;
    let spacing = (CORE_CELLS * core)
        .max(ps * (n / FIELD_MAX).sqrt())
        .min(room);
    // The normals' own radius: the field's normals are M3C2's at its sample points. A wider ball
    // smooths a scarp into a tilt the surface does not have, and the orientation carried
    // across it comes out wrong (St Leonards' dunes, at 1.5 field spacings).
    let radius = p.normal_radius.value.min(room);
    // Points within the ball: about π r² / s² on a surface.
    let inside = std::f64::consts::PI * (radius / ps).powi(2);
    let every = (inside / BALL_POINTS).floor().max(1.0) as u64;
    Geometry {
        spacing,
        radius,
        every,
    }
}

/// Whether the point at `p` is in the subset of one in `every` (a hash of its coordinates: the
/// same point is chosen in every tile that holds it).
fn chosen(p: &Point3, every: u64) -> bool {
    if every <= 1 {
        return true;
    }
    let mut h = crate::rng::SplitMix64::new(
        p[0].to_bits() ^ p[1].to_bits().rotate_left(21) ^ p[2].to_bits().rotate_left(42),
    );
    h.next_u64().is_multiple_of(every)
}

/// The progress line of the field and orient units (the tiles' points, as they are sampled).
pub(crate) const LINE: Line = Line {
    name: "orientation",
    counts: "points",
    total: Total::Unknown,
};

/// The before surveys whose orientation field the plan computes: with `--orientation auto`,
/// every survey that is some pair's before survey, once each, in order; else none.
pub(crate) fn befores(plan: &crate::plan::Plan) -> Vec<usize> {
    if plan.params.m3c2().orientation != Orientation::Auto {
        return Vec::new();
    }
    let mut b: Vec<usize> = plan.pairs.iter().map(|q| q.before).collect();
    b.sort_unstable();
    b.dedup();
    b
}

/// A sample point: its cell's key, its position (global) and its normal (unoriented).
pub(crate) type SamplePoint = (u64, Point3, Point3);

/// The orientation field's sample of a tile of a before survey.
pub(crate) struct FieldStage;

/// What a field unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct FieldMeta {
    /// The tile's sample points.
    pub(crate) points: usize,
}

impl Stage for FieldStage {
    const KIND: &'static str = "field";
    const SCOPE: Scope = Scope::SurveyTile;
    const VERSION: u32 = 1;
    const INTERMEDIATE: bool = true;
    const LINE: Line = LINE;
    type Meta = FieldMeta;

    /// With `--orientation auto`: one per tile of every survey that is some pair's before
    /// survey, over the units holding its tiles.
    fn plan(p: &mut Planner) -> Result<()> {
        let befores = befores(p.plan);
        if befores.is_empty() {
            return Ok(());
        }
        let grid = p.plan.layout.grid()?;
        for s in befores {
            let key = geometry(p.plan, s).key(p.plan);
            let deps = p.survey_tiles(s)?;
            let label = p.plan.surveys[s].label.clone();
            for t in grid.tiles() {
                p.add(
                    Spec::survey_tile(Self::KIND, s, t),
                    &format!("{label}-{}", t.name()),
                    &[&key],
                    deps.clone(),
                );
            }
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<FieldMeta> {
        let (s, id) = (ctx.survey(unit)?, ctx.tile(unit)?);
        let sample = sample_tile(ctx, s, id)?;
        write(out, &sample)?;
        Ok(FieldMeta {
            points: sample.len(),
        })
    }
}

/// The sample points of tile `id` of survey `s`, in the order of their cells' keys.
fn sample_tile(ctx: &Ctx, s: usize, id: talus_tiling::TileId) -> Result<Vec<SamplePoint>> {
    let plan = ctx.plan;
    let g = geometry(plan, s);
    let (tiling, meta) = ctx.tiles(s)?;
    let grid = plan.layout.grid()?;
    let anchor = plan.layout.anchor;
    let n = meta.tile_points[grid.index(id)];
    if n == 0 {
        return Ok(Vec::new());
    }
    let _held = ctx.reserve(
        n * BYTES_PER_POINT + crate::memory::HEADROOM,
        &format!("the orientation field: tile {} ({n} points)", id.name()),
    )?;
    let t = read_tile(ctx, &tiling, id)?;
    // A cell belongs to the tile holding its centre, which holds all of it (the halo is wider
    // than half a cell): its point is the one nearest its centre among all the survey's,
    // whichever tile owns each of them.
    let square = super::m3c2::open_box(&grid, id, 0.0);
    let centre_inside = |p: &Point3| {
        let c = crate::m3c2::core_points::cell_of(p, &anchor, g.spacing);
        let x = anchor[0] + (c[0] as f64 + 0.5) * g.spacing;
        let y = anchor[1] + (c[1] as f64 + 0.5) * g.spacing;
        x >= square[0] && x < square[2] && y >= square[1] && y < square[3]
    };
    let cells = crate::m3c2::core_points::thin(
        t.len(),
        |i| t.point(i),
        &anchor,
        g.spacing,
        |i| centre_inside(&t.point(i)),
    );
    let subset: Vec<Point3> = (0..t.len())
        .map(|i| t.point(i))
        .filter(|p| chosen(p, g.every))
        .collect();
    let index = Columns::new(&subset, anchor, g.radius);
    let mut found: Vec<SamplePoint> = cells
        .par_iter()
        .filter_map(|&(key, i)| {
            let p = t.point(i);
            let (n, spread) = normal_at(&index, &index.to_local(&p), g.radius)?;
            // Not a surface at the field's scale (an edge, a crest, a cleft): its normal would
            // carry a tilt the surface does not have.
            (spread <= field::FLAT).then_some((key, p, n))
        })
        .collect();
    found.sort_by_key(|s| s.0);
    (ctx.progress)(t.len() as u64);
    Ok(found)
}

/// The columns of a sample with normals `normals` (one per point): x, y, z and `normal_x`,
/// `normal_y`, `normal_z` (a field unit's unoriented ones, an orient unit's oriented ones).
pub(crate) fn columns(sample: &[SamplePoint], normals: &[Point3]) -> TileColumns {
    let f = |name: &str, k: usize| Column {
        name: name.into(),
        data: ColumnData::F64(normals.iter().map(|n| n[k]).collect()),
    };
    TileColumns {
        x: sample.iter().map(|s| s.1[0]).collect(),
        y: sample.iter().map(|s| s.1[1]).collect(),
        z: sample.iter().map(|s| s.1[2]).collect(),
        extra: vec![f("normal_x", 0), f("normal_y", 1), f("normal_z", 2)],
    }
}

/// Write a tile's sample: positions, normals, and each cell's key as two 32-bit halves.
fn write(out: &mut UnitWriter, sample: &[SamplePoint]) -> Result<()> {
    let normals: Vec<Point3> = sample.iter().map(|s| s.2).collect();
    let mut cols = columns(sample, &normals);
    let u = |name: &str, v: Vec<u32>| Column {
        name: name.into(),
        data: ColumnData::U32(v),
    };
    cols.extra.push(u(
        "key_hi",
        sample.iter().map(|s| (s.0 >> 32) as u32).collect(),
    ));
    cols.extra
        .push(u("key_lo", sample.iter().map(|s| s.0 as u32).collect()));
    super::write_columns(out, FILE, &cols)
}

/// The sample of field unit `u`, as [`FieldStage`] wrote it.
pub(crate) fn read(ctx: &Ctx, u: usize) -> Result<Vec<SamplePoint>> {
    let c = super::read_columns(ctx, u, FILE)?;
    let path = ctx.input(u, FILE)?;
    let damaged = |what: &str| Error::Damaged {
        path: path.clone(),
        problem: format!("no column {what}"),
    };
    let f = |name: &str| match c.column(name) {
        Some(ColumnData::F64(v)) if v.len() == c.len() => Ok(v),
        _ => Err(damaged(name)),
    };
    let k = |name: &str| match c.column(name) {
        Some(ColumnData::U32(v)) if v.len() == c.len() => Ok(v),
        _ => Err(damaged(name)),
    };
    let (hi, lo) = (k("key_hi")?, k("key_lo")?);
    let (nx, ny, nz) = (f("normal_x")?, f("normal_y")?, f("normal_z")?);
    Ok((0..c.len())
        .map(|i| {
            (
                (u64::from(hi[i]) << 32) | u64::from(lo[i]),
                [c.x[i], c.y[i], c.z[i]],
                [nx[i], ny[i], nz[i]],
            )
        })
        .collect())
}
