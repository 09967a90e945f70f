//! A terrestrial laser scan of triangle meshes, and the volume between two meshes: the tests'
//! own instruments for scenes given as surfaces (`tests/data/trier`), written here apart from
//! what they check.
//!
//! The scan: rays from the scanner on a regular grid of azimuth and elevation, each stopped at
//! the first triangle it meets (Möller & Trumbore 1997, "Fast, minimum storage ray-triangle
//! intersection"), found through a spherical depth buffer (each triangle is tested against the
//! rays of its angular bounding box only), with Gaussian range noise along the ray.
//!
//! The volume: an orthographic depth buffer of each mesh along a direction, on a fine grid of
//! the plane across it; the volume between the first surfaces met is the sum over the cells of
//! the difference of their depths times the cell's area (exact for surfaces that are graphs
//! along the direction, to the grid's resolution).

use talus::volume::Mesh;

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit(v: V3) -> V3 {
    let l = dot(v, v).sqrt();
    [v[0] / l, v[1] / l, v[2] / l]
}

/// Where the ray from `o` along `d` meets triangle (a, b, c), if it does (t > 0).
fn hit(o: V3, d: V3, a: V3, b: V3, c: V3) -> Option<f64> {
    let (e1, e2) = (sub(b, a), sub(c, a));
    let p = cross(d, e2);
    let det = dot(e1, p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = sub(o, a);
    let u = dot(s, p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = cross(s, e1);
    let v = dot(d, q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = dot(e2, q) * inv;
    (t > 0.0).then_some(t)
}

/// Every triangle of `meshes`, as vertex triples.
fn triangles(meshes: &[&Mesh]) -> Vec<[V3; 3]> {
    meshes
        .iter()
        .flat_map(|m| {
            m.faces.iter().map(|f| {
                [
                    m.vertices[f[0] as usize],
                    m.vertices[f[1] as usize],
                    m.vertices[f[2] as usize],
                ]
            })
        })
        .collect()
}

/// The points a scanner at `scanner` records of `meshes` with angular steps of `step` radians
/// (the grid offset by `shift` steps), range noise `noise` (m, seeded by `seed`); only the
/// points `keep` accepts.
pub fn scan(
    meshes: &[&Mesh],
    scanner: V3,
    step: f64,
    shift: [f64; 2],
    noise: f64,
    seed: u64,
    keep: impl Fn(&V3) -> bool,
) -> Vec<V3> {
    let tris = triangles(meshes);
    let angles = |p: V3| {
        let v = sub(p, scanner);
        [v[1].atan2(v[0]), v[2].atan2(v[0].hypot(v[1]))]
    };
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for t in &tris {
        for p in t {
            let a = angles(*p);
            for k in 0..2 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(a[k]);
            }
        }
    }
    let cols = ((hi[0] - lo[0]) / step).ceil() as usize + 2;
    let rows = ((hi[1] - lo[1]) / step).ceil() as usize + 2;
    let dir = |i: usize, j: usize| {
        let az = lo[0] + (i as f64 + shift[0]) * step;
        let el = lo[1] + (j as f64 + shift[1]) * step;
        [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()]
    };
    let mut depth = vec![f64::INFINITY; cols * rows];
    for t in &tris {
        let a = t.map(angles);
        let (mut l, mut h) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in &a {
            for k in 0..2 {
                l[k] = l[k].min(p[k]);
                h[k] = h[k].max(p[k]);
            }
        }
        let span = |k: usize| {
            let first = ((l[k] - lo[k]) / step - shift[k]).floor().max(0.0) as usize;
            let last = ((h[k] - lo[k]) / step - shift[k]).ceil().max(0.0) as usize;
            first..=last
        };
        for j in span(1) {
            for i in span(0) {
                if i >= cols || j >= rows {
                    continue;
                }
                if let Some(d) = hit(scanner, dir(i, j), t[0], t[1], t[2]) {
                    let cell = &mut depth[j * cols + i];
                    if d < *cell {
                        *cell = d;
                    }
                }
            }
        }
    }
    let mut rng = super::Rng::new(seed);
    let mut out = Vec::new();
    for j in 0..rows {
        for i in 0..cols {
            let d = depth[j * cols + i];
            if !d.is_finite() {
                continue;
            }
            let r = d + noise * gaussian(&mut rng);
            let u = dir(i, j);
            let p = [
                scanner[0] + r * u[0],
                scanner[1] + r * u[1],
                scanner[2] + r * u[2],
            ];
            if keep(&p) {
                out.push(p);
            }
        }
    }
    out
}

/// A standard normal value (Box–Muller).
fn gaussian(rng: &mut super::Rng) -> f64 {
    let u1 = 1.0 - rng.uniform();
    let u2 = rng.uniform();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The volume between the first surfaces of `before` and of `after` seen from far along `view`
/// (unit; positive where `after` lies nearer the viewer: material gained), over the cells of
/// side `cell` across `view` whose centres lie within `radius` of `centre`; and the area where
/// the two differ by more than `1e-6`.
pub fn volume_between(
    before: &[&Mesh],
    after: &[&Mesh],
    view: V3,
    centre: V3,
    radius: f64,
    cell: f64,
) -> (f64, f64) {
    let w = unit(view);
    let helper = if w[2].abs() < 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let u = unit(cross(helper, w));
    let v = cross(w, u);
    let n = (2.0 * radius / cell).ceil() as usize;
    let base = [
        dot(centre, u) - radius,
        dot(centre, v) - radius,
        dot(centre, w),
    ];
    let depth = |meshes: &[&Mesh]| {
        let mut z = vec![f64::NEG_INFINITY; n * n];
        for t in triangles(meshes) {
            let q = t.map(|p| [dot(p, u) - base[0], dot(p, v) - base[1], dot(p, w)]);
            let (lo, hi) = (
                [0, 1].map(|k| q.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min)),
                [0, 1].map(|k| q.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max)),
            );
            let first = lo.map(|x| (x / cell - 0.5).ceil().max(0.0) as usize);
            let last = hi.map(|x| ((x / cell - 0.5).floor().max(-1.0) + 1.0) as usize);
            for j in first[1]..last[1].min(n) {
                for i in first[0]..last[0].min(n) {
                    // The ray along −w through the cell's centre, from far on the viewer's side.
                    let (x, y) = ((i as f64 + 0.5) * cell, (j as f64 + 0.5) * cell);
                    let o = [x, y, base[2] + 1e4];
                    if let Some(t) = hit(o, [0.0, 0.0, -1.0], q[0], q[1], q[2]) {
                        let h = o[2] - t;
                        let c = &mut z[j * n + i];
                        if h > *c {
                            *c = h;
                        }
                    }
                }
            }
        }
        z
    };
    let (z0, z1) = (depth(before), depth(after));
    let (mut vol, mut area) = (0.0, 0.0);
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (
                (i as f64 + 0.5) * cell - radius,
                (j as f64 + 0.5) * cell - radius,
            );
            if x.hypot(y) > radius {
                continue;
            }
            let (a, b) = (z0[j * n + i], z1[j * n + i]);
            if a.is_finite() && b.is_finite() {
                vol += (b - a) * cell * cell;
                if (b - a).abs() > 1e-6 {
                    area += cell * cell;
                }
            }
        }
    }
    (vol, area)
}
