//! M3C2: multiscale model-to-model cloud comparison (Lague, Brodu & Leroux 2013), as SPEC.md §1
//! defines it: a normal per core point, then the signed distance between the two epochs' mean
//! positions inside a cylinder along that normal, with its level of detection (LoD95).

pub(crate) mod core_points;
pub mod cylinder;
pub(crate) mod field;
pub(crate) mod moments;
pub mod normals;
pub(crate) mod orientation;
pub(crate) mod reach;
pub mod tile;
pub(crate) mod window;

use rayon::prelude::*;

use crate::geom::Point3;
use crate::spatial::Columns;
pub use orientation::Orientation;
pub use reach::{Extent, Reach, Walk};

/// The M3C2 parameters (lengths in the input's units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct M3c2Params {
    pub normal_radius: f64,
    pub cyl_radius: f64,
    pub cyl_halflen: f64,
    /// Fewer points than this in either cylinder → distance NaN.
    pub min_points: u32,
    pub orientation: Orientation,
    /// The effective point spacing (1 / √density): how many points a column holds.
    pub point_spacing: f64,
    /// Where one epoch has no point in the cylinder: search on along the axis (`reach`).
    pub walk: Walk,
}

/// The result at one core point, with PDAL's filters.m3c2 field meanings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoreResult {
    /// `m3c2_distance`: t₂ − t₁ (NaN when not computable).
    pub(crate) distance: f64,
    /// `m3c2_uncertainty`: LoD95 = 1.96 (√(σ₁²/n₁ + σ₂²/n₂) + reg_error). M3C2 computes it with
    /// reg_error 0 (the registration error is measured afterwards, on all the distances:
    /// `events::stable`); [`CoreResult::with_registration`] adds it.
    pub uncertainty: f64,
    /// `m3c2_significant`: |d| > LoD95.
    pub significant: bool,
    pub std_dev1: f64,
    pub std_dev2: f64,
    pub count1: u32,
    pub count2: u32,
    /// Oriented unit normal (NaN when undefined).
    pub normal: Point3,
    /// Whether the distance needed the walk beyond the window, and what came of it.
    pub reach: Reach,
    /// Whether the data decides which side of the surface is out here (the normal's sign, and
    /// so the distance's): false where the orientation field is undecided (a face near vertical
    /// scanned alone) or no field normal near the core point speaks clearly
    /// (`field::Field::orient`).
    pub sign_known: bool,
}

impl Default for CoreResult {
    fn default() -> Self {
        CoreResult::undefined([f64::NAN; 3])
    }
}

impl CoreResult {
    /// The distance as the M3C2 outputs give it: NaN where the other epoch lies beyond the
    /// user's half-length (the walk found it, [`Reach::Beyond`], but the user's cylinder does not
    /// reach it).
    pub fn measured(&self) -> f64 {
        if self.reach == Reach::Beyond {
            f64::NAN
        } else {
            self.distance
        }
    }

    /// The result with the registration error `reg_error` in its LoD95 and significance.
    pub fn with_registration(mut self, reg_error: f64) -> Self {
        if self.distance.is_finite() {
            self.uncertainty += 1.96 * reg_error;
            self.significant = self.distance.abs() > self.uncertainty;
        }
        self
    }

    fn undefined(normal: Point3) -> Self {
        CoreResult {
            distance: f64::NAN,
            uncertainty: f64::NAN,
            significant: false,
            std_dev1: f64::NAN,
            std_dev2: f64::NAN,
            count1: 0,
            count2: 0,
            normal,
            reach: Reach::Window,
            sign_known: true,
        }
    }
}

/// The column width of the M3C2 indexes: the cylinder radius, or half the normal radius if that
/// is smaller, but wide enough for about 16 points a column. Narrower columns fit a query's disc
/// more tightly (fewer points tested for nothing) but cost more columns per query, each with its
/// own bounds and search. Measured with `examples/kernel_cost.rs` (µs per core point, normal +
/// two cylinders): at 100 points per m², normal radius 1.0, cylinder 0.5 × 3.0 (the py4dgeo
/// benchmark), 0.5 m beats 0.35 and 0.7 (5.2 vs 5.7 and 5.6); at 46 points per m², 0.59 and
/// 0.44 × 4.4 (the 120M-point synthetic pair), 0.59 m (16 points a column) beats the radius
/// rule's 0.295 (4 a column): 2.45 vs 3.24; at 0.79 per m², 4.49 and 3.37 × 33.7 (the St
/// Leonards DSM), 4.5 m beats 2.24: 2.20 vs 2.56. The index is exact whatever the width: results
/// do not change with it.
pub fn column_width(params: &M3c2Params) -> f64 {
    let rule = params.cyl_radius.min(0.5 * params.normal_radius);
    if params.point_spacing.is_finite() && params.point_spacing > 0.0 {
        rule.max(4.0 * params.point_spacing)
    } else {
        rule
    }
}

/// A processing order of `cores` along a Z-order curve (cells of size `cell`): consecutive
/// queries then touch the same columns and cache lines, several times faster than a random
/// order (a `--core-points` file may come in any order). Results are scattered back, so the
/// output order is the input order.
fn spatial_order(cores: &[Point3], cell: f64) -> Vec<usize> {
    let mut keyed: Vec<(u64, usize)> = cores
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = [
                (p[0] / cell).floor() as i64,
                (p[1] / cell).floor() as i64,
                (p[2] / cell).floor() as i64,
            ];
            (core_points::morton(&c), i)
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// Run `f` on every core point in spatial order, in parallel; results in input order.
fn in_spatial_order<T: Send + Copy + Default>(
    cores: &[Point3],
    cell: f64,
    f: impl Fn(usize) -> T + Sync + Send,
) -> Vec<T> {
    let order = spatial_order(cores, cell);
    let computed: Vec<T> = order.par_iter().with_min_len(256).map(|&i| f(i)).collect();
    let mut out = vec![T::default(); cores.len()];
    for (k, &i) in order.iter().enumerate() {
        out[i] = computed[k];
    }
    out
}

/// The normals at a set of core points.
pub struct Normals {
    /// Oriented unit normals (NaN where undefined).
    pub normal: Vec<Point3>,
    /// Whether the data decides each one's sign ([`CoreResult::sign_known`]).
    pub(crate) known: Vec<bool>,
    /// Whether each one's neighbourhood is a surface (its smallest eigenvalue at most
    /// [`field::FLAT`] of the three): only a surface's normal is walked beyond the window
    /// ([`reach`]; a post or a spike has no normal to follow).
    pub(crate) surface: Vec<bool>,
}

/// Normals at `cores` (local frame of `before`), oriented as `params.orientation` says (`auto`
/// by `field`, the survey's orientation field near the cores, in their frame).
pub fn normals(
    before: &Columns,
    cores: &[Point3],
    params: &M3c2Params,
    field: Option<&field::Field>,
) -> Normals {
    let fitted: Vec<(Point3, f64)> = in_spatial_order(cores, params.normal_radius, |i| {
        normals::normal_at(before, &cores[i], params.normal_radius)
            .unwrap_or(([f64::NAN; 3], f64::NAN))
    });
    let mut normal: Vec<Point3> = fitted.iter().map(|f| f.0).collect();
    let surface = fitted.iter().map(|f| f.1 <= field::FLAT).collect();
    let known = orientation::orient(
        cores,
        &mut normal,
        before.origin(),
        params.orientation,
        field,
    );
    Normals {
        normal,
        known,
        surface,
    }
}

/// M3C2 at each core point, given its oriented normal and whether its neighbourhood is a
/// surface (`surface`: only those are walked beyond the window). `before` and `after` must share
/// the local frame of `cores`, and hold every point of `extent.held`. Work is split over rayon's
/// pool; the result does not depend on the thread count (each core point is computed alone,
/// with exact sums).
pub(crate) fn distances(
    before: &Columns,
    after: &Columns,
    cores: &[Point3],
    normals: &[Point3],
    surface: &[bool],
    params: &M3c2Params,
    extent: &Extent,
) -> Vec<CoreResult> {
    debug_assert_eq!(before.origin(), after.origin());
    in_spatial_order(cores, params.cyl_radius.max(params.normal_radius), |i| {
        core_result(
            before,
            after,
            &cores[i],
            &normals[i],
            surface[i],
            params,
            extent,
        )
    })
}

/// M3C2 at one core point `q` with oriented normal `n` (of a surface, or not: `surface`).
fn core_result(
    before: &Columns,
    after: &Columns,
    q: &Point3,
    n: &Point3,
    surface: bool,
    params: &M3c2Params,
    extent: &Extent,
) -> CoreResult {
    if !n[0].is_finite() {
        return CoreResult::undefined(*n);
    }
    let (r, h) = (params.cyl_radius, params.cyl_halflen);
    // One surface per cylinder (see `cylinder`): projections split at gaps wider than the
    // cylinder's diameter; C1's group is the core point's, C2's the one nearest to it.
    thread_local! {
        static SCRATCH: std::cell::RefCell<([cylinder::Projections; 2], reach::Scratch)> =
            Default::default();
    }
    SCRATCH.with(|s| {
        let ([p1, p2], walk) = &mut *s.borrow_mut();
        p1.collect(before, q, n, r, h);
        let (c1, span1) = p1.surface(2.0 * r, (0.0, 0.0));
        p2.collect(after, q, n, r, h);
        // Without C1 (the user's core points), C2's surface is the one nearest the core point.
        let near = if c1.count > 0 { span1 } else { (0.0, 0.0) };
        let (c2, span2) = p2.surface(2.0 * r, near);
        let need = params.min_points.max(1);
        let undefined = || CoreResult {
            count1: c1.count,
            count2: c2.count,
            std_dev1: c1.std_dev,
            std_dev2: c2.std_dev,
            ..CoreResult::undefined(*n)
        };
        if c1.count >= need && c2.count >= need {
            return result(c1, c2, n, Reach::Window);
        }
        // One epoch in the window, none of the other: walk on along the axis.
        // A post or a spike (no surface at the normal's scale) has no normal to follow: walked,
        // its axis ran 195 m across St Leonards' beach to a dune.
        let walking = params.walk != Walk::Off && surface;
        // The present epoch's surface must hold the few points that show a surface's lie, as
        // the group the walk finds must: a single point of it walked 53 m along a horizontal
        // normal across St Leonards to a surface of the other epoch.
        let lie = need.max(normals::MIN_NORMAL_POINTS as u32);
        let present = match (c1.count, c2.count) {
            (k, 0) if k >= lie && walking => Some((0, p1.range(), span1)),
            (0, k) if k >= lie && walking => Some((1, p2.range(), span2)),
            _ => None,
        };
        let Some((which, (lo, hi), span)) = present else {
            return undefined();
        };
        let axis = reach::Axis { q: *q, n: *n, r, h };
        let at = reach::Present {
            span,
            beyond: [lo < span.0, hi > span.1],
        };
        let (pres, miss) = if which == 0 {
            (before, after)
        } else {
            (after, before)
        };
        match reach::walk(pres, miss, &axis, at, extent, walk) {
            reach::Walked::Found(found) if found.count >= need => {
                let how = match params.walk {
                    Walk::Detect => Reach::Beyond,
                    _ => Reach::Extended,
                };
                if which == 0 {
                    result(c1, found, n, how)
                } else {
                    result(found, c2, n, how)
                }
            }
            reach::Walked::Unheld => CoreResult {
                reach: Reach::Pending,
                ..undefined()
            },
            _ => undefined(),
        }
    })
}

/// The M3C2 result of the two epochs' surfaces in a cylinder (or along its axis).
fn result(
    c1: cylinder::CylinderStats,
    c2: cylinder::CylinderStats,
    n: &Point3,
    reach: Reach,
) -> CoreResult {
    let distance = c2.mean - c1.mean;
    let se = (c1.std_dev * c1.std_dev / c1.count as f64
        + c2.std_dev * c2.std_dev / c2.count as f64)
        .sqrt();
    let lod = 1.96 * se;
    CoreResult {
        distance,
        uncertainty: lod,
        significant: distance.abs() > lod,
        std_dev1: c1.std_dev,
        std_dev2: c2.std_dev,
        count1: c1.count,
        count2: c2.count,
        normal: *n,
        reach,
        sign_known: true,
    }
}
