//! Analytic ground truth: M3C2 distances on synthetic surfaces equal the planted change.
//! Surfaces are sampled independently per epoch (uniform by area, 2 mm noise) at UTM-sized
//! coordinates.

mod common;

use common::{Rng, OFFSET};
use talus::io::result_table;
use talus::io::Point3;

fn g(p: Point3) -> Point3 {
    [p[0] + OFFSET[0], p[1] + OFFSET[1], p[2] + OFFSET[2]]
}

/// Run compare with `extra` flags; return (core xyz, distance, normals).
fn compare(before: &[Point3], after: &[Point3], extra: &[&str]) -> result_table::ResultTable {
    let dir = common::tempdir();
    let (b, a, out) = (
        dir.path().join("b.laz"),
        dir.path().join("a.laz"),
        dir.path().join("out"),
    );
    common::write_cloud(&b, before);
    common::write_cloud(&a, after);
    let o = common::run_compare(&b, &a, &out, extra);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    result_table::read(&out.join("m3c2.laz")).unwrap()
}

/// Core points every 0.5 m, normals over 0.5 m, cylinders 0.3 m × ±2 m: the scenes' scale.
const FINE: &[&str] = &[
    "--core-spacing",
    "0.5",
    "--normal-radius",
    "0.5",
    "--cyl-radius",
    "0.3",
    "--cyl-halflen",
    "2",
];

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// A plane, raised by 0.4 m inside a 6 m × 6 m square in epoch 2 (vertical change): interior core
/// points measure +0.4, the stable surroundings 0.
#[test]
fn vertical_bump_is_measured_exactly() {
    let h = 0.4;
    let sample = |seed: u64, raised: bool| {
        let mut r = Rng::new(seed);
        (0..60_000)
            .map(|_| {
                let (x, y) = (r.uniform() * 20.0, r.uniform() * 20.0);
                let inside = (7.0..13.0).contains(&x) && (7.0..13.0).contains(&y);
                let z = if raised && inside { h } else { 0.0 } + 0.002 * r.normal();
                g([x, y, z])
            })
            .collect::<Vec<_>>()
    };
    let t = compare(&sample(1, false), &sample(2, true), FINE);
    let d = t.column("m3c2_distance").unwrap();
    let (mut inner, mut outer) = (Vec::new(), Vec::new());
    for (p, &d) in t.xyz.iter().zip(d) {
        let (x, y) = (p[0] - OFFSET[0], p[1] - OFFSET[1]);
        if (8.0..12.0).contains(&x) && (8.0..12.0).contains(&y) {
            inner.push(d);
        } else if (!(6.0..14.0).contains(&x) || !(6.0..14.0).contains(&y))
            && (1.0..19.0).contains(&x)
            && (1.0..19.0).contains(&y)
        {
            outer.push(d);
        }
    }
    assert!(inner.len() > 40 && outer.len() > 300);
    // Each distance averages ~40 points of 2 mm noise per epoch: its error is ≈ 0.5 mm.
    for &d in &inner {
        assert!((d - h).abs() < 0.003, "inner distance {d}");
    }
    for &d in &outer {
        assert!(d.abs() < 0.003, "stable distance {d}");
    }
}

/// A plane tilted 30° about a skew axis, shifted 0.25 m along its normal: every distance is 0.25
/// and every normal is the plane's.
#[test]
fn tilted_plane_shifted_along_its_normal() {
    let n = {
        let v = [0.3f64, -0.4, 0.8660];
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / l, v[1] / l, v[2] / l]
    };
    // Two tangent vectors.
    let u = {
        let v = [n[2], 0.0, -n[0]];
        let l = (v[0] * v[0] + v[2] * v[2]).sqrt();
        [v[0] / l, 0.0, v[2] / l]
    };
    let w = [
        n[1] * u[2] - n[2] * u[1],
        n[2] * u[0] - n[0] * u[2],
        n[0] * u[1] - n[1] * u[0],
    ];
    let shift = 0.25;
    let sample = |seed: u64, off: f64| {
        let mut r = Rng::new(seed);
        (0..50_000)
            .map(|_| {
                let (a, b) = (r.uniform() * 20.0 - 10.0, r.uniform() * 20.0 - 10.0);
                let e = off + 0.002 * r.normal();
                g([
                    a * u[0] + b * w[0] + e * n[0],
                    a * u[1] + b * w[1] + e * n[1],
                    a * u[2] + b * w[2] + e * n[2],
                ])
            })
            .collect::<Vec<_>>()
    };
    let t = compare(
        &sample(3, 0.0),
        &sample(4, shift),
        &[
            "--core-spacing",
            "1.0",
            "--normal-radius",
            "0.6",
            "--cyl-radius",
            "0.4",
            "--cyl-halflen",
            "1.5",
            "--orientation",
            "up",
        ],
    );
    let d = t.column("m3c2_distance").unwrap();
    let nz = t.column("normal_z").unwrap();
    let mut interior = Vec::new();
    for (i, p) in t.xyz.iter().enumerate() {
        let q = [p[0] - OFFSET[0], p[1] - OFFSET[1], p[2] - OFFSET[2]];
        let a = q[0] * u[0] + q[1] * u[1] + q[2] * u[2];
        let b = q[0] * w[0] + q[1] * w[1] + q[2] * w[2];
        if a.abs() < 8.0 && b.abs() < 8.0 {
            interior.push(d[i]);
            assert!(
                (nz[i] - n[2]).abs() < 0.01,
                "normal z {} vs {}",
                nz[i],
                n[2]
            );
        }
    }
    assert!(interior.len() > 150);
    for &x in &interior {
        assert!((x - shift).abs() < 0.003, "distance {x}");
    }
    assert!((median(interior) - shift).abs() < 0.0005);
}

/// A vertical cliff face (plane y = 0, rock at y < 0, a plateau on top and a beach below) moved
/// 0.3 m outward (+y) in a 6 m-wide, 4 m-high patch: with `auto` orientation the face normals
/// point out of the rock and the patch measures +0.3 (material gained), the rest of the face 0.
#[test]
fn vertical_face_moved_horizontally() {
    let dy = 0.3;
    let sample = |seed: u64, moved: bool| {
        let mut r = Rng::new(seed);
        let mut pts = Vec::new();
        for _ in 0..120_000 {
            let x = r.uniform() * 20.0;
            let s = r.uniform() * 30.0; // 10 m plateau, 10 m face, 10 m beach
            let e = 0.002 * r.normal();
            let p = if s < 10.0 {
                [x, -10.0 + s, 10.0 + e]
            } else if s < 20.0 {
                let z = s - 10.0;
                let inside = moved && (7.0..13.0).contains(&x) && (3.0..7.0).contains(&z);
                [x, if inside { dy } else { 0.0 } + e, z]
            } else {
                [x, s - 20.0, e]
            };
            pts.push(g(p));
        }
        pts
    };
    let t = compare(&sample(5, false), &sample(6, true), FINE);
    let d = t.column("m3c2_distance").unwrap();
    let ny = t.column("normal_y").unwrap();
    let (mut patch, mut face) = (Vec::new(), Vec::new());
    for (i, p) in t.xyz.iter().enumerate() {
        let (x, y, z) = (p[0] - OFFSET[0], p[1] - OFFSET[1], p[2] - OFFSET[2]);
        let on_face = y.abs() < 0.05 && (1.0..9.0).contains(&z) && (1.0..19.0).contains(&x);
        if !on_face {
            continue;
        }
        assert!(
            ny[i] > 0.99,
            "face normal at {x:.2},{z:.2} has n_y {}",
            ny[i]
        );
        if (8.0..12.0).contains(&x) && (4.0..6.0).contains(&z) {
            patch.push(d[i]);
        } else if !(6.0..14.0).contains(&x) || !(2.0..8.0).contains(&z) {
            face.push(d[i]);
        }
    }
    assert!(
        patch.len() > 15 && face.len() > 100,
        "{} {}",
        patch.len(),
        face.len()
    );
    for &x in &patch {
        assert!((x - dy).abs() < 0.003, "patch distance {x}");
    }
    for &x in &face {
        assert!(x.abs() < 0.003, "face distance {x}");
    }
}
