//! M3C2 inside the cylinder only (no walk beyond it), in two halves: the before epoch's half —
//! the normals and C1's statistics at the core points — computed once, then any number of after
//! epochs measured against it.
//!
//! Why: the alignment samples every later survey of a campaign against the first at the same
//! core points (`units::align`), so the first survey's half is the same for all of them; computed
//! once, it is most of the sample's cost saved (a permanent scanner's campaign of small surveys,
//! where the sample is every core point and nothing gets aligned, paid twice the CPU of `--align
//! off` before). A sample takes only distances measured in the window (a walked one may be
//! finished in another tile), so the walk is not needed here.
//!
//! Each result is, bit for bit, the one [`super::tile::compute`] gives at a core point measured
//! in the window (the same calls on the same index: `tests` checks it); the others come back
//! undefined.

use super::cylinder::{CylinderStats, Projections};
use super::tile::{EpochPoints, KeyedResult};
use super::{CoreResult, M3c2Params, Reach};
use crate::geom::Point3;
use crate::spatial::Columns;

/// The before epoch's half at a set of core points.
pub(crate) struct BeforeHalf {
    /// The core points (key, global position), in the order given.
    cores: Vec<(u64, Point3)>,
    normal: Vec<Point3>,
    known: Vec<bool>,
    /// C1 (the before epoch's surface in the cylinder) and its span along the axis.
    c1: Vec<(CylinderStats, (f64, f64))>,
}

impl BeforeHalf {
    /// Core points held.
    pub(crate) fn len(&self) -> usize {
        self.cores.len()
    }

    /// What it holds in memory, about.
    pub(crate) fn bytes(&self) -> u64 {
        (self.len()
            * std::mem::size_of::<((u64, Point3), Point3, bool, (CylinderStats, (f64, f64)))>())
            as u64
    }
}

/// The before half at `cores` (global positions, with their keys) of `before`'s points, in the
/// local frame anchored at `anchor` (as [`super::tile::compute`] has it), normals oriented as
/// `params.orientation` says without an orientation field.
pub(crate) fn before_half(
    before: &EpochPoints,
    anchor: Point3,
    cores: &[(u64, Point3)],
    params: &M3c2Params,
) -> BeforeHalf {
    let cell = super::column_width(params);
    let b = Columns::from_fn(before.len(), |i| before.point(i), anchor, cell);
    let local: Vec<Point3> = cores.iter().map(|(_, p)| b.to_local(p)).collect();
    let n = super::normals(&b, &local, params, None);
    let (r, h) = (params.cyl_radius, params.cyl_halflen);
    let c1 = super::in_spatial_order(&local, r.max(params.normal_radius), |i| {
        let normal = &n.normal[i];
        if !normal[0].is_finite() {
            return (CylinderStats::default(), (0.0, 0.0));
        }
        with_projections(|p1| {
            p1.collect(&b, &local[i], normal, r, h);
            p1.surface(2.0 * r, (0.0, 0.0))
        })
    });
    BeforeHalf {
        cores: cores.to_vec(),
        normal: n.normal,
        known: n.known,
        c1,
    }
}

/// M3C2 in the window at `half`'s core points against `after`'s points (the same `anchor`),
/// sorted by key: what [`super::tile::compute`] gives where the distance is measured in the
/// window, undefined (NaN) elsewhere.
pub(crate) fn against(
    half: &BeforeHalf,
    after: &EpochPoints,
    anchor: Point3,
    params: &M3c2Params,
) -> Vec<KeyedResult> {
    let cell = super::column_width(params);
    let a = Columns::from_fn(after.len(), |i| after.point(i), anchor, cell);
    let local: Vec<Point3> = half.cores.iter().map(|(_, p)| a.to_local(p)).collect();
    let (r, h) = (params.cyl_radius, params.cyl_halflen);
    let need = params.min_points.max(1);
    let results = super::in_spatial_order(&local, r.max(params.normal_radius), |i| {
        let n = &half.normal[i];
        if !n[0].is_finite() {
            return CoreResult::undefined(*n);
        }
        let (c1, span1) = half.c1[i];
        // As `super::core_result`: C2's group is the one nearest to C1's.
        let near = if c1.count > 0 { span1 } else { (0.0, 0.0) };
        let (c2, _) = with_projections(|p2| {
            p2.collect(&a, &local[i], n, r, h);
            p2.surface(2.0 * r, near)
        });
        if c1.count >= need && c2.count >= need {
            super::result(c1, c2, n, Reach::Window)
        } else {
            CoreResult {
                count1: c1.count,
                count2: c2.count,
                std_dev1: c1.std_dev,
                std_dev2: c2.std_dev,
                ..CoreResult::undefined(*n)
            }
        }
    });
    super::tile::keyed_by(&half.cores, results, &half.known)
}

/// `f` with this thread's projection scratch (no allocation per core point).
fn with_projections<T>(f: impl FnOnce(&mut Projections) -> T) -> T {
    thread_local! {
        static SCRATCH: std::cell::RefCell<Projections> = Default::default();
    }
    SCRATCH.with(|s| f(&mut s.borrow_mut()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::m3c2::{Extent, Orientation, Walk};

    /// A rough slope, and after it the same slope with a pit dug 1.5 m deep and a mound laid
    /// beside it and a strip missing (cylinders with no after point: walked by the tile, left
    /// undefined here).
    fn scene() -> (Vec<Point3>, Vec<Point3>) {
        let mut rng = crate::rng::SplitMix64::new(7);
        let mut before = Vec::new();
        let mut after = Vec::new();
        for i in 0..120 {
            for j in 0..120 {
                let (x, y) = (i as f64 * 0.25, j as f64 * 0.25);
                let z = 0.3 * x + 0.05 * (x * 1.7).sin() * (y * 0.9).cos();
                let jitter = |r: &mut crate::rng::SplitMix64| (r.uniform() - 0.5) * 0.02;
                before.push([x, y, z + jitter(&mut rng)]);
                let pit = ((x - 10.0).powi(2) + (y - 10.0).powi(2)).sqrt() < 3.0;
                let mound = ((x - 20.0).powi(2) + (y - 18.0).powi(2)).sqrt() < 2.5;
                let gone = (14.0..16.0).contains(&x) && y > 20.0;
                if gone {
                    continue;
                }
                let dz = if pit {
                    -1.5
                } else if mound {
                    0.8
                } else {
                    0.0
                };
                after.push([x + 0.01, y, z + dz + jitter(&mut rng)]);
            }
        }
        (before, after)
    }

    fn columns(p: &[Point3]) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<bool>) {
        (
            p.iter().map(|p| p[0]).collect(),
            p.iter().map(|p| p[1]).collect(),
            p.iter().map(|p| p[2]).collect(),
            vec![true; p.len()],
        )
    }

    #[test]
    fn the_halves_give_the_tiles_window_results_bit_for_bit() {
        let (b, a) = scene();
        let (bx, by, bz, bo) = columns(&b);
        let (ax, ay, az, ao) = columns(&a);
        let before = EpochPoints {
            x: &bx,
            y: &by,
            z: &bz,
            owned: &bo,
        };
        let after = EpochPoints {
            x: &ax,
            y: &ay,
            z: &az,
            owned: &ao,
        };
        let params = M3c2Params {
            normal_radius: 1.0,
            cyl_radius: 0.5,
            cyl_halflen: 3.0,
            min_points: 3,
            orientation: Orientation::Up,
            point_spacing: 0.25,
            walk: Walk::Measure,
        };
        let anchor = [0.0, 0.0, 0.0];
        let extent = Extent::whole([-1.0, -1.0, -1.0], [31.0, 31.0, 12.0]);
        let tile =
            crate::m3c2::tile::compute(&before, &after, anchor, 0.75, None, &params, &extent, None);
        let cores: Vec<(u64, Point3)> = tile.iter().map(|k| (k.key, k.xyz)).collect();
        let half = before_half(&before, anchor, &cores, &params);
        let halves = against(&half, &after, anchor, &params);
        assert_eq!(halves.len(), tile.len());
        let (mut window, mut walked) = (0, 0);
        for (t, w) in tile.iter().zip(&halves) {
            assert_eq!((t.key, t.xyz), (w.key, w.xyz));
            assert_eq!(t.r.normal.map(f64::to_bits), w.r.normal.map(f64::to_bits));
            if t.r.reach == Reach::Window && t.r.distance.is_finite() {
                window += 1;
                assert_eq!(t.r, w.r, "core point {}", t.key);
                assert_eq!(t.r.distance.to_bits(), w.r.distance.to_bits());
            } else {
                walked += 1;
                assert!(w.r.distance.is_nan(), "core point {}: {:?}", t.key, w.r);
            }
        }
        // The scene has both kinds, and the change is in the window results.
        assert!(
            window > 1000 && walked > 10,
            "{window} in the window, {walked} not"
        );
        assert!(halves.iter().any(|k| k.r.distance < -1.4));
        assert!(halves.iter().any(|k| k.r.distance > 0.7));
    }
}
