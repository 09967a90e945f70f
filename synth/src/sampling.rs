//! Streaming point generation: an epoch's points as a sequence of bounded chunks.
//!
//! The epoch's patches are cut into strips (along their v parameter) of at most [`STRIP_POINTS`]
//! expected points; the requested count is shared among all strips in proportion to their area
//! (largest-remainder rounding, so the total is exact). Each strip is sampled by rejection (see
//! [`surface`](super::surface)) from its own random stream (seed, epoch, strip), so the points do
//! not depend on the thread count. A chunk is a run of consecutive strips holding at most
//! [`CHUNK_POINTS`] points, sampled in parallel into one buffer, and only when the writer asks
//! for the next chunk: at most one chunk of points is ever in memory, whatever the total.

use rayon::prelude::*;

use super::surface::{Patch, V3};
use talus_base::rng::Rng;

/// Largest number of points generated (and held) at once.
pub const CHUNK_POINTS: usize = 1_000_000;

/// Target points per strip: the unit of parallel sampling (eight per chunk).
pub(crate) const STRIP_POINTS: usize = CHUNK_POINTS / 8;

/// Grid resolution (per side) of the midpoint-rule area integrals that share points out.
const AREA_GRID: usize = 256;

/// One strip of a patch: the part with v in [v0, v1], with its point count and random stream.
#[derive(Debug, Clone)]
struct Strip {
    patch: usize,
    v: [f64; 2],
    count: u64,
    stream: u64,
}

/// Rigid placement of local scene coordinates: rotation by an angle about the vertical axis
/// through `centre`, then translation by `origin` (to UTM-like coordinates).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Placement {
    pub centre: [f64; 2],
    pub cos: f64,
    pub sin: f64,
    pub origin: V3,
    /// A misregistration's turn (rows of a rotation matrix) about the scene's centre at height
    /// `turn_z`, applied after the scene's own rotation: identity but for `--turn`'s epoch.
    pub turn: [[f64; 3]; 3],
    /// The local height of the turn's centre.
    pub turn_z: f64,
    /// A slow landslide's settling (m): the point sinks by `creep` × [`creep_share`] of its
    /// place (local, unrotated coordinates): zero but for `--creep`'s epoch.
    pub creep: f64,
}

impl Placement {
    pub(crate) fn new(centre: [f64; 2], rotate_deg: f64, origin: V3) -> Self {
        let (sin, cos) = rotate_deg.to_radians().sin_cos();
        Placement {
            centre,
            cos,
            sin,
            origin,
            turn: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            turn_z: 0.0,
            creep: 0.0,
        }
    }

    /// The same placement, its points sinking by `creep` × [`creep_share`] (m).
    pub(crate) fn creeping(mut self, creep: f64) -> Self {
        self.creep = creep;
        self
    }

    /// The same placement, turned by `deg` about x, then y, then z (degrees) through the scene's
    /// centre at (local) height `z`.
    pub(crate) fn turned(mut self, deg: [f64; 3], z: f64) -> Self {
        self.turn_z = z;
        let [a, b, c] = deg.map(f64::to_radians);
        let (sa, ca) = a.sin_cos();
        let (sb, cb) = b.sin_cos();
        let (sc, cc) = c.sin_cos();
        let rx = [[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]];
        let ry = [[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]];
        let rz = [[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]];
        let mul = |p: [[f64; 3]; 3], q: [[f64; 3]; 3]| -> [[f64; 3]; 3] {
            std::array::from_fn(|i| {
                std::array::from_fn(|j| (0..3).map(|k| p[i][k] * q[k][j]).sum())
            })
        };
        self.turn = mul(rz, mul(ry, rx));
        self
    }
    pub(crate) fn apply(&self, p: V3) -> V3 {
        let (dx, dy) = (p[0] - self.centre[0], p[1] - self.centre[1]);
        // The settling's field only where there is one: this runs for every point written.
        let z = if self.creep == 0.0 {
            p[2]
        } else {
            p[2] - self.creep * creep_share(p[0], p[1])
        };
        let mut q = [
            self.cos * dx - self.sin * dy,
            self.sin * dx + self.cos * dy,
            z,
        ];
        if self.turn != [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
            let t = &self.turn;
            let d = [q[0], q[1], q[2] - self.turn_z];
            q = std::array::from_fn(|i| t[i][0] * d[0] + t[i][1] * d[1] + t[i][2] * d[2]);
            q[2] += self.turn_z;
        }
        [
            self.origin[0] + self.centre[0] + q[0],
            self.origin[1] + self.centre[1] + q[1],
            self.origin[2] + q[2],
        ]
    }
}

/// Wavelength (m) of the settling of `--creep`.
pub(crate) const CREEP_WAVELENGTH: f64 = 24.0;

/// The share of `--creep` by which the ground at local (x, y) settles: a smooth field between
/// 0.25 and 1 (a landslide's mass does not move as one rigid body: its parts settle by different
/// amounts, here in cells of [`CREEP_WAVELENGTH`]), never zero, so no part of it holds still.
pub(crate) fn creep_share(x: f64, y: f64) -> f64 {
    let k = 2.0 * std::f64::consts::PI / CREEP_WAVELENGTH;
    0.625 + 0.375 * (k * x).sin() * (k * y).cos()
}

/// Share `total` among weights by largest remainder: floor of each exact share, then one more to
/// the largest fractional parts (ties to the lower index). Deterministic and exact.
fn apportion(weights: &[f64], total: u64) -> Vec<u64> {
    let sum: f64 = weights.iter().sum();
    if sum <= 0.0 || weights.is_empty() {
        return vec![0; weights.len()];
    }
    let exact: Vec<f64> = weights.iter().map(|w| total as f64 * w / sum).collect();
    let mut counts: Vec<u64> = exact.iter().map(|e| e.floor() as u64).collect();
    let assigned: u64 = counts.iter().sum();
    let mut order: Vec<usize> = (0..weights.len()).collect();
    order.sort_by(|&a, &b| {
        let (fa, fb) = (exact[a] - exact[a].floor(), exact[b] - exact[b].floor());
        fb.total_cmp(&fa).then(a.cmp(&b))
    });
    // f64 rounding could leave the floors a little off `total`: fix either way.
    let mut left = total.saturating_sub(assigned);
    for &i in order.iter().cycle().take(order.len() * 2) {
        if left == 0 {
            break;
        }
        counts[i] += 1;
        left -= 1;
    }
    let mut over = assigned.saturating_sub(total);
    for &i in order.iter().rev() {
        while over > 0 && counts[i] > 0 {
            counts[i] -= 1;
            over -= 1;
        }
    }
    counts
}

/// The chunks of one epoch, generated lazily: an iterator of point batches in global
/// coordinates, each at most [`CHUNK_POINTS`] long, whose lengths add up to the requested count.
pub struct Chunks {
    patches: Vec<Patch>,
    strips: std::iter::Peekable<std::vec::IntoIter<Strip>>,
    seed: u64,
    epoch: u64,
    noise: f64,
    placement: Placement,
    /// Plants whose crowns hide part of the surfaces (`plants::hidden`): a hidden draw is drawn
    /// again, so the strip keeps its count.
    plants: Vec<super::plants::Plant>,
    /// The surfaces' area (the one the points are shared out by).
    area: f64,
}

impl Chunks {
    pub(crate) fn new(
        patches: Vec<Patch>,
        total: u64,
        seed: u64,
        epoch: u64,
        noise: f64,
        placement: Placement,
    ) -> Self {
        // First a coarse area per patch to decide how many strips each needs, then the area of
        // every strip to share the points out exactly.
        let patch_area: Vec<f64> = patches
            .iter()
            .map(|p| {
                let d = p.domain();
                p.area(d[2], d[3], AREA_GRID, AREA_GRID)
            })
            .collect();
        let all: f64 = patch_area.iter().sum();
        let mut strips = Vec::new();
        let mut areas = Vec::new();
        for (i, p) in patches.iter().enumerate() {
            let expected = total as f64 * patch_area[i] / all;
            // 2 % headroom so rounding never pushes a strip over STRIP_POINTS.
            let n = ((expected * 1.02 / STRIP_POINTS as f64).ceil() as usize).max(1);
            let [_, _, v0, v1] = p.domain();
            for k in 0..n {
                let a = v0 + (v1 - v0) * k as f64 / n as f64;
                let b = v0 + (v1 - v0) * (k + 1) as f64 / n as f64;
                areas.push(if n == 1 {
                    patch_area[i]
                } else {
                    // Thin strips: fewer rows suffice for their area.
                    p.area(a, b, AREA_GRID, AREA_GRID / 8)
                });
                strips.push(Strip {
                    patch: i,
                    v: [a, b],
                    count: 0,
                    stream: 0,
                });
            }
        }
        for (k, (s, c)) in strips.iter_mut().zip(apportion(&areas, total)).enumerate() {
            s.count = c;
            s.stream = k as u64;
        }
        Chunks {
            patches,
            strips: strips.into_iter().peekable(),
            seed,
            epoch,
            noise,
            placement,
            plants: Vec::new(),
            area: all,
        }
    }

    /// The same chunks, with the surface behind `plants`' crowns partly hidden.
    pub(crate) fn behind(mut self, plants: Vec<super::plants::Plant>) -> Self {
        self.plants = plants;
        self
    }

    /// The area of the surfaces.
    pub(crate) fn area(&self) -> f64 {
        self.area
    }

    /// Fill `out` (of length strip.count) with the strip's points.
    fn sample(&self, strip: &Strip, out: &mut [V3]) {
        let patch = &self.patches[strip.patch];
        let [u0, u1, _, _] = patch.domain();
        let [v0, v1] = strip.v;
        let jmax = patch.jac_max();
        // One stream per (epoch, strip): epochs are independent, and a strip's points do not
        // depend on how many points other strips drew.
        let mut rng = Rng::new(self.seed, (self.epoch << 32) | strip.stream);
        let mut filled = 0;
        while filled < out.len() {
            let u = u0 + (u1 - u0) * rng.uniform();
            let v = v0 + (v1 - v0) * rng.uniform();
            let jac = patch.jac(u, v);
            if jac <= 0.0 || rng.uniform() * jmax >= jac {
                continue;
            }
            let s = patch.point(u, v);
            let e = self.noise * rng.normal();
            let p = [
                s.p[0] + e * s.n[0],
                s.p[1] + e * s.n[1],
                s.p[2] + e * s.n[2],
            ];
            if !self.plants.is_empty()
                && super::plants::hidden(&self.plants, &s.p, self.seed, self.epoch)
            {
                continue;
            }
            out[filled] = self.placement.apply(p);
            filled += 1;
        }
    }
}

impl Iterator for Chunks {
    type Item = Vec<V3>;
    fn next(&mut self) -> Option<Vec<V3>> {
        // Gather consecutive non-empty strips up to CHUNK_POINTS (at least one).
        let mut group = Vec::new();
        let mut n = 0usize;
        while let Some(s) = self
            .strips
            .next_if(|s| s.count == 0 || group.is_empty() || n + s.count as usize <= CHUNK_POINTS)
        {
            if s.count > 0 {
                n += s.count as usize;
                group.push(s);
            }
        }
        if group.is_empty() {
            return None;
        }
        // One buffer for the chunk, cut into one slice per strip, filled in parallel.
        let mut out = vec![[0.0; 3]; n];
        let mut slices = Vec::with_capacity(group.len());
        let mut rest = out.as_mut_slice();
        for s in &group {
            let (head, tail) = rest.split_at_mut(s.count as usize);
            slices.push(head);
            rest = tail;
        }
        group
            .par_iter()
            .zip(slices.into_par_iter())
            .for_each(|(s, slice)| self.sample(s, slice));
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn apportion_is_exact_and_proportional() {
        let c = apportion(&[1.0, 2.0, 3.0], 100);
        assert_eq!(c.iter().sum::<u64>(), 100);
        assert_eq!(c, vec![17, 33, 50]);
        assert_eq!(apportion(&[1.0, 0.0], 7), vec![7, 0]);
    }

    #[test]
    fn placement_rotates_about_centre() {
        let p = Placement::new([10.0, 10.0], 90.0, [100.0, 200.0, 0.0]);
        let q = p.apply([11.0, 10.0, 5.0]);
        assert!((q[0] - 110.0).abs() < 1e-12 && (q[1] - 211.0).abs() < 1e-12 && q[2] == 5.0);
    }
}
