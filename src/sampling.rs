//! Measured point spacing: the median nearest-neighbour distance of a cloud, the length every
//! derived parameter starts from (see [`crate::params`]).
//!
//! A cloud of up to [`WHOLE`] points is measured whole. A larger one is measured in a square
//! window at the centre of its footprint, sized from the mean density to hold about
//! `WINDOW_TARGET` points (grown when it falls on a hole, shrunk when it is denser than
//! expected): each try is one streaming pass, so memory stays bounded whatever the file's size
//! and point order. Only points in the inner half of the window are measured, so that their
//! nearest neighbour is inside the window. Exact duplicates are measured once (see `distinct`).

use std::path::Path;

use crate::error::{Error, Result};
use crate::io::classes::{ClassCounts, Classes};
use crate::io::{self, Bounds, Point3};
use crate::spatial::{DensityGrid, Index};

/// The version of what [`measure`] returns for a file: a store's cached measurements of another
/// version are measured again (`plan::measured::cached_spacing`). Change it with the measurement.
pub(crate) const METHOD: u32 = 1;

/// Clouds up to this many points are measured whole.
pub const WHOLE: u64 = 400_000;
/// Points a window aims for.
pub(crate) const WINDOW_TARGET: f64 = 40_000.0;

/// The measured spacing and how it was measured.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Spacing {
    /// Median nearest-neighbour distance.
    pub spacing: f64,
    /// Median local surface density (points per unit²), from the distance r₁₀ to the 10th
    /// neighbour: 10 / (π r₁₀²).
    pub density: f64,
    /// 1 / √density: the side of the square one point covers. This, not the nearest-neighbour
    /// distance, is what the parameter rules start from: for randomly placed points the median
    /// nearest-neighbour distance is only ≈ 0.47 / √density, for a grid it is 1 / √density, so
    /// rules on it would give twice the points per cylinder on a grid as on a random cloud.
    pub effective_spacing: f64,
    /// Points whose nearest-neighbour distance entered the median.
    pub measured_points: usize,
    pub method: String,
}

/// What `measure` finds in a cloud.
pub struct Measured {
    pub spacing: Spacing,
    /// Points per XY cell, counted on the way (one of the passes reads every point anyway).
    pub density: DensityGrid,
    /// With a class filter on a LAS/LAZ file: its points per class and those left out (from the
    /// same pass).
    pub classes: Option<ClassCounts>,
    /// The file's header, as its reader gave it.
    pub info: io::CloudInfo,
}

/// Measure the point spacing of the cloud at `path` over the points of the classes `classes`
/// keeps (those a comparison uses).
pub(crate) fn measure(path: &Path, classes: Option<&Classes>) -> Result<Measured> {
    measure_keeping(path, classes, &mut |_| {})
}

/// `measure`, handing `keep` every point the pass over the whole file delivers, in the order
/// the reader delivers them (for [`io::replay`]: the tiling then need not decode the file again).
/// When this returns `Ok`, `keep` has seen them all, once.
pub fn measure_keeping(
    path: &Path,
    classes: Option<&Classes>,
    keep: &mut dyn FnMut(&[Point3]),
) -> Result<Measured> {
    measure_opened(path, classes, &|| io::open_with(path, classes), keep)
}

/// [`measure_keeping`] of the cloud `open` delivers, from its start each time it is called (a
/// file's reader, or points already in memory: the Python bindings measure numpy arrays so, and
/// get the spacing a file of the same points gives); `path` names the cloud in errors, `classes`
/// what `open` keeps of it.
pub fn measure_opened<'a>(
    path: &Path,
    classes: Option<&Classes>,
    open: &dyn Fn() -> Result<Box<dyn io::PointReader + 'a>>,
    keep: &mut dyn FnMut(&[Point3]),
) -> Result<Measured> {
    measure_in(classes, open, keep)?.map_err(|n| {
        Error::input(
            path,
            format!("cannot measure a point spacing: {}", n.problem),
        )
    })
}

/// Why a readable file has no point spacing, with what was read of it (`talus info` describes
/// such a file all the same).
pub(crate) struct NoSpacing {
    /// In the user's terms (after "cannot measure a point spacing: "): the classes compared
    /// leave none of its points (naming those it holds), too few distinct positions,
    /// coordinates so large that distances overflow.
    pub problem: String,
    /// Its points per class (with a class filter on a LAS/LAZ file).
    pub classes: Option<ClassCounts>,
}

/// [`measure`], or why no spacing can be measured on a file that reads (errors reading it stay
/// errors).
pub(crate) fn measure_or_why(
    path: &Path,
    classes: Option<&Classes>,
) -> Result<std::result::Result<Measured, NoSpacing>> {
    measure_in(classes, &|| io::open_with(path, classes), &mut |_| {})
}

fn measure_in<'a>(
    classes: Option<&Classes>,
    open: &dyn Fn() -> Result<Box<dyn io::PointReader + 'a>>,
    keep: &mut dyn FnMut(&[Point3]),
) -> Result<std::result::Result<Measured, NoSpacing>> {
    let mut reader = open()?;
    let info = reader.info().clone();
    if info.point_count <= WHOLE {
        let mut all = Vec::with_capacity(info.point_count as usize);
        let mut buf = Vec::new();
        while reader.fill(&mut buf, 1 << 16)? > 0 {
            keep(&buf);
            all.extend_from_slice(&buf);
        }
        let mut grid = DensityGrid::new(&info.bounds);
        grid.add(&all);
        let origin = all.first().copied().unwrap_or_default();
        let kept = all.len();
        distinct(&mut all);
        let probes: Vec<usize> = (0..all.len()).collect();
        let index = Index::new(&all, origin);
        let counts = reader.class_counts();
        let Some((s, density)) = stats(&index, &probes) else {
            let problem = unmeasurable(classes, counts.as_ref(), kept, all.len(), "");
            return Ok(Err(NoSpacing {
                problem,
                classes: counts,
            }));
        };
        if let Some(problem) = overflow(&info, 1.0 / density.sqrt()) {
            return Ok(Err(NoSpacing {
                problem,
                classes: counts,
            }));
        }
        let spacing = Spacing {
            spacing: s,
            density,
            effective_spacing: 1.0 / density.sqrt(),
            measured_points: all.len(),
            method: "over all points".into(),
        };
        return Ok(Ok(Measured {
            spacing,
            density: grid,
            classes: counts,
            info,
        }));
    }
    drop(reader);
    let b = info.bounds;
    let (cx, cy) = ((b.min[0] + b.max[0]) / 2.0, (b.min[1] + b.max[1]) / 2.0);
    let area = footprint_area(&b);
    let density = info.point_count as f64 / area;
    let mut half = 0.5 * (WINDOW_TARGET / density).sqrt();
    let max_half = 0.5 * (b.max[0] - b.min[0]).max(b.max[1] - b.min[1]) + 1.0;
    // The first pass reads the whole file, whatever the window holds, for the density grid and
    // the class counts.
    let mut whole = (DensityGrid::new(&b), None);
    let mut counting = Some((&mut whole, keep));
    for _ in 0..12 {
        let pts = window(
            open,
            cx,
            cy,
            half,
            8 * WINDOW_TARGET as usize,
            counting.take(),
        )?;
        match pts {
            None => half /= 2.0, // denser than expected: shrink
            Some(pts) if pts.len() < 1000 && half < max_half => half *= 3.0,
            Some(mut pts) => {
                let origin = [cx, cy, pts.first().map_or(0.0, |p| p[2])];
                distinct(&mut pts);
                let inner: Vec<usize> = (0..pts.len())
                    .filter(|&i| {
                        (pts[i][0] - cx).abs() <= half / 2.0 && (pts[i][1] - cy).abs() <= half / 2.0
                    })
                    .collect();
                let index = Index::new(&pts, origin);
                let measured = stats(&index, &inner);
                let problem = match measured {
                    None => Some(unmeasurable(
                        classes,
                        whole.1.as_ref(),
                        0,
                        inner.len(),
                        " in a window at the footprint's centre",
                    )),
                    Some((_, density)) => overflow(&info, 1.0 / density.sqrt()),
                };
                let (Some((s, density)), None) = (measured, problem.clone()) else {
                    return Ok(Err(NoSpacing {
                        problem: problem.unwrap_or_default(),
                        classes: whole.1,
                    }));
                };
                let spacing = Spacing {
                    spacing: s,
                    density,
                    effective_spacing: 1.0 / density.sqrt(),
                    measured_points: inner.len(),
                    method: format!(
                        "in a {:.3} × {:.3} window at the footprint's centre",
                        2.0 * half,
                        2.0 * half
                    ),
                };
                let (density, classes) = whole;
                return Ok(Ok(Measured {
                    spacing,
                    density,
                    classes,
                    info,
                }));
            }
        }
    }
    let problem = unmeasurable(
        classes,
        whole.1.as_ref(),
        0,
        0,
        " near the footprint's centre",
    );
    Ok(Err(NoSpacing {
        problem,
        classes: whole.1,
    }))
}

/// Distinct positions a point spacing needs: a point and its 10 nearest neighbours.
pub(crate) const MIN_DISTINCT: usize = 11;

/// Why no spacing could be measured on `path`, in the user's terms: the classes compared leave
/// none of its points (naming the classes it holds), or too few distinct positions are left
/// (`kept` points of the classes compared, `distinct` positions among them, `where` they were
/// looked for).
fn unmeasurable(
    classes: Option<&Classes>,
    counts: Option<&ClassCounts>,
    kept: usize,
    distinct: usize,
    place: &str,
) -> String {
    if let (Some(c), Some(counts)) = (classes, counts) {
        if counts.kept() == 0 {
            return counts.none_kept(c);
        }
    }
    // "of the classes compared" only where classes were read and some left out.
    let of = if counts.is_some_and(|c| c.left_out() > 0) {
        " of the classes compared"
    } else {
        ""
    };
    let held = match kept {
        0 => format!("points{of}{place} at {distinct} distinct position(s)"),
        k if k == distinct => format!("{k} point(s){of}{place}"),
        k => format!("{k} points{of}{place} at only {distinct} distinct position(s)"),
    };
    format!(
        "{held}; it needs at least {MIN_DISTINCT} distinct positions (a point and its 10 nearest \
         neighbours)"
    )
}

/// A spacing that is not a positive finite length comes from coordinates so large that the
/// distances between points overflow: said so (an input error naming the file), never a number
/// passed on.
fn overflow(info: &io::CloudInfo, effective: f64) -> Option<String> {
    if effective.is_finite() && effective > 0.0 {
        return None;
    }
    let b = &info.bounds;
    let largest = b
        .min
        .iter()
        .chain(&b.max)
        .fold(0.0f64, |m, v| m.max(v.abs()));
    Some(format!(
        "coordinates as large as {} make the distances between points overflow; are they in \
         metres (or another length unit)?",
        crate::geom::show(largest)
    ))
}

/// Keep one of each set of exactly coincident points: a cloud stored twice over (merged flight
/// lines, an export repeated) has the spacing of its distinct positions, not zero.
fn distinct(points: &mut Vec<Point3>) {
    points.sort_unstable_by(|a, b| {
        a[0].total_cmp(&b[0])
            .then(a[1].total_cmp(&b[1]))
            .then(a[2].total_cmp(&b[2]))
    });
    points.dedup();
}

/// Median nearest-neighbour distance and median local density over the `probes` of `index`.
fn stats(index: &Index, probes: &[usize]) -> Option<(f64, f64)> {
    use rayon::prelude::*;
    let per: Vec<(f64, f64)> = probes
        .par_iter()
        .filter_map(|&i| {
            let q = index.points()[i];
            let nn = index.nearest(&q, 11);
            let d1 = nn.get(1)?.1.sqrt();
            let r10 = nn.get(10)?.1;
            (r10 > 0.0).then(|| (d1, 10.0 / (std::f64::consts::PI * r10)))
        })
        .collect();
    if per.is_empty() {
        return None;
    }
    let median = |mut v: Vec<f64>| {
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
    };
    let s = median(per.iter().map(|p| p.0).collect());
    let density = median(per.iter().map(|p| p.1).collect());
    (s > 0.0 && density.is_finite()).then_some((s, density))
}

/// Area of the footprint: the two largest extents (a vertical wall has no XY area).
fn footprint_area(b: &Bounds) -> f64 {
    let mut e = [
        b.max[0] - b.min[0],
        b.max[1] - b.min[1],
        b.max[2] - b.min[2],
    ];
    e.sort_by(|a, b| b.total_cmp(a));
    (e[0] * e[1]).max(1e-12)
}

/// What the pass over the whole file fills: the density grid and class counts, and the keeper
/// of its points.
type Whole<'a, 'k> = (
    &'a mut (DensityGrid, Option<ClassCounts>),
    &'a mut (dyn FnMut(&[Point3]) + 'k),
);

/// The points within the XY window, or None when more than `cap` fall in it; every point of
/// the file counted into `whole`'s grid and handed to its keeper when given (then the whole file
/// is read, and its class counts recorded there).
fn window<'a>(
    open: &dyn Fn() -> Result<Box<dyn io::PointReader + 'a>>,
    cx: f64,
    cy: f64,
    half: f64,
    cap: usize,
    mut whole: Option<Whole<'_, '_>>,
) -> Result<Option<Vec<Point3>>> {
    let mut reader = open()?;
    let mut buf = Vec::new();
    let mut out = Vec::new();
    let mut over = false;
    while reader.fill(&mut buf, 1 << 16)? > 0 {
        if let Some(((g, _), keep)) = whole.as_mut() {
            g.add(&buf);
            keep(&buf);
        }
        if over {
            continue;
        }
        for p in &buf {
            if (p[0] - cx).abs() <= half && (p[1] - cy).abs() <= half {
                out.push(*p);
                if out.len() > cap {
                    over = true;
                    out = Vec::new();
                    break;
                }
            }
        }
        if over && whole.is_none() {
            return Ok(None);
        }
    }
    if let Some(((_, c), _)) = whole {
        *c = reader.class_counts();
    }
    Ok((!over).then_some(out))
}
