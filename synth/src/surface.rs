//! Analytic surfaces of the synthetic scenes and uniform-by-area sampling of them.
//!
//! An epoch's true surface is a list of [`Patch`]es, each a map from a parameter rectangle
//! (u, v) to 3D points with a known area element |∂p/∂u × ∂p/∂v| (the Jacobian). Sampling a patch
//! uniformly by area is rejection sampling: draw (u, v) uniformly in the rectangle and accept with
//! probability jac(u, v) / jac_max (von Neumann 1951), where jac_max bounds the Jacobian; masked
//! parts (holes) have Jacobian 0. The number of points per patch is proportional to its area.
//!
//! Patches: heightfields z = f(x, y) (base plane or smooth waves plus bumps, spherical caps, flat
//! blocks and cones; Jacobian sqrt(1 + |∇f|²)), optionally with holes (ground a survey did not
//! see), planar rectangles with holes (box walls, the cliff face; Jacobian 1), vertical walls
//! standing on a base surface (box walls on undulating ground: (s + u·d, base(s + u·d) + v) for a
//! horizontal unit d, whose ∂/∂v is vertical, so the Jacobian is 1), and half-ellipsoids (rockfall scars; sampled through the unit
//! hemisphere, whose area element in (φ, w = cos θ) is dφ dw by Archimedes' hat-box theorem, mapped
//! by diag(a, b, c), whose area scale at unit normal s is abc·|diag(1/a, 1/b, 1/c)·s|).

use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::sync::Mutex;

pub(crate) type V3 = [f64; 3];

fn norm(v: V3) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn unit(v: V3) -> V3 {
    let n = norm(v);
    [v[0] / n, v[1] / n, v[2] / n]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// One plane wave of a smooth base: `amp · sin(kx·x + ky·y + phase)`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Wave {
    pub amp: f64,
    pub kx: f64,
    pub ky: f64,
    pub phase: f64,
}

/// The base of a heightfield: a tilted plane plus smooth waves.
#[derive(Debug, Clone)]
pub(crate) struct Base {
    pub z0: f64,
    pub gx: f64,
    pub gy: f64,
    pub waves: Vec<Wave>,
}

impl Base {
    pub(crate) fn plane(z0: f64) -> Self {
        Base {
            z0,
            gx: 0.0,
            gy: 0.0,
            waves: Vec::new(),
        }
    }
    pub(crate) fn eval(&self, x: f64, y: f64) -> (f64, [f64; 2]) {
        let mut z = self.z0 + self.gx * x + self.gy * y;
        let mut g = [self.gx, self.gy];
        for w in &self.waves {
            let (s, c) = (w.kx * x + w.ky * y + w.phase).sin_cos();
            z += w.amp * s;
            g[0] += w.amp * c * w.kx;
            g[1] += w.amp * c * w.ky;
        }
        (z, g)
    }
    /// Upper bound of |∇z|.
    pub(crate) fn max_slope(&self) -> f64 {
        self.gx.hypot(self.gy)
            + self
                .waves
                .iter()
                .map(|w| w.amp.abs() * w.kx.hypot(w.ky))
                .sum::<f64>()
    }
}

/// A localised change added to a base surface. Heights are signed (negative = dent or pit).
#[derive(Debug, Clone, Copy)]
pub(crate) enum Feature {
    /// `height · cos²(π r / 2R)` for r < R: smooth (C¹) bump.
    Bump {
        c: [f64; 2],
        radius: f64,
        height: f64,
    },
    /// Spherical cap of a sphere of radius `sphere_radius`, cap height |height| < sphere_radius:
    /// `±(sqrt(Rs² − r²) − (Rs − h))` for r < a = sqrt(h(2Rs − h)).
    Cap {
        c: [f64; 2],
        sphere_radius: f64,
        height: f64,
    },
    /// Flat-topped block over [x0, x1) × [y0, y1); its vertical walls are separate patches.
    Block {
        min: [f64; 2],
        max: [f64; 2],
        height: f64,
    },
    /// Right circular cone `height · (1 − r/R)` for r < R (debris fan when cut by a face).
    Cone {
        c: [f64; 2],
        radius: f64,
        height: f64,
    },
}

impl Feature {
    /// Value and gradient at (x, y).
    fn eval(&self, x: f64, y: f64) -> (f64, [f64; 2]) {
        // d(value)/dr times the unit radial vector gives the gradient of a radial profile.
        let radial = |c: [f64; 2], f: &dyn Fn(f64) -> Option<(f64, f64)>| {
            let (dx, dy) = (x - c[0], y - c[1]);
            let r = dx.hypot(dy);
            match f(r) {
                Some((v, dvdr)) if r > 0.0 => (v, [dvdr * dx / r, dvdr * dy / r]),
                Some((v, _)) => (v, [0.0, 0.0]),
                None => (0.0, [0.0, 0.0]),
            }
        };
        match *self {
            Feature::Bump { c, radius, height } => radial(c, &|r| {
                (r < radius).then(|| {
                    let a = FRAC_PI_2 * r / radius;
                    (
                        height * a.cos().powi(2),
                        -height * FRAC_PI_2 / radius * (2.0 * a).sin(),
                    )
                })
            }),
            Feature::Cap {
                c,
                sphere_radius: rs,
                height,
            } => {
                let h = height.abs();
                let s = height.signum();
                let a2 = h * (2.0 * rs - h);
                radial(c, &|r| {
                    (r * r < a2).then(|| {
                        let q = (rs * rs - r * r).sqrt();
                        (s * (q - (rs - h)), -s * r / q)
                    })
                })
            }
            Feature::Block { min, max, height } => {
                let inside = x >= min[0] && x < max[0] && y >= min[1] && y < max[1];
                (if inside { height } else { 0.0 }, [0.0, 0.0])
            }
            Feature::Cone { c, radius, height } => radial(c, &|r| {
                (r < radius).then(|| (height * (1.0 - r / radius), -height / radius))
            }),
        }
    }

    fn max_slope(&self) -> f64 {
        match *self {
            Feature::Bump { radius, height, .. } => height.abs() * FRAC_PI_2 / radius,
            Feature::Cap {
                sphere_radius: rs,
                height,
                ..
            } => {
                let h = height.abs();
                (h * (2.0 * rs - h)).sqrt() / (rs - h)
            }
            Feature::Block { .. } => 0.0,
            Feature::Cone { radius, height, .. } => height.abs() / radius,
        }
    }
}

impl Feature {
    /// The same feature moved by d in (x, y).
    pub(crate) fn moved(self, d: [f64; 2]) -> Self {
        let add = |p: [f64; 2]| [p[0] + d[0], p[1] + d[1]];
        match self {
            Feature::Bump { c, radius, height } => Feature::Bump {
                c: add(c),
                radius,
                height,
            },
            Feature::Cap {
                c,
                sphere_radius,
                height,
            } => Feature::Cap {
                c: add(c),
                sphere_radius,
                height,
            },
            Feature::Block { min, max, height } => Feature::Block {
                min: add(min),
                max: add(max),
                height,
            },
            Feature::Cone { c, radius, height } => Feature::Cone {
                c: add(c),
                radius,
                height,
            },
        }
    }

    /// Closed-form volume between the feature and its base (signed): see the volume functions
    /// below; a cone πR²H/3, a block w·d·h.
    pub(crate) fn volume(&self) -> f64 {
        match *self {
            Feature::Bump { radius, height, .. } => bump_volume(radius, height),
            Feature::Cap {
                sphere_radius,
                height,
                ..
            } => cap_volume(sphere_radius, height),
            Feature::Block { min, max, height } => (max[0] - min[0]) * (max[1] - min[1]) * height,
            Feature::Cone { radius, height, .. } => PI * radius * radius * height / 3.0,
        }
    }

    /// Axis-aligned bounding box of the footprint: (min, max).
    pub(crate) fn bbox(&self) -> ([f64; 2], [f64; 2]) {
        let around = |c: [f64; 2], r: f64| ([c[0] - r, c[1] - r], [c[0] + r, c[1] + r]);
        match *self {
            Feature::Bump { c, radius, .. } | Feature::Cone { c, radius, .. } => around(c, radius),
            Feature::Cap {
                c,
                sphere_radius,
                height,
            } => around(c, cap_footprint(sphere_radius, height)),
            Feature::Block { min, max, .. } => (min, max),
        }
    }
}

/// z = base(x, y) + Σ features(x, y). Features must not overlap: the truth volumes assume
/// disjoint footprints.
#[derive(Debug, Clone)]
pub(crate) struct Heightfield {
    base: Base,
    features: Vec<Feature>,
    index: FeatureIndex,
}

/// Uniform grid over the features' bounding boxes so that evaluating a point looks at the few
/// features near it, not at all of them (the large scene has about a thousand).
#[derive(Debug, Clone)]
struct FeatureIndex {
    min: [f64; 2],
    cell: f64,
    dims: [usize; 2],
    cells: Vec<Vec<u32>>,
}

impl FeatureIndex {
    fn new(features: &[Feature]) -> Self {
        let mut min = [f64::INFINITY; 2];
        let mut max = [f64::NEG_INFINITY; 2];
        let mut extent: f64 = 0.0;
        for f in features {
            let (a, b) = f.bbox();
            for k in 0..2 {
                min[k] = min[k].min(a[k]);
                max[k] = max[k].max(b[k]);
                extent = extent.max(b[k] - a[k]);
            }
        }
        if features.is_empty() {
            return FeatureIndex {
                min: [0.0; 2],
                cell: 1.0,
                dims: [0, 0],
                cells: Vec::new(),
            };
        }
        let cell = extent.max(1e-9);
        let dims = [
            ((max[0] - min[0]) / cell).floor() as usize + 1,
            ((max[1] - min[1]) / cell).floor() as usize + 1,
        ];
        let mut cells = vec![Vec::new(); dims[0] * dims[1]];
        for (i, f) in features.iter().enumerate() {
            let (a, b) = f.bbox();
            let (i0, j0) = (
                ((a[0] - min[0]) / cell) as usize,
                ((a[1] - min[1]) / cell) as usize,
            );
            let i1 = (((b[0] - min[0]) / cell) as usize).min(dims[0] - 1);
            let j1 = (((b[1] - min[1]) / cell) as usize).min(dims[1] - 1);
            for j in j0..=j1 {
                for ii in i0..=i1 {
                    cells[j * dims[0] + ii].push(i as u32);
                }
            }
        }
        FeatureIndex {
            min,
            cell,
            dims,
            cells,
        }
    }

    fn near(&self, x: f64, y: f64) -> &[u32] {
        let (fx, fy) = ((x - self.min[0]) / self.cell, (y - self.min[1]) / self.cell);
        if !(fx >= 0.0 && fy >= 0.0) {
            return &[];
        }
        let (i, j) = (fx as usize, fy as usize);
        if i >= self.dims[0] || j >= self.dims[1] {
            return &[];
        }
        &self.cells[j * self.dims[0] + i]
    }
}

impl Heightfield {
    pub(crate) fn new(base: Base, features: Vec<Feature>) -> Self {
        let index = FeatureIndex::new(&features);
        Heightfield {
            base,
            features,
            index,
        }
    }

    pub(crate) fn eval(&self, x: f64, y: f64) -> (f64, [f64; 2]) {
        let (mut z, mut g) = self.base.eval(x, y);
        for &i in self.index.near(x, y) {
            let (v, fg) = self.features[i as usize].eval(x, y);
            z += v;
            g[0] += fg[0];
            g[1] += fg[1];
        }
        (z, g)
    }
    fn max_slope(&self) -> f64 {
        // Base slope plus the steepest feature: an upper bound since features are disjoint.
        self.base.max_slope()
            + self
                .features
                .iter()
                .map(Feature::max_slope)
                .fold(0.0, f64::max)
    }
}

/// A hole cut out of a planar patch, in its (u, v) coordinates.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Hole {
    Rect {
        min: [f64; 2],
        max: [f64; 2],
    },
    Ellipse {
        c: [f64; 2],
        a: f64,
        b: f64,
    },
    /// Below a tent profile v < peak − slope·|u − cu| (the face hidden behind a debris cone).
    BelowTent {
        cu: f64,
        peak: f64,
        slope: f64,
    },
}

impl Hole {
    pub(crate) fn contains(&self, u: f64, v: f64) -> bool {
        match *self {
            Hole::Rect { min, max } => u >= min[0] && u < max[0] && v >= min[1] && v < max[1],
            Hole::Ellipse { c, a, b } => {
                let (p, q) = ((u - c[0]) / a, (v - c[1]) / b);
                p * p + q * q < 1.0
            }
            Hole::BelowTent { cu, peak, slope } => v < peak - slope * (u - cu).abs(),
        }
    }

    /// An interval of u outside which the hole holds no point with v ≥ `v_min`, widened by a
    /// margin so that rounding never leaves out a u the hole holds (it only spares tests).
    fn u_span(&self, v_min: f64) -> [f64; 2] {
        let (lo, hi) = match *self {
            Hole::Rect { min, max } => (min[0], max[0]),
            Hole::Ellipse { c, a, .. } => (c[0] - a.abs(), c[0] + a.abs()),
            Hole::BelowTent { cu, peak, slope } if slope > 0.0 => {
                let half = (peak - v_min) / slope;
                (cu - half, cu + half)
            }
            Hole::BelowTent { .. } => (f64::NEG_INFINITY, f64::INFINITY),
        };
        let margin = 1e-9 * (1.0 + lo.abs().max(hi.abs()));
        [lo - margin, hi + margin]
    }
}

/// A piece of an epoch's surface; see the module documentation.
#[derive(Debug, Clone)]
pub(crate) enum Patch {
    /// The heightfield over [x0, x1] × [y0, y1], minus holes (in (x, y)).
    Height {
        field: Heightfield,
        min: [f64; 2],
        max: [f64; 2],
        holes: Vec<Hole>,
    },
    /// origin + u·eu + v·ev for u ∈ [0, len_u], v ∈ [0, len_v] (eu, ev orthonormal), minus holes.
    Plane {
        origin: V3,
        eu: V3,
        ev: V3,
        len: [f64; 2],
        holes: Vec<Hole>,
    },
    /// A vertical wall along the horizontal segment start + u·dir, u ∈ [0, len] (dir a unit
    /// vector), from base + z[0] to base + z[1] above each point of it: v ∈ [z[0], z[1]].
    Wall {
        base: Base,
        start: [f64; 2],
        dir: [f64; 2],
        len: f64,
        z: [f64; 2],
    },
    /// The half (local y ≥ 0) of the ellipsoid with semi-axes `radii` along x, y, z centred at
    /// `centre`: a scar hollowed into a face lying in the plane y = centre.y, rock at y > it.
    HalfEllipsoid { centre: V3, radii: V3 },
}

/// A point sampled on a patch with its unit normal.
pub(crate) struct Sample {
    pub p: V3,
    pub n: V3,
}

impl Patch {
    /// The parameter rectangle [u0, u1] × [v0, v1].
    pub(crate) fn domain(&self) -> [f64; 4] {
        match self {
            Patch::Height { min, max, .. } => [min[0], max[0], min[1], max[1]],
            Patch::Plane { len, .. } => [0.0, len[0], 0.0, len[1]],
            Patch::Wall { len, z, .. } => [0.0, *len, z[0], z[1]],
            Patch::HalfEllipsoid { .. } => [0.0, TAU, 0.0, 1.0],
        }
    }

    /// Upper bound of the Jacobian over the domain.
    pub(crate) fn jac_max(&self) -> f64 {
        match self {
            Patch::Height { field, .. } => (1.0 + field.max_slope().powi(2)).sqrt(),
            Patch::Plane { .. } | Patch::Wall { .. } => 1.0,
            Patch::HalfEllipsoid {
                radii: [a, b, c], ..
            } => a * b * c * (1.0 / a).max(1.0 / b).max(1.0 / c),
        }
    }

    /// The Jacobian at (u, v); 0 inside holes.
    pub(crate) fn jac(&self, u: f64, v: f64) -> f64 {
        if self.holes().iter().any(|h| h.contains(u, v)) {
            return 0.0;
        }
        self.jac_open(u, v)
    }

    /// The holes cut out of the patch (none but for heightfields and planar rectangles).
    fn holes(&self) -> &[Hole] {
        match self {
            Patch::Height { holes, .. } | Patch::Plane { holes, .. } => holes,
            Patch::Wall { .. } | Patch::HalfEllipsoid { .. } => &[],
        }
    }

    /// The Jacobian at (u, v), holes aside.
    fn jac_open(&self, u: f64, v: f64) -> f64 {
        match self {
            Patch::Height { field, .. } => {
                let (_, g) = field.eval(u, v);
                (1.0 + g[0] * g[0] + g[1] * g[1]).sqrt()
            }
            Patch::Plane { .. } | Patch::Wall { .. } => 1.0,
            Patch::HalfEllipsoid { radii, .. } => ellipsoid_jac(*radii, hemisphere(u, v)),
        }
    }

    /// The surface point and unit normal at (u, v) (outside holes).
    pub(crate) fn point(&self, u: f64, v: f64) -> Sample {
        match self {
            Patch::Height { field, .. } => {
                let (z, g) = field.eval(u, v);
                Sample {
                    p: [u, v, z],
                    n: unit([-g[0], -g[1], 1.0]),
                }
            }
            Patch::Plane { origin, eu, ev, .. } => Sample {
                p: [
                    origin[0] + u * eu[0] + v * ev[0],
                    origin[1] + u * eu[1] + v * ev[1],
                    origin[2] + u * eu[2] + v * ev[2],
                ],
                n: unit(cross(*eu, *ev)),
            },
            Patch::Wall {
                base, start, dir, ..
            } => {
                let (x, y) = (start[0] + u * dir[0], start[1] + u * dir[1]);
                // ∂p/∂u × ∂p/∂v = (dx, dy, ∂base/∂u) × (0, 0, 1) = (dy, −dx, 0).
                Sample {
                    p: [x, y, base.eval(x, y).0 + v],
                    n: [dir[1], -dir[0], 0.0],
                }
            }
            Patch::HalfEllipsoid {
                centre,
                radii: [a, b, c],
            } => {
                let s = hemisphere(u, v);
                Sample {
                    p: [
                        centre[0] + a * s[0],
                        centre[1] + b * s[1],
                        centre[2] + c * s[2],
                    ],
                    n: unit([s[0] / a, s[1] / b, s[2] / c]),
                }
            }
        }
    }

    /// Area of the part of the patch with v in [v0, v1], by the midpoint rule on an nu × nv grid
    /// (used only to share points between patches and strips in proportion to area).
    ///
    /// The sum of `jac` over the grid, in its order (the same bits), with less work: a cell is
    /// tested only against the holes whose u-span holds its column (a campaign's face has a hole
    /// per scar, hundreds in a long one), a plane's or wall's Jacobian of 1 is counted, not
    /// summed, and a half-ellipsoid's azimuths are turned into sines and cosines once per
    /// column, not once per cell.
    pub(crate) fn area(&self, v0: f64, v1: f64, nu: usize, nv: usize) -> f64 {
        // A campaign's survey k holds every scar of the surveys before it: its half-ellipsoids'
        // areas are taken from those surveys' (the same bits), or the work grows with the square
        // of the surveys (401 surveys: 2 minutes).
        let key = match self {
            Patch::HalfEllipsoid { centre, radii } => {
                let mut k = [0u64; 10];
                for (slot, x) in k
                    .iter_mut()
                    .zip(centre.iter().chain(radii).chain(&[v0, v1]))
                {
                    *slot = x.to_bits();
                }
                k[8] = nu as u64;
                k[9] = nv as u64;
                let known = ELLIPSOID_AREAS.lock().ok().and_then(|m| m.get(&k).copied());
                if let Some(a) = known {
                    return a;
                }
                Some(k)
            }
            _ => None,
        };
        let a = self.grid_area(v0, v1, nu, nv);
        if let (Some(k), Ok(mut m)) = (key, ELLIPSOID_AREAS.lock()) {
            if m.len() >= MAX_REMEMBERED {
                m.clear();
            }
            m.insert(k, a);
        }
        a
    }

    /// [`Patch::area`] computed.
    fn grid_area(&self, v0: f64, v1: f64, nu: usize, nv: usize) -> f64 {
        let [u0, u1, _, _] = self.domain();
        let (du, dv) = ((u1 - u0) / nu as f64, (v1 - v0) / nv as f64);
        let us: Vec<f64> = (0..nu).map(|i| u0 + (i as f64 + 0.5) * du).collect();
        let column_holes: Vec<Vec<&Hole>> = us
            .iter()
            .map(|&u| {
                self.holes()
                    .iter()
                    .filter(|h| {
                        let [lo, hi] = h.u_span(v0.min(v1));
                        (lo..=hi).contains(&u)
                    })
                    .collect()
            })
            .collect();
        let turns: Vec<(f64, f64)> = match self {
            Patch::HalfEllipsoid { .. } => us.iter().map(|u| u.sin_cos()).collect(),
            _ => Vec::new(),
        };
        let open = |i: usize, u: f64, v: f64| !column_holes[i].iter().any(|h| h.contains(u, v));
        if let Patch::Plane { .. } | Patch::Wall { .. } = self {
            // A Jacobian of 1: the sum is the number of open cells, exactly.
            let mut cells = 0u64;
            for j in 0..nv {
                let v = v0 + (j as f64 + 0.5) * dv;
                if self.holes().is_empty() {
                    cells += nu as u64;
                    continue;
                }
                for (i, &u) in us.iter().enumerate() {
                    cells += u64::from(open(i, u, v));
                }
            }
            return cells as f64 * du * dv;
        }
        let mut sum = 0.0;
        for j in 0..nv {
            let v = v0 + (j as f64 + 0.5) * dv;
            for (i, &u) in us.iter().enumerate() {
                sum += if !open(i, u, v) {
                    0.0
                } else if let Patch::HalfEllipsoid { radii, .. } = self {
                    ellipsoid_jac(*radii, hemisphere_turned(turns[i], v))
                } else {
                    self.jac_open(u, v)
                };
            }
        }
        sum * du * dv
    }
}

/// Half-ellipsoid areas computed in this process, by the bits of the patch and of the grid
/// (`Patch::area`); emptied when it holds [`MAX_REMEMBERED`].
static ELLIPSOID_AREAS: Mutex<BTreeMap<[u64; 10], f64>> = Mutex::new(BTreeMap::new());
/// Most areas remembered (160 KiB).
const MAX_REMEMBERED: usize = 2048;

/// Unit-hemisphere point (y ≥ 0) at azimuth φ and y = w: uniform (φ, w) is uniform by area.
fn hemisphere(phi: f64, w: f64) -> V3 {
    hemisphere_turned(phi.sin_cos(), w)
}

/// [`hemisphere`] given the azimuth's (sine, cosine).
fn hemisphere_turned((s, c): (f64, f64), w: f64) -> V3 {
    let r = (1.0 - w * w).max(0.0).sqrt();
    [r * c, w, r * s]
}

/// The area scale of the unit sphere mapped by diag(a, b, c) at its unit normal s.
fn ellipsoid_jac([a, b, c]: V3, s: V3) -> f64 {
    a * b * c * ((s[0] / a).powi(2) + (s[1] / b).powi(2) + (s[2] / c).powi(2)).sqrt()
}

/// The four vertical walls of a box with footprint [min, max] between heights zlo and zhi.
pub(crate) fn box_walls(min: [f64; 2], max: [f64; 2], zlo: f64, zhi: f64) -> Vec<Patch> {
    box_walls_on(&Base::plane(zlo), min, max, [0.0, zhi - zlo])
}

/// The four vertical walls of a box with footprint [min, max] standing on `base`: from
/// base + z[0] to base + z[1] along each edge (a block raised or dug into sloping ground).
pub(crate) fn box_walls_on(base: &Base, min: [f64; 2], max: [f64; 2], z: [f64; 2]) -> Vec<Patch> {
    let wall = |start: [f64; 2], dir: [f64; 2], len: f64| Patch::Wall {
        base: base.clone(),
        start,
        dir,
        len,
        z,
    };
    let (wx, wy) = (max[0] - min[0], max[1] - min[1]);
    vec![
        wall(min, [1.0, 0.0], wx),
        wall([min[0], max[1]], [1.0, 0.0], wx),
        wall(min, [0.0, 1.0], wy),
        wall([max[0], min[1]], [0.0, 1.0], wy),
    ]
}

/// Volume under `height·cos²(πr/2R)`, r < R: 2π·h·∫₀ᴿ r cos²(πr/2R) dr. With cos² = (1 + cos(πr/R))/2
/// and ∫₀ᴿ r cos(πr/R) dr = [r sin(kr)/k + cos(kr)/k²]₀ᴿ = −2R²/π² (k = π/R), the integral is
/// R²/4 − R²/π², so V = h·R²·(π/2 − 2/π).
pub(crate) fn bump_volume(radius: f64, height: f64) -> f64 {
    height * radius * radius * (FRAC_PI_2 - 2.0 / PI)
}

/// Volume of a spherical cap of height h on a sphere of radius R: πh²(3R − h)/3 (signed by h).
pub(crate) fn cap_volume(sphere_radius: f64, height: f64) -> f64 {
    let h = height.abs();
    height.signum() * PI * h * h * (3.0 * sphere_radius - h) / 3.0
}

/// Footprint radius of a spherical cap: sqrt(h(2R − h)).
pub(crate) fn cap_footprint(sphere_radius: f64, height: f64) -> f64 {
    let h = height.abs();
    (h * (2.0 * sphere_radius - h)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The midpoint rule as `Patch::area` states it: `jac` summed over the grid in order.
    fn summed(p: &Patch, v0: f64, v1: f64, nu: usize, nv: usize) -> f64 {
        let [u0, u1, _, _] = p.domain();
        let (du, dv) = ((u1 - u0) / nu as f64, (v1 - v0) / nv as f64);
        let mut sum = 0.0;
        for j in 0..nv {
            let v = v0 + (j as f64 + 0.5) * dv;
            for i in 0..nu {
                sum += p.jac(u0 + (i as f64 + 0.5) * du, v);
            }
        }
        sum * du * dv
    }

    /// `Patch::area` (holes tested by column, unit Jacobians counted, an ellipsoid's azimuths
    /// turned once per column, its areas remembered) is the plain sum, bit for bit: a face with
    /// rectangle, ellipse and tent holes, a hole-free plane, a wall, a heightfield with holes
    /// and features, a half-ellipsoid (twice: computed, then remembered), on whole domains and
    /// strips.
    #[test]
    fn area_is_the_plain_sum_bit_for_bit() {
        let holes = vec![
            Hole::Rect {
                min: [3.0, 2.0],
                max: [5.5, 4.0],
            },
            Hole::Ellipse {
                c: [10.0, 6.0],
                a: 2.5,
                b: 1.5,
            },
            Hole::BelowTent {
                cu: 17.0,
                peak: 5.0,
                slope: 1.2,
            },
            Hole::Ellipse {
                c: [25.0, 12.0],
                a: -1.0,
                b: 1.0,
            },
        ];
        let face = Patch::Plane {
            origin: [0.0, 0.0, 100.0],
            eu: [1.0, 0.0, 0.0],
            ev: [0.0, 0.0, 1.0],
            len: [31.0, 30.0],
            holes: holes.clone(),
        };
        let plain = Patch::Plane {
            origin: [0.0; 3],
            eu: [0.0, 1.0, 0.0],
            ev: [0.0, 0.0, 1.0],
            len: [2.3, 1.7],
            holes: Vec::new(),
        };
        let wall = Patch::Wall {
            base: Base::plane(1.0),
            start: [0.0, 0.0],
            dir: [0.6, 0.8],
            len: 4.0,
            z: [0.0, 2.5],
        };
        let ground = Patch::Height {
            field: Heightfield::new(
                Base {
                    z0: 1.0,
                    gx: 0.02,
                    gy: -0.01,
                    waves: vec![Wave {
                        amp: 0.3,
                        kx: 0.4,
                        ky: 0.1,
                        phase: 0.2,
                    }],
                },
                vec![
                    Feature::Cone {
                        c: [8.0, 8.0],
                        radius: 2.0,
                        height: 1.0,
                    },
                    Feature::Cap {
                        c: [20.0, 15.0],
                        sphere_radius: 3.0,
                        height: -0.8,
                    },
                ],
            ),
            min: [0.0, 0.0],
            max: [31.0, 30.0],
            holes,
        };
        let scar = Patch::HalfEllipsoid {
            centre: [5.0, 0.0, 112.0],
            radii: [2.1, 0.9, 1.7],
        };
        for p in [&face, &plain, &wall, &ground, &scar, &scar] {
            let [_, _, v0, v1] = p.domain();
            let mid = 0.5 * (v0 + v1);
            for (a, b, nu, nv) in [(v0, v1, 256, 256), (v0, mid, 256, 32), (mid, v1, 97, 13)] {
                assert_eq!(
                    p.area(a, b, nu, nv).to_bits(),
                    summed(p, a, b, nu, nv).to_bits(),
                    "{p:?} over v in [{a}, {b}], {nu} × {nv}"
                );
            }
        }
    }
}
