//! The orientation field of a survey that is a pair's before survey (`--orientation auto`): its
//! surface sampled coarsely, the sample oriented once for the whole survey
//! ([`crate::m3c2::field`]), and read by every M3C2 unit of its pairs, which turn each core
//! point's normal to agree with it. So the outside of a face is decided from the whole
//! surface it belongs to — a beach in front, a plateau behind, or the face's own lean — and a
//! tile never decides it from the part it happens to hold.
//!
//! The sample: the survey's points thinned to one per cubic cell of the field spacing on the
//! run's anchor, each cell by the tile holding its centre (the same points whatever the tiling),
//! each with a normal over M3C2's normal ball from a subset of the tile's points chosen by a hash
//! of their coordinates (so also the same whatever the tiling). The field's spacing keeps the
//! sample below [`FIELD_MAX`] points however large the survey; a sample point whose
//! neighbourhood is no surface at that scale (an edge, a crest) is left out
//! ([`field::FLAT`]).

use serde::{Deserialize, Serialize};
use talus_tiling::{Column, ColumnData, TileColumns};

use super::stage::{Line, Planner, Scope, Stage, Total};
use super::{read_tile, Ctx};
use crate::error::{Error, Result};
use crate::geom::Point3;
use crate::m3c2::field::{self, Field, Part};
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

/// The file of an orient unit: the oriented sample.
pub(crate) const FILE: &str = "field.tile";

/// The geometry of a survey's field: its cell, its normals' radius and the share of points
/// they are fitted to (one in `every`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Geometry {
    pub(crate) spacing: f64,
    pub(crate) radius: f64,
    pub(crate) every: u64,
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

/// The orientation field of a before survey.
pub(crate) struct OrientStage;

/// What an orient unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct OrientMeta {
    /// Sample points, and those in parts whose sign the data does not decide.
    pub(crate) points: usize,
    pub(crate) undecided: usize,
    pub(crate) spacing: f64,
    pub(crate) radius: f64,
    /// The connected parts of the sample, largest first (at most ten).
    pub(crate) parts: Vec<Part>,
    /// How many parts in all.
    pub(crate) part_count: usize,
}

impl Stage for OrientStage {
    const KIND: &'static str = "orient";
    const SCOPE: Scope = Scope::Survey;
    const VERSION: u32 = 1;
    const INTERMEDIATE: bool = true;
    const LINE: Line = Line {
        name: "orientation",
        counts: "points",
        total: Total::Unknown,
    };
    type Meta = OrientMeta;

    /// With `--orientation auto`: one per survey that is some pair's before survey, over the
    /// units holding its tiles.
    fn plan(p: &mut Planner) -> Result<()> {
        if p.plan.params.m3c2().orientation != Orientation::Auto {
            return Ok(());
        }
        let mut befores: Vec<usize> = p.plan.pairs.iter().map(|q| q.before).collect();
        befores.sort_unstable();
        befores.dedup();
        for s in befores {
            let g = geometry(p.plan, s);
            let key = format!(
                "field 1|{}|{}|{}|{}",
                g.spacing, g.radius, g.every, p.plan.layout.anchor[0]
            );
            let deps = p.survey_tiles(s)?;
            let label = p.plan.surveys[s].label.clone();
            p.add(Spec::survey(Self::KIND, s), &label, &[&key], deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<OrientMeta> {
        let plan = ctx.plan;
        let s = ctx.survey(unit)?;
        let g = geometry(plan, s);
        let (tiling, meta) = ctx.tiles(s)?;
        let grid = plan.layout.grid()?;
        let anchor = plan.layout.anchor;
        let mut sample: Vec<(u64, Point3, Point3)> = Vec::new();
        for id in grid.tiles() {
            let n = meta.tile_points[grid.index(id)];
            if n == 0 {
                continue;
            }
            let _held = ctx.reserve(
                n * BYTES_PER_POINT + crate::memory::HEADROOM,
                &format!("the orientation field: tile {} ({n} points)", id.name()),
            )?;
            let t = read_tile(ctx, tiling, id)?;
            // A cell belongs to the tile holding its centre, which holds all of it (the halo is
            // wider than half a cell): its point is the one nearest its centre among all the
            // survey's, whichever tile owns each of them.
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
            use rayon::prelude::*;
            let found: Vec<(u64, Point3, Point3)> = cells
                .par_iter()
                .filter_map(|&(key, i)| {
                    let p = t.point(i);
                    let (n, spread) = normal_at(&index, &index.to_local(&p), g.radius)?;
                    // Not a surface at the field's scale (an edge, a crest, a cleft): its normal
                    // would carry a tilt the surface does not have.
                    (spread <= field::FLAT).then_some((key, p, n))
                })
                .collect();
            sample.extend(found);
            (ctx.progress)(t.len() as u64);
            crate::interrupt::check()?;
        }
        sample.sort_by_key(|s| s.0);
        let points: Vec<Point3> = sample
            .iter()
            .map(|s| [s.1[0] - anchor[0], s.1[1] - anchor[1], s.1[2] - anchor[2]])
            .collect();
        let normals: Vec<Point3> = sample.iter().map(|s| s.2).collect();
        let o = field::orient(&points, &normals, g.spacing);
        let decided: Vec<bool> = o
            .part
            .iter()
            .map(|&k| o.parts[k as usize].decided)
            .collect();
        write(out, &sample, &o.normals, &decided)?;
        let mut parts = o.parts.clone();
        parts.sort_by_key(|p| std::cmp::Reverse(p.points));
        let part_count = parts.len();
        parts.truncate(10);
        Ok(OrientMeta {
            points: sample.len(),
            undecided: decided.iter().filter(|d| !**d).count(),
            spacing: g.spacing,
            radius: g.radius,
            parts,
            part_count,
        })
    }
}

fn write(
    out: &mut UnitWriter,
    sample: &[(u64, Point3, Point3)],
    normals: &[Point3],
    decided: &[bool],
) -> Result<()> {
    let f = |name: &str, v: Vec<f64>| Column {
        name: name.into(),
        data: ColumnData::F64(v),
    };
    let cols = TileColumns {
        x: sample.iter().map(|s| s.1[0]).collect(),
        y: sample.iter().map(|s| s.1[1]).collect(),
        z: sample.iter().map(|s| s.1[2]).collect(),
        extra: vec![
            f("normal_x", normals.iter().map(|n| n[0]).collect()),
            f("normal_y", normals.iter().map(|n| n[1]).collect()),
            f("normal_z", normals.iter().map(|n| n[2]).collect()),
            Column {
                name: "decided".into(),
                data: ColumnData::U8(decided.iter().map(|&d| d as u8).collect()),
            },
        ],
    };
    super::write_columns(out, FILE, &cols)
}

/// The orientation field of pair `pair`'s before survey near the box `near` ([x0, y0, x1, y1],
/// global), in the local frame of `anchor`; None when the plan has no field (an orientation
/// other than `auto`).
pub(crate) fn read_near(
    ctx: &Ctx,
    pair: usize,
    near: [f64; 4],
    anchor: Point3,
) -> Result<Option<Field>> {
    let s = ctx.plan.pairs[pair].before;
    let Some(u) = ctx.plan.find(&Spec::survey(OrientStage::KIND, s)) else {
        return Ok(None);
    };
    let spacing = ctx.meta::<OrientStage>(u)?.spacing;
    let c = super::read_columns(ctx, u, FILE)?;
    let path = ctx.input(u, FILE)?;
    let damaged = |what: &str| Error::Damaged {
        path: path.clone(),
        problem: format!("no column {what}"),
    };
    let f = |name: &str| match c.column(name) {
        Some(ColumnData::F64(v)) => Ok(v),
        _ => Err(damaged(name)),
    };
    let (nx, ny, nz) = (f("normal_x")?, f("normal_y")?, f("normal_z")?);
    let decided = match c.column("decided") {
        Some(ColumnData::U8(v)) => v,
        _ => return Err(damaged("decided")),
    };
    let grow = field::REACH * spacing;
    let (mut pts, mut ns, mut ds) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..c.len() {
        let (x, y) = (c.x[i], c.y[i]);
        if x < near[0] - grow || x > near[2] + grow || y < near[1] - grow || y > near[3] + grow {
            continue;
        }
        pts.push([x - anchor[0], y - anchor[1], c.z[i] - anchor[2]]);
        ns.push([nx[i], ny[i], nz[i]]);
        ds.push(decided[i] == 1);
    }
    Ok(Some(Field::new(pts, ns, ds, spacing)))
}
