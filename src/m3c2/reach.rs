//! Change of any depth (SPEC.md §1 "Change of any depth, at any density"): where one epoch has
//! points in a core point's cylinder and the other has none, the search goes on along the axis.
//!
//! The cylinder's half-length h is a search window (Lague, Brodu & Leroux 2013 §3.2 choose it
//! to reach the largest expected change): derived from the point spacing, it is 0.5 m at the
//! 1.6 cm spacing of a terrestrial scan, and a 2 m deep rockfall leaves the after epoch outside
//! every cylinder of its floor. Those core points got no distance, the event shrank to its rim
//! and its volume to a few per cent of the truth.
//!
//! **The walk.** Call the epoch with points in the window *present* and the other *missing*.
//! From the present epoch's surface (the group of projections nearest the core point, see
//! [`super::cylinder`]), the cylinder is carried on along the axis, both ways, beyond ±h:
//! - the first thing met decides each way. A surface of the *present* epoch (its next surface
//!   along the axis: the far wall of a gully, the beach under an overhang) ends the search that
//!   way: between two surfaces of one epoch lies air or rock, and a change of the near surface
//!   cannot pass the far one unseen;
//! - a group of the *missing* epoch (its projections split at gaps wider than the cylinder's
//!   diameter, as in the window) is the displaced surface, unless the present epoch has points
//!   among it: a surface both epochs hold at one place did not move (the far wall again, seen
//!   through a hole of the missing epoch);
//! - the group must cross the axis: spread far along it ([`ALONG`]), it is a surface running
//!   beside the axis (the side of a block), not one displaced along it; and it must hold the few
//!   points that show a surface's lie (a stray point metres away is none);
//! - beyond the displaced surface lies what lay beyond the present one: the next surface met
//!   further on must be the present epoch's (alone or shared). A second surface of the missing
//!   epoch alone makes the first the near side of something only that epoch holds: a block
//!   placed 20 m away, seen through the air where another block was removed;
//! - the data's extent ends it: the axis leaves the surveys' bounds (grown by the radius).
//!
//! Of the two ways, the group nearer the present surface is the displaced one (ties: the lower
//! position, like [`super::cylinder::nearest_group`]). Nothing found both ways is a hole of the
//! missing epoch, not a change: no distance, as before.
//!
//! The walk's result depends only on the points within the radius of the axis, never on how
//! far one query reaches or which points a tile holds: positions are measured from the core
//! point, the sums are exact ([`super::moments`]), and a walk that would need points beyond
//! what an index holds (a tile's square and halo) says so ([`Walked::Unheld`]) instead of
//! deciding, for the caller to repeat it over the points along the whole axis.

use super::cylinder::CylinderStats;
use super::moments::Moments1;
use crate::geom::Point3;
use crate::spatial::{in_cylinder, Columns};

/// The largest spread (standard deviation along the axis, in cylinder radii) of a surface the
/// walk takes: a plane crossing the cylinder at an angle θ to its cross-section spreads its
/// points over 2r·tan θ, a standard deviation of about 0.58 r·tan θ; 2 r admits surfaces up to
/// 74° from square to the axis (a 35° debris cone seen along a horizontal normal is 55°) and
/// refuses a wall running along it.
pub(crate) const ALONG: f64 = 2.0;

/// How the walk's finding is used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Walk {
    /// No walk: a cylinder without the other epoch gives no distance (plain M3C2).
    Off,
    /// The surface found is measured: the derived half-length is only a window.
    Measure,
    /// The surface found is flagged beyond reach, not measured: the user chose the half-length.
    Detect,
}

/// What one core point's distance rests on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum Reach {
    /// Both epochs inside the cylinder (or no distance at all).
    #[default]
    Window = 0,
    /// The walk found the other epoch beyond the window and measured it.
    Extended = 1,
    /// The walk found the other epoch beyond the user's half-length: not measured (the distance
    /// the M3C2 outputs give is NaN), kept for the events it belongs to.
    Beyond = 2,
    /// The walk left the points the index holds before deciding; to be walked again.
    Pending = 3,
}

impl Reach {
    /// The reach of a stored code (a result chunk's column).
    pub(crate) fn from_code(c: u8) -> Option<Reach> {
        [
            Reach::Window,
            Reach::Extended,
            Reach::Beyond,
            Reach::Pending,
        ]
        .into_iter()
        .find(|r| *r as u8 == c)
    }
}

/// Where a walk may look, in the local frame of the indexes: the data's bounds and the xy box
/// inside which the indexes hold every point of both epochs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// The surveys' bounds (both epochs).
    pub(crate) data_min: Point3,
    pub(crate) data_max: Point3,
    /// [x0, y0, x1, y1]: every point of either epoch in this box is indexed (infinite sides for a
    /// tile at the grid's edge, whose file holds every point beyond it).
    pub(crate) held: [f64; 4],
}

impl Extent {
    /// Everything indexed, within `data` bounds.
    pub fn whole(data_min: Point3, data_max: Point3) -> Extent {
        Extent {
            data_min,
            data_max,
            held: [
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::INFINITY,
            ],
        }
    }

    /// The same extent in a frame whose origin is at `origin`.
    pub(crate) fn local(&self, origin: &Point3) -> Extent {
        let o = origin;
        Extent {
            data_min: std::array::from_fn(|k| self.data_min[k] - o[k]),
            data_max: std::array::from_fn(|k| self.data_max[k] - o[k]),
            held: [
                self.held[0] - o[0],
                self.held[1] - o[1],
                self.held[2] - o[0],
                self.held[3] - o[1],
            ],
        }
    }

    /// The axis positions t at which a cylinder of radius `r` along `n` through `q` can hold a
    /// point inside the data's bounds: (lo, hi), lo ≤ 0 ≤ hi for a `q` inside.
    pub(crate) fn axis_limits(&self, q: &Point3, n: &Point3, r: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let (a, b) = (self.data_min[k] - r - q[k], self.data_max[k] + r - q[k]);
            if n[k].abs() < 1e-12 {
                if a > 0.0 || b < 0.0 {
                    return (0.0, 0.0);
                }
                continue;
            }
            let (u, v) = (a / n[k], b / n[k]);
            lo = lo.max(u.min(v));
            hi = hi.min(u.max(v));
        }
        (lo.min(0.0), hi.max(0.0))
    }

    /// Does the index hold every point of the cylinder of radius `r` along `n` through `q`
    /// between axis positions `t0` and `t1`?
    fn holds(&self, q: &Point3, n: &Point3, r: f64, t0: f64, t1: f64) -> bool {
        (0..2).all(|k| {
            let (a, b) = (q[k] + t0 * n[k], q[k] + t1 * n[k]);
            a.min(b) - r >= self.held[k] && a.max(b) + r <= self.held[k + 2]
        })
    }
}

/// What the walk found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Walked {
    /// The missing epoch's displaced surface: its statistics, positions measured from the core
    /// point along the axis.
    Found(CylinderStats),
    /// No surface of the missing epoch that way: a hole.
    Nothing,
    /// The walk needs points beyond what the index holds.
    Unheld,
}

/// The present epoch at the core point: the span of its surface's group along the axis and
/// whether it has other points in the window beyond that group, below and above.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Present {
    pub(crate) span: (f64, f64),
    pub(crate) beyond: [bool; 2],
}

/// One cylinder query: the core point `q` (local frame), unit axis `n`, radius `r`, window
/// half-length `h`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Axis {
    pub(crate) q: Point3,
    pub(crate) n: Point3,
    pub(crate) r: f64,
    pub(crate) h: f64,
}

/// Reused buffers of a walk (no allocation per core point).
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    present: Vec<f64>,
    missing: Vec<f64>,
}

/// Walk from the present epoch's surface along `axis` both ways (see the module), over the
/// points of `present` and `missing` (indexes in the local frame of `axis.q`).
pub(crate) fn walk(
    present: &Columns,
    missing: &Columns,
    axis: &Axis,
    at: Present,
    extent: &Extent,
    scratch: &mut Scratch,
) -> Walked {
    let (lo, hi) = extent.axis_limits(&axis.q, &axis.n, axis.r);
    // Exact sums need one scale for every position the walk can give.
    let scale = lo.abs().max(hi).max(axis.h).max(f64::MIN_POSITIVE);
    let mut best: Option<(f64, CylinderStats)> = None;
    for (way, dir) in [(0usize, -1.0f64), (1, 1.0)] {
        if at.beyond[way] {
            continue;
        }
        let limit = if dir > 0.0 { hi } else { -lo };
        match one_way(present, missing, axis, dir, limit, scale, extent, scratch) {
            OneWay::Unheld => return Walked::Unheld,
            OneWay::Nothing => {}
            OneWay::Found(g0, g1, stats) => {
                // Gap between the present surface and the group (both in axis positions).
                let (a, b) = (dir * g0, dir * g1);
                let gap = if dir > 0.0 {
                    a - at.span.1
                } else {
                    at.span.0 - b
                };
                if best.is_none_or(|(d, _)| gap < d) {
                    best = Some((gap, stats));
                }
            }
        }
    }
    match best {
        Some((_, s)) => Walked::Found(s),
        None => Walked::Nothing,
    }
}

enum OneWay {
    /// The group's first and last position (walk coordinates s = dir·t) and statistics.
    Found(f64, f64, CylinderStats),
    Nothing,
    Unheld,
}

/// The walk one way: positions s = dir·t from h to `limit`.
#[allow(clippy::too_many_arguments)]
fn one_way(
    present: &Columns,
    missing: &Columns,
    axis: &Axis,
    dir: f64,
    limit: f64,
    scale: f64,
    extent: &Extent,
    scratch: &mut Scratch,
) -> OneWay {
    let gap = 2.0 * axis.r;
    let Scratch {
        present: pres,
        missing: miss,
    } = scratch;
    pres.clear();
    miss.clear();
    let mut cursor = Cursor {
        from: axis.h,
        len: (2.0 * axis.h).max(gap).max(f64::MIN_POSITIVE),
        step: (2.0 * axis.h).max(gap).max(f64::MIN_POSITIVE),
        limit,
        dir,
    };
    let first = |v: &[f64], after: f64| {
        v.iter()
            .copied()
            .filter(|&x| x > after)
            .fold(f64::INFINITY, f64::min)
    };
    // 1. The first thing met: a group of the missing epoch, or the present epoch's next surface.
    loop {
        match cursor.next(present, missing, axis, extent, pres, miss) {
            Step::Unheld => return OneWay::Unheld,
            Step::Empty => continue,
            Step::Found | Step::End => {}
        }
        if first(pres, 0.0) <= first(miss, 0.0) {
            // The present epoch's next surface comes first (or nothing came at all).
            return OneWay::Nothing;
        }
        miss.sort_unstable_by(f64::total_cmp);
        let end = group_end(miss, 0, gap);
        if cursor.at_end() || end + 1 < miss.len() || cursor.from > miss[end] + gap {
            break;
        }
    }
    let end = group_end(miss, 0, gap);
    let (g0, g1) = (miss[0], miss[end]);
    if first(pres, 0.0) <= g1 + gap {
        // Interleaved with the present epoch: a surface both hold, unmoved.
        return OneWay::Nothing;
    }
    let mut m = Moments1::new(scale);
    for &s in &miss[..=end] {
        m.add(dir * s, true);
    }
    let (mean, var) = m.mean_var();
    if m.count() < super::normals::MIN_NORMAL_POINTS as u64 || var.sqrt() > ALONG * axis.r {
        // Fewer points than show a surface's lie (a stray point metres away is no surface), or
        // spread far along the axis: a surface running beside it (the side of a block), not one
        // crossing it.
        return OneWay::Nothing;
    }
    let stats = CylinderStats {
        count: m.count() as u32,
        mean,
        std_dev: var.sqrt(),
    };
    // 2. What comes next. The near surface displaced has, beyond it, what the present epoch has
    // beyond its own surface: the next surface met is the present epoch's (alone or shared). A
    // second surface of the missing epoch alone means the first was the near side of something
    // only it holds (a block placed 20 m away, seen through the air where a block was removed).
    loop {
        let (p, m) = (first(pres, g1 + gap), first(miss, g1 + gap));
        if p.is_finite() || m.is_finite() {
            if m < p - gap {
                return OneWay::Nothing;
            }
            break;
        }
        match cursor.next(present, missing, axis, extent, pres, miss) {
            Step::Unheld => return OneWay::Unheld,
            Step::End => break,
            Step::Empty | Step::Found => {}
        }
    }
    OneWay::Found(g0, g1, stats)
}

/// The last index of the group of sorted `v` that starts at `start` (gaps up to `gap`).
fn group_end(v: &[f64], start: usize, gap: f64) -> usize {
    let mut end = start;
    while end + 1 < v.len() && v[end + 1] - v[end] <= gap {
        end += 1;
    }
    end
}

/// Where a walk one way has got to: the stretch (from, from + len] is next, strides doubling
/// through empty space.
struct Cursor {
    from: f64,
    len: f64,
    step: f64,
    limit: f64,
    dir: f64,
}

enum Step {
    /// A stretch without points.
    Empty,
    /// A stretch with points of either epoch.
    Found,
    /// The data's end reached: nothing more to collect.
    End,
    /// The next stretch needs points the index does not hold.
    Unheld,
}

impl Cursor {
    fn at_end(&self) -> bool {
        self.from >= self.limit
    }

    /// Collect the next stretch of both epochs.
    fn next(
        &mut self,
        present: &Columns,
        missing: &Columns,
        axis: &Axis,
        extent: &Extent,
        pres: &mut Vec<f64>,
        miss: &mut Vec<f64>,
    ) -> Step {
        if self.at_end() {
            return Step::End;
        }
        let to = (self.from + self.len).min(self.limit);
        if !extent.holds(
            &axis.q,
            &axis.n,
            axis.r,
            self.dir * self.from,
            self.dir * to,
        ) {
            return Step::Unheld;
        }
        let found = collect(present, axis, self.dir, self.from, to, pres)
            | collect(missing, axis, self.dir, self.from, to, miss);
        self.from = to;
        if found {
            self.len = self.step;
            Step::Found
        } else {
            // Empty space (air, rock): longer strides change no result.
            self.len *= 2.0;
            if self.at_end() {
                Step::End
            } else {
                Step::Empty
            }
        }
    }
}

/// Push the walk positions s = dir·t ∈ (from, to] of `index`'s points inside the cylinder of
/// `axis` into `out`; true when any was pushed. Positions and the radial test are measured from
/// the core point whatever the stretch queried, so they do not depend on how the walk was cut.
fn collect(index: &Columns, axis: &Axis, dir: f64, from: f64, to: f64, out: &mut Vec<f64>) -> bool {
    let before = out.len();
    let mid = 0.5 * (from + to) * dir;
    let centre = std::array::from_fn(|k| axis.q[k] + mid * axis.n[k]);
    let half = 0.5 * (to - from);
    let r2 = axis.r * axis.r;
    // Culled a little wider than tested: the test is made from the core point, the candidates
    // come from around the stretch's centre, and the two roundings differ.
    let slack = 1e-9 * (1.0 + to.abs() + axis.r);
    index.cylinder_candidates(
        &centre,
        &axis.n,
        axis.r * (1.0 + 1e-7) + slack,
        half + slack,
        |points| {
            for p in points {
                let (t, inside) = in_cylinder(p, &axis.q, &axis.n, r2, f64::INFINITY);
                let s = dir * t;
                if inside && s > from && s <= to {
                    out.push(s);
                }
            }
        },
    );
    out.len() > before
}
