//! The orientation field of a survey that is a pair's before survey (`--orientation auto`): its
//! surface sampled coarsely, tile by tile ([`super::field`]), the sample oriented once for the
//! whole survey ([`crate::m3c2::field`]), and read by every M3C2 unit of its pairs, which turn
//! each core point's normal to agree with it. So the outside of a face is decided from the
//! whole surface it belongs to — a beach in front, a plateau behind, or the face's own lean —
//! and a tile never decides it from the part it happens to hold.
//!
//! The field's spacing keeps the sample below [`super::field::FIELD_MAX`] points however large
//! the survey: this unit holds the sample and its spanning tree, never the survey's points.

use serde::{Deserialize, Serialize};
use talus_tiling::{Column, ColumnData};

use super::field::{self as sample, FieldStage, SamplePoint};
use super::stage::{Line, Planner, Scope, Stage};
use super::Ctx;
use crate::error::{Error, Result};
use crate::geom::Point3;
use crate::m3c2::field::{self, Field, Part};
use crate::plan::Spec;
use crate::store::UnitWriter;

/// The file of an orient unit: the oriented sample.
pub(crate) const FILE: &str = "field.tile";

/// Resident bytes per sample point while it is oriented: the sample (56), its local copy and
/// normals (48), the graph and spanning tree (≈ 40 MB at `FIELD_MAX` points, see there).
const BYTES_PER_SAMPLE: u64 = 256;

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
    const LINE: Line = sample::LINE;
    type Meta = OrientMeta;

    /// With `--orientation auto`: one per survey that is some pair's before survey, over its
    /// tiles' samples.
    fn plan(p: &mut Planner) -> Result<()> {
        let befores = sample::befores(p.plan);
        if befores.is_empty() {
            return Ok(());
        }
        let grid = p.plan.layout.grid()?;
        for s in befores {
            let key = sample::geometry(p.plan, s).key(p.plan);
            let deps = grid
                .tiles()
                .map(|t| p.the(&Spec::survey_tile(FieldStage::KIND, s, t)))
                .collect::<Result<Vec<usize>>>()?;
            let label = p.plan.surveys[s].label.clone();
            p.add(Spec::survey(Self::KIND, s), &label, &[&key], deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<OrientMeta> {
        let plan = ctx.plan;
        let s = ctx.survey(unit)?;
        let g = sample::geometry(plan, s);
        let anchor = plan.layout.anchor;
        let fields: Vec<usize> = plan.units[unit].deps.clone();
        // Reserved before anything is read: the tiles' samples' sizes are in their records.
        let n = fields
            .iter()
            .map(|&u| Ok(ctx.meta::<FieldStage>(u)?.points as u64))
            .sum::<Result<u64>>()?;
        let _held = ctx.reserve(
            n * BYTES_PER_SAMPLE + crate::memory::HEADROOM,
            &format!("the orientation field: {n} sample points"),
        )?;
        let mut sample: Vec<SamplePoint> = Vec::with_capacity(n as usize);
        for &u in &fields {
            sample.extend(sample::read(ctx, u)?);
            crate::interrupt::check()?;
        }
        // Each cell is one tile's (the one holding its centre): the keys are distinct, and the
        // sample is in one order whatever the tiling.
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
    sample: &[SamplePoint],
    normals: &[Point3],
    decided: &[bool],
) -> Result<()> {
    let mut cols = sample::columns(sample, normals);
    cols.extra.push(Column {
        name: "decided".into(),
        data: ColumnData::U8(decided.iter().map(|&d| d as u8).collect()),
    });
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
