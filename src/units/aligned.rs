//! A later survey tiled again in the first survey's frame, when its alignment applies: its route
//! onto the first survey — its own fit, or a chain through its predecessors
//! ([`crate::events::chain`]) — chosen from the align units ([`super::align`]) of every survey up
//! to it, and recorded (`route.json`); every point mapped by the route's matrix and rounded to
//! its file's coordinate quantum (so that the tiles keep their exact integer encoding), cut into
//! the same layout — a survey tiled in parts by a unit per part. When the alignment does not
//! apply, the unit writes no tile and the survey's own tiling is read in its place
//! ([`super::Ctx::tiling`]): everything after it is then the same bytes as with `--align off`.

use serde::{Deserialize, Serialize};

use super::align::AlignStage;
use super::stage::{Line, Planner, Scope, Stage, TilesOf, Total};
use super::tiling::{split_part, TilingMeta};
use super::Ctx;
use crate::error::Result;
use crate::events::chain::{routes, Route};
use crate::plan::Spec;
use crate::store::UnitWriter;

/// The file of an aligned unit: its [`Route`].
pub(crate) const FILE: &str = "route.json";

/// A survey in the first survey's frame.
pub(crate) struct AlignedStage;

/// What an aligned-tiling unit records: the tiling's, when the alignment applied.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct AlignedMeta {
    pub(crate) applied: bool,
    pub(crate) tiling: Option<TilingMeta>,
}

impl Stage for AlignedStage {
    const KIND: &'static str = "aligned";
    const SCOPE: Scope = Scope::Survey;
    const VERSION: u32 = 1;
    const INTERMEDIATE: bool = true;
    const KEPT: &'static [&'static str] = &[FILE];
    const LINE: Line = Line {
        name: "alignment",
        counts: "core points sampled",
        total: Total::Unknown,
    };
    type Meta = AlignedMeta;
    /// Its tiles hold the survey only where the alignment applied (else it wrote none).
    const TILES: Option<TilesOf<AlignedMeta>> = Some(|m| m.tiling.clone().filter(|_| m.applied));

    /// One per survey with an align unit — or one per part where the survey is tiled in parts
    /// (`super::tiling::parts`: each part tiled again by a task of its own, as it was tiled) —
    /// over the align units of every survey up to it (its route may pass through them) and the
    /// survey's own tiling.
    fn plan(p: &mut Planner) -> Result<()> {
        let mut aligns = Vec::new();
        for s in 0..p.plan.surveys.len() {
            let Some(align) = p.find(&Spec::survey(AlignStage::KIND, s)) else {
                continue;
            };
            aligns.push(align);
            let mut deps = aligns.clone();
            deps.extend(p.tiling_units(s)?);
            let label = p.plan.surveys[s].label.clone();
            let parts = super::tiling::parts(p.plan, s);
            if parts.is_empty() {
                p.add(Spec::survey(Self::KIND, s), &label, &[], deps.clone());
            }
            for (k, part) in parts.iter().enumerate() {
                let range = format!("points {}..{}", part.start, part.end);
                p.add(
                    Spec::survey_part(Self::KIND, s, k as u32),
                    &format!("{label}-p{k}"),
                    &[&range],
                    deps.clone(),
                );
            }
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<AlignedMeta> {
        let s = ctx.survey(unit)?;
        let fits = (0..=s)
            .map(|k| super::align::read(ctx, k))
            .collect::<Result<Vec<_>>>()?;
        let Some(route) = routes(&fits).pop().flatten() else {
            return Ok(AlignedMeta {
                applied: false,
                tiling: None,
            });
        };
        super::write_json(out, FILE, &route)?;
        let a = &route.alignment;
        if !a.applied {
            return Ok(AlignedMeta {
                applied: false,
                tiling: None,
            });
        }
        let m = a.matrix();
        let quantum = ctx.quantum(s)?;
        let map = move |pts: &mut [crate::geom::Point3]| {
            for p in pts.iter_mut() {
                let q: [f64; 3] = std::array::from_fn(|i| {
                    m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3]
                });
                *p = match quantum {
                    // The decoder's own expression: scale · record + offset.
                    Some(t) => std::array::from_fn(|i| {
                        let [scale, offset] = t[i];
                        scale * ((q[i] - offset) / scale).round() + offset
                    }),
                    None => q,
                };
            }
        };
        // A part of the survey: its range, as its tiling part read it.
        let part = match ctx.plan.units[unit].spec.part {
            Some(k) => Some(
                *super::tiling::parts(ctx.plan, s)
                    .get(k as usize)
                    .ok_or_else(|| {
                        crate::error::Error::Internal(format!("survey {s} has no part {k}"))
                    })?,
            ),
            None => None,
        };
        let tiling = split_part(ctx, s, part, Some(&map), out)?;
        Ok(AlignedMeta {
            applied: true,
            tiling: Some(tiling),
        })
    }
}

/// The route of survey `s` onto the first (its aligned unit must be done — or its first part:
/// every part records the same route), if it has one.
pub(crate) fn route(ctx: &Ctx, s: usize) -> Result<Option<Route>> {
    match ctx.plan.survey_units(AlignedStage::KIND, s).first() {
        Some(&u) => Ok(Some(super::read_json(ctx, u, FILE)?)),
        None => Ok(None),
    }
}
