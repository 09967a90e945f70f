//! face: a rock face scanned alone by a terrestrial laser scanner 300 m away, as face deliveries
//! usually come (no beach in front, no plateau behind).
//!
//! The face is a surface given in its own frame: a point at strike position `a` and up-dip
//! position `b` lies `f(a, b)` out of the face's mean plane (along its outward normal `n`), so
//! that it is a graph over the plane whatever it does in the world: a ledge (a shelf whose top
//! faces up), a bay (a recess, concave in plan), an overhang (a roof whose underside faces down)
//! and rough rock (a sum of plane waves from decimetres to metres). The change between the
//! epochs is a sum of cos² bumps in that frame (scars into the rock, material gained), so each
//! event's volume is exact: the material between two graphs over a plane is ∫ Δf da db, and a
//! bump h·cos²(πr/2R) holds h·R²(π/2 − 2/π) (`surface::bump_volume`).
//!
//! The points are what a scanner records: rays from the scanner on a regular grid of azimuth
//! and elevation (each epoch's grid offset by a fraction of a step, as two scans never repeat
//! their angles), each stopped at the first surface it meets (found by marching along the ray in
//! the face frame and bisecting the crossing), with Gaussian range noise along the ray. So the
//! density falls off with the incidence, a ledge's top is in the shadow of its own lip from a
//! scanner below it, and nothing is recorded beyond the face's outline.

use rayon::prelude::*;

use super::scenes::ModelEvent;
use super::surface::{bump_volume, V3};
use talus_base::geom::dot;
use talus_base::rng::Rng;

/// Strike length and up-dip height of the face (m).
const WIDTH: f64 = 60.0;
const HEIGHT: f64 = 40.0;
/// Height of the face's foot (local z).
const FOOT: f64 = 100.0;
/// Horizontal distance of the scanner from the face's foot, and its height above the foot.
pub(crate) const RANGE: f64 = 300.0;
const SCANNER_HEIGHT: f64 = 1.6;

/// A plane wave of the rock's roughness in the face frame.
#[derive(Debug, Clone)]
struct Wave {
    amp: f64,
    ka: f64,
    kb: f64,
    phase: f64,
}

/// A cos² bump `height · cos²(π r / 2R)` in the face frame (a, b).
#[derive(Debug, Clone, Copy)]
struct Bump {
    c: [f64; 2],
    radius: f64,
    height: f64,
}

impl Bump {
    fn at(&self, a: f64, b: f64) -> f64 {
        let r = (a - self.c[0]).hypot(b - self.c[1]);
        if r >= self.radius {
            return 0.0;
        }
        let c = (std::f64::consts::FRAC_PI_2 * r / self.radius).cos();
        self.height * c * c
    }
}

/// The logistic step 1 / (1 + e^(−x/w)).
fn step(x: f64, w: f64) -> f64 {
    1.0 / (1.0 + (-x / w).exp())
}

/// A smooth window: ≈ 1 for a ∈ [lo, hi], ≈ 0 a few `w` outside.
fn window(a: f64, lo: f64, hi: f64, w: f64) -> f64 {
    step(a - lo, w) * step(hi - a, w)
}

/// One of the scene's planted changes.
#[derive(Debug, Clone)]
struct Planted {
    bump: Bump,
    what: &'static str,
}

/// The face scene: its frame, shape, changes and scanner (local coordinates).
#[derive(Debug, Clone)]
pub(crate) struct FaceScene {
    /// The frame: origin at the foot's left end, strike `u`, up-dip `w`, outward normal `n`.
    origin: V3,
    u: V3,
    w: V3,
    n: V3,
    waves: Vec<Wave>,
    changes: Vec<Planted>,
    /// The scanner's position (local coordinates).
    pub scanner: V3,
}

impl FaceScene {
    /// The face dipping at `dip_deg`, facing −y (rock at +y, as the cliff scene's).
    pub(crate) fn new(dip_deg: f64) -> Self {
        let d = dip_deg.to_radians();
        let (sd, cd) = d.sin_cos();
        let n = [0.0, -sd, cd];
        let w = [0.0, cd, sd];
        let u = [1.0, 0.0, 0.0];
        let origin = [0.0, 0.0, FOOT];
        // Rough rock: metres to decimetres, every direction (fixed: the scene does not depend on
        // the seed).
        let waves = [
            (0.25, 7.1, 0.3, 0.4),
            (0.18, 5.3, 2.1, 1.7),
            (0.12, 3.7, -1.2, 2.9),
            (0.08, 2.3, 0.9, 0.6),
            (0.05, 1.3, -0.4, 4.1),
            (0.03, 0.7, 1.9, 5.3),
        ]
        .iter()
        .map(|&(amp, lambda, turn, phase): &(f64, f64, f64, f64)| {
            let k = std::f64::consts::TAU / lambda;
            Wave {
                amp,
                ka: k * turn.cos(),
                kb: k * turn.sin(),
                phase,
            }
        })
        .collect();
        let changes = vec![
            Planted {
                bump: Bump {
                    c: [12.0, 30.0],
                    radius: 2.5,
                    height: -1.0,
                },
                what: "rockfall scar on the open face: 1 m deep, R = 2.5 m",
            },
            Planted {
                bump: Bump {
                    c: [22.0, 34.0],
                    radius: 3.0,
                    height: -2.0,
                },
                what: "deep rockfall scar on the open face: 2 m deep, R = 3 m",
            },
            Planted {
                bump: Bump {
                    c: [34.0, 18.0],
                    radius: 2.0,
                    height: -0.8,
                },
                what: "rockfall scar in the bay: 0.8 m deep, R = 2 m",
            },
            Planted {
                bump: Bump {
                    c: [14.0, 15.2],
                    radius: 1.5,
                    height: 0.8,
                },
                what:
                    "debris come to rest on the ledge, against the face above it: 0.8 m, R = 1.5 m",
            },
            Planted {
                bump: Bump {
                    c: [50.0, 26.3],
                    radius: 2.0,
                    height: -1.0,
                },
                what: "the overhang's lip collapsed: 1 m deep, R = 2 m",
            },
            Planted {
                bump: Bump {
                    c: [56.0, 12.0],
                    radius: 1.5,
                    height: 0.6,
                },
                what: "a block toppling out of the face: 0.6 m, R = 1.5 m",
            },
        ];
        let mid = [WIDTH / 2.0, 0.0, FOOT + SCANNER_HEIGHT];
        let scanner = [mid[0], -RANGE, mid[2]];
        FaceScene {
            origin,
            u,
            w,
            n,
            waves,
            changes,
            scanner,
        }
    }

    /// How far the face of epoch `epoch` (0 before, 1 after) lies out of the mean plane at
    /// (a, b): roughness, the ledge, the bay, the overhang and, after, the changes.
    pub(crate) fn offset(&self, epoch: usize, a: f64, b: f64) -> f64 {
        let mut f: f64 = self
            .waves
            .iter()
            .map(|w| w.amp * (w.ka * a + w.kb * b + w.phase).sin())
            .sum();
        // The ledge: below b = 14 the face stands 1.2 m further out, along a ∈ [4, 24].
        f += 1.2 * step(14.0 - b, 0.15) * window(a, 4.0, 24.0, 0.8);
        // The bay: a recess 3 m deep and 16 m wide, the face's whole height.
        let x = (a - 34.0) / 8.0;
        if x.abs() < 1.0 {
            let c = (std::f64::consts::FRAC_PI_2 * x).cos();
            f -= 3.0 * c * c;
        }
        // The overhang: above b = 26 the face stands 1.5 m further out along a ∈ [44, 57]: its
        // underside faces down.
        f += 1.5 * step(b - 26.0, 0.25) * window(a, 44.0, 57.0, 0.8);
        if epoch == 1 {
            f += self.changes.iter().map(|c| c.bump.at(a, b)).sum::<f64>();
        }
        f
    }

    /// The local point at frame coordinates (a, b, c).
    pub(crate) fn point(&self, a: f64, b: f64, c: f64) -> V3 {
        std::array::from_fn(|k| self.origin[k] + a * self.u[k] + b * self.w[k] + c * self.n[k])
    }

    /// The frame coordinates (a, b, c) of local point `p`.
    pub(crate) fn frame(&self, p: V3) -> V3 {
        let d = [
            p[0] - self.origin[0],
            p[1] - self.origin[1],
            p[2] - self.origin[2],
        ];
        [dot(&d, &self.u), dot(&d, &self.w), dot(&d, &self.n)]
    }

    /// Centre of the face's footprint (the vertical axis `--rotate` turns about).
    pub(crate) fn centre(&self) -> [f64; 2] {
        let p = self.point(WIDTH / 2.0, HEIGHT / 2.0, 0.0);
        [p[0], p[1]]
    }

    /// The height of the face's centre (the point `--turn` turns about).
    pub(crate) fn centre_height(&self) -> f64 {
        self.point(WIDTH / 2.0, HEIGHT / 2.0, 0.0)[2]
    }

    /// The planted changes as events (their centres on the before surface).
    pub(crate) fn events(&self) -> Vec<ModelEvent> {
        self.changes
            .iter()
            .map(|c| {
                let [a, b] = c.bump.c;
                let centre = self.point(a, b, self.offset(0, a, b));
                let r = c.bump.radius;
                ModelEvent {
                    volume_m3: bump_volume(r, c.bump.height),
                    centre,
                    radius_m: r,
                    footprint: super::scenes::Footprint::Frame {
                        min: [a - r, b - r],
                        max: [a + r, b + r],
                    },
                    covered_volume_m3: None,
                    description: c.what.into(),
                }
            })
            .collect()
    }

    /// Where the ray from the scanner along unit `d` first meets epoch `epoch`'s face, if it
    /// does within the face's outline.
    fn hit(&self, epoch: usize, d: V3) -> Option<V3> {
        let s = self.frame(self.scanner);
        let df = [dot(&d, &self.u), dot(&d, &self.w), dot(&d, &self.n)];
        if df[2] >= 0.0 {
            return None;
        }
        // The face lies within these offsets of its plane: the ray's stretch between them.
        let (hi, lo) = (4.0, -6.0);
        let (t0, t1) = ((hi - s[2]) / df[2], (lo - s[2]) / df[2]);
        let at = |t: f64| [s[0] + t * df[0], s[1] + t * df[1], s[2] + t * df[2]];
        let inside = |q: &V3| (0.0..=WIDTH).contains(&q[0]) && (0.0..=HEIGHT).contains(&q[1]);
        let gap = |t: f64| {
            let q = at(t);
            q[2] - self.offset(epoch, q[0], q[1])
        };
        // Sphere tracing (Hart 1996): the offset changes by at most `slope` per metre along the
        // face, so the surface is no nearer than gap / (|d_c| + slope·|d_ab|) along the ray.
        let reach = df[2].abs() + self.slope(epoch) * df[0].hypot(df[1]);
        let (mut prev, mut t) = (t0, t0);
        let mut was_inside = inside(&at(t0));
        let mut g = gap(t0);
        while t < t1 {
            t = (t + (g / reach).max(1e-3)).min(t1);
            let q = at(t);
            let now_inside = inside(&q);
            // Outside the outline there is no surface: step to the outline, no further.
            g = if now_inside {
                gap(t)
            } else {
                let da = (-q[0]).max(q[0] - WIDTH).max(0.0);
                let db = (-q[1]).max(q[1] - HEIGHT).max(0.0);
                ((q[2] - lo) / reach).min(da.hypot(db) / df[0].hypot(df[1]).max(1e-9)) * reach
            };
            if now_inside && g <= 0.0 {
                if !was_inside {
                    // Entered the outline behind the surface: the ray went through rock that
                    // lies outside the scanned face.
                    return None;
                }
                let (mut lo_t, mut hi_t) = (prev, t);
                for _ in 0..30 {
                    let m = 0.5 * (lo_t + hi_t);
                    if gap(m) > 0.0 {
                        lo_t = m;
                    } else {
                        hi_t = m;
                    }
                }
                let tm = 0.5 * (lo_t + hi_t);
                let q = at(tm);
                return Some(self.point(q[0], q[1], q[2]));
            }
            was_inside = now_inside;
            prev = t;
        }
        None
    }

    /// A bound of |∇f| over the face (per metre along it): the sum of every term's steepest
    /// slope.
    fn slope(&self, epoch: usize) -> f64 {
        let rough: f64 = self.waves.iter().map(|w| w.amp * w.ka.hypot(w.kb)).sum();
        // Logistic steps rise by h over a slope of at most h / 4w; the bay's cos² by 3π/16.
        let shapes = 1.2 / (4.0 * 0.15)
            + 1.2 / (4.0 * 0.8) * 2.0
            + 1.5 / (4.0 * 0.25)
            + 1.5 / (4.0 * 0.8) * 2.0
            + 3.0 * std::f64::consts::PI / 16.0;
        let changes: f64 = if epoch == 1 {
            self.changes
                .iter()
                .map(|c| c.bump.height.abs() * std::f64::consts::FRAC_PI_2 / c.bump.radius)
                .sum()
        } else {
            0.0
        };
        rough + shapes + changes
    }

    /// The angular box (azimuth, elevation: radians) of the face seen from the scanner.
    fn angles(&self) -> [[f64; 2]; 2] {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for a in [0.0, WIDTH] {
            for b in [0.0, HEIGHT] {
                for c in [-6.0, 4.0] {
                    let p = self.point(a, b, c);
                    let v = [
                        p[0] - self.scanner[0],
                        p[1] - self.scanner[1],
                        p[2] - self.scanner[2],
                    ];
                    let az = v[1].atan2(v[0]);
                    let el = v[2].atan2(v[0].hypot(v[1]));
                    for (k, x) in [az, el].into_iter().enumerate() {
                        lo[k] = lo[k].min(x);
                        hi[k] = hi[k].max(x);
                    }
                }
            }
        }
        [lo, hi]
    }

    /// The points of epoch `epoch` scanned on an angular grid of step `step` (radians), offset
    /// by `shift` steps (each in [0, 1)), with range noise `noise` (m), in scan order (by
    /// elevation row, then azimuth).
    fn scan_grid(
        &self,
        epoch: usize,
        step: f64,
        shift: [f64; 2],
        noise: f64,
        seed: u64,
    ) -> Vec<V3> {
        let [lo, hi] = self.angles();
        let rows = ((hi[1] - lo[1]) / step).ceil() as usize + 1;
        let cols = ((hi[0] - lo[0]) / step).ceil() as usize + 1;
        (0..rows)
            .into_par_iter()
            .flat_map_iter(|j| {
                let mut rng = Rng::new(seed, ((epoch as u64) << 32) | j as u64);
                let el = lo[1] + (j as f64 + shift[1]) * step;
                let mut row = Vec::new();
                for i in 0..cols {
                    let az = lo[0] + (i as f64 + shift[0]) * step;
                    let d = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
                    if let Some(p) = self.hit(epoch, d) {
                        let e = noise * rng.normal();
                        row.push([p[0] + e * d[0], p[1] + e * d[1], p[2] + e * d[2]]);
                    }
                }
                row
            })
            .collect()
    }

    /// About `points` points of epoch `epoch`: the angular step is found from a coarse scan's
    /// count (hits grow as 1 / step²).
    pub(crate) fn scan(&self, epoch: usize, points: u64, noise: f64, seed: u64) -> Vec<V3> {
        let coarse = 0.4 / RANGE;
        let n0 = self
            .scan_grid(epoch, coarse, [0.5, 0.5], 0.0, seed)
            .len()
            .max(1);
        // The same step for both epochs (from the before face), so that their densities compare.
        let n_before = if epoch == 0 {
            n0
        } else {
            self.scan_grid(0, coarse, [0.5, 0.5], 0.0, seed)
                .len()
                .max(1)
        };
        let step = coarse * (n_before as f64 / points.max(1) as f64).sqrt();
        let mut rng = Rng::new(seed, 0xFACE_0000 + epoch as u64);
        let shift = [rng.uniform(), rng.uniform()];
        self.scan_grid(epoch, step, shift, noise, seed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_frame_is_orthonormal_and_round_trips() {
        for dip in [70.0, 90.0, 100.0] {
            let f = FaceScene::new(dip);
            assert!((dot(&f.u, &f.w)).abs() < 1e-12 && dot(&f.u, &f.n).abs() < 1e-12);
            assert!(dot(&f.w, &f.n).abs() < 1e-12);
            let p = f.point(12.0, 7.0, -0.4);
            let q = f.frame(p);
            for (x, y) in q.iter().zip([12.0, 7.0, -0.4]) {
                assert!((x - y).abs() < 1e-9, "{q:?}");
            }
        }
    }

    #[test]
    fn scanned_points_lie_on_the_face_and_face_the_scanner() {
        let f = FaceScene::new(70.0);
        let pts = f.scan(0, 20_000, 0.0, 3);
        assert!(pts.len() > 10_000, "{}", pts.len());
        for p in &pts {
            let [a, b, c] = f.frame(*p);
            assert!(
                (c - f.offset(0, a, b)).abs() < 1e-6,
                "{p:?} off the surface"
            );
            assert!((0.0..=WIDTH).contains(&a) && (0.0..=HEIGHT).contains(&b));
        }
    }

    #[test]
    fn the_ledge_top_is_shadowed_and_the_overhang_underside_seen() {
        // From a scanner at the foot, rays meet the shelf (the step at b = 14, facing up) at a
        // grazing angle, the little of it they reach past its lip; the roof's underside (the
        // step at b = 26, facing down) is in plain view.
        let f = FaceScene::new(70.0);
        let pts = f.scan(0, 200_000, 0.0, 5);
        let count = |a: [f64; 2], b: [f64; 2]| {
            pts.iter()
                .filter(|p| {
                    let q = f.frame(**p);
                    (a[0]..a[1]).contains(&q[0]) && (b[0]..b[1]).contains(&q[1])
                })
                .count()
        };
        let open = count([8.0, 20.0], [5.0, 5.4]);
        let shelf = count([8.0, 20.0], [13.8, 14.2]);
        assert!(open > 100, "{open}");
        assert!(shelf * 2 < open, "shelf {shelf} vs open face {open}");
        let roof = count([8.0, 20.0].map(|a| a + 38.0), [25.8, 26.2]);
        assert!(roof > open, "roof {roof} vs open face {open}");
    }

    #[test]
    fn planted_volumes_are_the_integral_of_the_offset_change() {
        let f = FaceScene::new(70.0);
        for e in f.events() {
            let super::super::scenes::Footprint::Frame { min, max } = e.footprint else {
                panic!("a frame footprint");
            };
            let h = 0.01;
            let (na, nb) = (
                ((max[0] - min[0]) / h) as usize,
                ((max[1] - min[1]) / h) as usize,
            );
            let mut v = 0.0;
            for i in 0..na {
                for j in 0..nb {
                    let (a, b) = (min[0] + (i as f64 + 0.5) * h, min[1] + (j as f64 + 0.5) * h);
                    v += (f.offset(1, a, b) - f.offset(0, a, b)) * h * h;
                }
            }
            assert!(
                (v - e.volume_m3).abs() < 2e-3 * e.volume_m3.abs(),
                "{v} vs {}",
                e.volume_m3
            );
        }
    }
}
