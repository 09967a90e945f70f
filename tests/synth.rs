//! Tests of `talus synth`: files read back by las-rs (an independent reader), closed-form volumes
//! checked against numerical integration of the two analytic surfaces, volumes re-measured from the
//! written points, noise and density statistics, determinism, rotation, density2 and streaming.

use std::path::Path;

use talus::synth::{
    epoch_chunks, scene_model, synth, Footprint, SceneKind, SynthOptions, Truth, CHUNK_POINTS,
    CRS_EPSG, ORIGIN, UTM33N_WKT,
};

const SMALL: [SceneKind; 6] = [
    SceneKind::Hill,
    SceneKind::Cube,
    SceneKind::Spheres,
    SceneKind::Cubes,
    SceneKind::Cliff,
    SceneKind::Stable,
];

/// All points of a LAS/LAZ file, read with las-rs.
fn read_points(path: &Path) -> (las::Header, Vec<[f64; 3]>) {
    let mut reader = las::Reader::from_path(path).expect("readable LAS");
    let header = reader.header().clone();
    let data = reader.read_all().expect("points");
    let pts = data
        .x()
        .zip(data.y())
        .zip(data.z())
        .map(|((x, y), z)| [x, y, z])
        .collect();
    (header, pts)
}

fn opts() -> SynthOptions {
    SynthOptions::default()
}

#[test]
fn scene_names_parse() {
    for k in SceneKind::ALL {
        assert_eq!(k.name().parse::<SceneKind>().unwrap(), k);
    }
    let err = "dune".parse::<SceneKind>().unwrap_err().to_string();
    assert!(
        err.contains("hill") && err.contains("large") && err.contains("dune"),
        "{err}"
    );
}

#[test]
fn bad_options_are_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    for o in [
        SynthOptions {
            density2: 0.0,
            ..opts()
        },
        SynthOptions {
            noise: Some(f64::NAN),
            ..opts()
        },
        SynthOptions {
            points: Some(10),
            ..opts()
        },
    ] {
        let e = synth(SceneKind::Hill, &o, dir.path()).unwrap_err();
        assert_eq!(e.exit_code(), 2, "{e}");
    }
    // An output "directory" that is a file: a typed output error, nothing panics.
    let file = dir.path().join("not-a-dir");
    std::fs::write(&file, b"x").unwrap();
    let e = synth(SceneKind::Hill, &opts(), &file).unwrap_err();
    assert!(matches!(e, talus::Error::Output { .. }), "{e}");
    let e = synth(
        SceneKind::Large,
        &SynthOptions {
            points: Some(1000),
            ..opts()
        },
        dir.path(),
    )
    .unwrap_err();
    assert_eq!(e.exit_code(), 2);
}

/// truth.json holds the returned truth (floats to within decimal round-trip error).
fn same_truth(a: &Truth, b: &Truth) {
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * x.abs().max(1.0);
    assert_eq!(
        (&a.scene, a.seed, &a.epochs, a.points),
        (&b.scene, b.seed, &b.epochs, b.points)
    );
    assert_eq!((a.crs_epsg, &a.crs_wkt), (b.crs_epsg, &b.crs_wkt));
    assert!((0..3).all(|k| close(a.shift_m[k], b.shift_m[k])));
    assert!(close(a.noise_m, b.noise_m) && close(a.total_gain_m3, b.total_gain_m3));
    assert!(close(a.total_loss_m3, b.total_loss_m3));
    assert_eq!(a.events.len(), b.events.len());
    for (e, f) in a.events.iter().zip(&b.events) {
        assert_eq!(
            (e.id, &e.kind, &e.description),
            (f.id, &f.kind, &f.description)
        );
        assert!(close(e.volume_m3, f.volume_m3) && close(e.radius_m, f.radius_m));
        assert!((0..3).all(|k| close(e.centre[k], f.centre[k])));
    }
}

/// Every small scene writes two LAS 1.4 files that las-rs reads back with the advertised count,
/// header bounds that match the points, 1 mm scale, the WKT CRS, and a truth.json equal to the
/// returned truth.
#[test]
fn each_scene_writes_readable_las() {
    for (i, kind) in SMALL.into_iter().enumerate() {
        let dir = tempfile::tempdir().unwrap();
        // Alternate LAS and LAZ so both writers are exercised.
        let o = SynthOptions {
            laz: i % 2 == 0,
            ..opts()
        };
        let truth = synth(kind, &o, dir.path()).unwrap();
        assert_eq!(truth.scene, kind.name());
        assert_eq!(truth.points, [kind.default_points(); 2]);
        let json = std::fs::read(dir.path().join("truth.json")).unwrap();
        let back: Truth = serde_json::from_slice(&json).unwrap();
        same_truth(&back, &truth);
        for e in 0..2 {
            let path = dir.path().join(&truth.epochs[e]);
            let ext = if o.laz { "laz" } else { "las" };
            assert_eq!(path.extension().unwrap(), ext);
            let (h, pts) = read_points(&path);
            assert_eq!(h.version(), las::Version::new(1, 4));
            assert_eq!(h.point_format().to_u8().unwrap(), 6);
            assert_eq!(h.point_format().is_compressed, o.laz);
            assert_eq!(h.number_of_points(), truth.points[e]);
            assert_eq!(pts.len() as u64, truth.points[e]);
            assert_eq!(h.transforms().x.scale, 0.001);
            assert_eq!(h.transforms().z.scale, 0.001);
            let wkt = h.get_wkt_crs_bytes().expect("WKT CRS VLR");
            let wkt = std::str::from_utf8(wkt).unwrap().trim_end_matches('\0');
            assert_eq!(wkt, UTM33N_WKT);
            assert!(wkt.contains(&format!("AUTHORITY[\"EPSG\",\"{CRS_EPSG}\"]]")));
            let b = h.bounds();
            let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for p in &pts {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            // las-rs rounds the header bounds outward to the 1 mm grid, which can move an
            // on-grid value by one step through floating-point division.
            let (bmin, bmax) = ([b.min.x, b.min.y, b.min.z], [b.max.x, b.max.y, b.max.z]);
            for k in 0..3 {
                assert!(
                    bmin[k] <= lo[k] && lo[k] - bmin[k] < 0.0011,
                    "{kind} min {k}"
                );
                assert!(
                    bmax[k] >= hi[k] && bmax[k] - hi[k] < 0.0011,
                    "{kind} max {k}"
                );
            }
            // UTM-like placement: ground near z = 100, scene within a few hundred metres of the
            // origin.
            assert!(
                lo[0] >= ORIGIN[0] - 50.0 && hi[0] <= ORIGIN[0] + 100.0,
                "{kind}"
            );
            assert!(
                lo[1] >= ORIGIN[1] - 50.0 && hi[1] <= ORIGIN[1] + 100.0,
                "{kind}"
            );
            assert!(lo[2] > 95.0 && hi[2] < 135.0, "{kind}: z {lo:?} {hi:?}");
        }
        // No temporary file is left behind.
        for f in std::fs::read_dir(dir.path()).unwrap() {
            let name = f.unwrap().file_name();
            assert!(!name.to_string_lossy().ends_with(".tmp"), "{name:?}");
        }
        for e in &truth.events {
            assert_eq!(e.kind == "gain", e.volume_m3 > 0.0);
        }
    }
}

/// Midpoint-rule integral of f over [x0, x1] × [y0, y1] on an n × n grid.
fn integrate(x0: f64, x1: f64, y0: f64, y1: f64, n: usize, f: impl Fn(f64, f64) -> f64) -> f64 {
    let (dx, dy) = ((x1 - x0) / n as f64, (y1 - y0) / n as f64);
    let mut s = 0.0;
    for j in 0..n {
        let y = y0 + (j as f64 + 0.5) * dy;
        for i in 0..n {
            s += f(x0 + (i as f64 + 0.5) * dx, y);
        }
    }
    s * dx * dy
}

/// The closed-form volume of every event equals the numerical integral of the difference of the
/// two analytic surfaces over its footprint grown by 0.5 m (so the footprint holds the whole
/// change), within 0.5 %: ∫∫(z2 − z1) dx dy on the ground, −∫∫(d2 − d1) dx dz into the face.
#[test]
fn truth_volumes_match_numerical_integration() {
    let mut scenes: Vec<(SceneKind, SynthOptions)> = SMALL.iter().map(|&k| (k, opts())).collect();
    scenes.push((
        SceneKind::Large,
        SynthOptions {
            points: Some(2_000_000),
            ..opts()
        },
    ));
    let mut checked = 0;
    for (kind, o) in scenes {
        let m = scene_model(kind, &o).unwrap();
        for ev in m.events() {
            let g = 0.5;
            let num = match ev.footprint {
                Footprint::Ground { min, max } => integrate(
                    min[0] - g,
                    max[0] + g,
                    min[1] - g,
                    max[1] + g,
                    1500,
                    |x, y| m.height(1, x, y).unwrap() - m.height(0, x, y).unwrap(),
                ),
                Footprint::Face { min, max } => -integrate(
                    min[0] - g,
                    max[0] + g,
                    min[1] - g,
                    max[1] + g,
                    1500,
                    |x, z| m.face_depth(1, x, z).unwrap() - m.face_depth(0, x, z).unwrap(),
                ),
            };
            let rel = (num - ev.volume_m3).abs() / ev.volume_m3.abs();
            assert!(
                rel < 0.005,
                "{kind} {}: closed form {} vs integral {num}",
                ev.description,
                ev.volume_m3
            );
            assert!(ev.volume_m3.abs() > 1.0, "{kind}: realistic volumes");
            checked += 1;
        }
    }
    // hill 1, cube 1, spheres 5, cubes 4, cliff 3, large (2M points: 150 m² … 3 × 3 grid) 9.
    assert_eq!(checked, 1 + 1 + 5 + 4 + 3 + 9);
}

/// Outside the events nothing changes: the whole-scene integral of z2 − z1 equals the sum of the
/// event volumes (heightfield scenes), and the stable scene differs by exactly its 5 mm shift.
#[test]
fn no_change_outside_events() {
    for (kind, size) in [
        (SceneKind::Hill, 40.0),
        (SceneKind::Cube, 30.0),
        (SceneKind::Spheres, 50.0),
        (SceneKind::Cubes, 40.0),
    ] {
        let m = scene_model(kind, &opts()).unwrap();
        let total: f64 = m.events().iter().map(|e| e.volume_m3).sum();
        let num = integrate(0.0, size, 0.0, size, 3000, |x, y| {
            m.height(1, x, y).unwrap() - m.height(0, x, y).unwrap()
        });
        assert!(
            (num - total).abs() < 0.005 * total.abs().max(1.0),
            "{kind}: {num} vs {total}"
        );
    }
    let m = scene_model(SceneKind::Stable, &opts()).unwrap();
    assert!(m.events().is_empty());
    for (x, y) in [(1.0, 2.0), (17.3, 33.1), (39.0, 0.5)] {
        let d = m.height(1, x, y).unwrap() - m.height(0, x, y).unwrap();
        assert!((d - 0.005).abs() < 1e-9);
    }
}

/// Volumes re-measured from the written points (mean height per 0.5 m cell in each epoch, summed
/// difference × cell area over each event's footprint grown by 1 m) agree with the truth within
/// four standard errors plus 1 %. The standard error comes from the data: each cell mean's
/// variance is the sample variance of its heights over its count (noise and, mostly, random
/// positions on sloping cells). The 1 % covers the bias of sampling by area rather than by
/// footprint (steep parts of a cell weigh more in its mean) on the steep rims of small caps.
#[test]
fn volumes_from_written_points() {
    for kind in [SceneKind::Hill, SceneKind::Spheres] {
        let dir = tempfile::tempdir().unwrap();
        let o = SynthOptions {
            laz: false,
            ..opts()
        };
        let truth = synth(kind, &o, dir.path()).unwrap();
        let m = scene_model(kind, &o).unwrap();
        let (_, p1) = read_points(&dir.path().join(&truth.epochs[0]));
        let (_, p2) = read_points(&dir.path().join(&truth.epochs[1]));
        let cell = 0.5;
        let size = if kind == SceneKind::Hill { 40.0 } else { 50.0 };
        let n = (size / cell) as usize;
        let grid = |pts: &[[f64; 3]]| {
            // (Σz, Σz², count) per cell.
            let mut sum = vec![(0.0, 0.0, 0u32); n * n];
            for p in pts {
                let (i, j) = (
                    ((p[0] - ORIGIN[0]) / cell) as usize,
                    ((p[1] - ORIGIN[1]) / cell) as usize,
                );
                if i < n && j < n {
                    let c = &mut sum[j * n + i];
                    c.0 += p[2];
                    c.1 += p[2] * p[2];
                    c.2 += 1;
                }
            }
            sum
        };
        let (g1, g2) = (grid(&p1), grid(&p2));
        for (ev, te) in m.events().iter().zip(&truth.events) {
            let Footprint::Ground { min, max } = ev.footprint else {
                unreachable!()
            };
            let (i0, i1) = (
                ((min[0] - 1.0) / cell) as usize,
                ((max[0] + 1.0) / cell) as usize,
            );
            let (j0, j1) = (
                ((min[1] - 1.0) / cell) as usize,
                ((max[1] + 1.0) / cell) as usize,
            );
            // Mean and variance of the mean of one cell.
            let stats = |c: (f64, f64, u32)| {
                let k = c.2 as f64;
                let mean = c.0 / k;
                let var = (c.1 / k - mean * mean).max(0.0) * k / (k - 1.0);
                (mean, var / k)
            };
            let (mut v, mut var) = (0.0, 0.0);
            let a2 = cell * cell;
            for j in j0..j1 {
                for i in i0..i1 {
                    let (a, b) = (g1[j * n + i], g2[j * n + i]);
                    assert!(a.2 > 5 && b.2 > 5, "cell ({i}, {j}) nearly empty");
                    let ((m1, v1), (m2, v2)) = (stats(a), stats(b));
                    v += (m2 - m1) * a2;
                    var += (v1 + v2) * a2 * a2;
                }
            }
            let bound = 4.0 * var.sqrt() + 0.01 * te.volume_m3.abs();
            assert!(
                (v - te.volume_m3).abs() < bound,
                "{kind} {}: points {v} vs truth {} (bound {bound})",
                te.description,
                te.volume_m3
            );
            // The check has teeth: the bound is a small part of the volume.
            assert!(bound < 0.15 * te.volume_m3.abs(), "{kind}: bound {bound}");
        }
    }
}

/// Noise: vertical residuals on the (nearly flat) hill plane have the requested 5 mm standard
/// deviation (plus 0.29 mm of 1 mm quantisation); on the cliff the face points scatter 5 mm
/// horizontally about the face plane, and the face holds its share of points by area
/// (1800 m² of 3600 m²).
#[test]
fn noise_and_density_on_surfaces() {
    let dir = tempfile::tempdir().unwrap();
    let o = SynthOptions {
        laz: false,
        ..opts()
    };
    let truth = synth(SceneKind::Hill, &o, dir.path()).unwrap();
    let m = scene_model(SceneKind::Hill, &o).unwrap();
    let (_, pts) = read_points(&dir.path().join(&truth.epochs[0]));
    let ss: f64 = pts
        .iter()
        .map(|p| {
            let r = p[2] - m.height(0, p[0] - ORIGIN[0], p[1] - ORIGIN[1]).unwrap();
            r * r
        })
        .sum();
    let rms = (ss / pts.len() as f64).sqrt();
    // Expected sqrt(5² + 1/12) mm = 5.008 mm; the standard error with 160k points is 0.009 mm.
    assert!((rms - 0.005008).abs() < 0.0001, "hill rms {rms}");

    let truth = synth(SceneKind::Cliff, &o, dir.path()).unwrap();
    let (_, pts) = read_points(&dir.path().join(&truth.epochs[0]));
    let face: Vec<&[f64; 3]> = pts
        .iter()
        .filter(|p| p[2] > 100.1 && p[2] < 129.9 && (p[1] - ORIGIN[1]).abs() < 0.1)
        .collect();
    let rms =
        (face.iter().map(|p| (p[1] - ORIGIN[1]).powi(2)).sum::<f64>() / face.len() as f64).sqrt();
    assert!((rms - 0.005008).abs() < 0.0002, "face rms {rms}");
    // Share of the face (z in the open band excludes a 0.1 m strip at the foot and top:
    // 60 × 29.8 m² of 3600 m²); binomial standard deviation 0.001, bound at 4σ.
    let share = face.len() as f64 / pts.len() as f64;
    let expect = 60.0 * 29.8 / 3600.0;
    assert!(
        (share - expect).abs() < 0.004,
        "face share {share} vs {expect}"
    );

    // The cube's walls (4 × 4 m × 1.5 m = 24 m² of 924 m²) get their share of epoch-2 points.
    let truth = synth(SceneKind::Cube, &o, dir.path()).unwrap();
    let (_, pts) = read_points(&dir.path().join(&truth.epochs[1]));
    let walls = pts
        .iter()
        .filter(|p| p[2] > 100.05 && p[2] < 101.45)
        .count() as f64;
    let expect = pts.len() as f64 * (24.0 * 1.4 / 1.5) / 924.0;
    // Binomial standard deviation sqrt(2424) ≈ 49 points; bound at 4σ.
    assert!((walls - expect).abs() < 200.0, "walls {walls} vs {expect}");
}

/// Same seed → identical bytes (also when run on one thread); another seed → other points.
#[test]
fn same_seed_same_bytes() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    synth(SceneKind::Cliff, &opts(), a.path()).unwrap();
    // The second run on one thread: the bytes must not depend on the thread count.
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| synth(SceneKind::Cliff, &opts(), b.path()))
        .unwrap();
    let other = SynthOptions { seed: 2, ..opts() };
    synth(SceneKind::Cliff, &other, c.path()).unwrap();
    for f in ["before.laz", "after.laz", "truth.json"] {
        let x = std::fs::read(a.path().join(f)).unwrap();
        assert_eq!(x, std::fs::read(b.path().join(f)).unwrap(), "{f}");
        if f != "truth.json" {
            assert_ne!(x, std::fs::read(c.path().join(f)).unwrap(), "{f}");
        }
    }
    // The two epochs of one run come from different random streams.
    let (_, p1) = read_points(&a.path().join("before.laz"));
    let (_, p2) = read_points(&a.path().join("after.laz"));
    assert_ne!(p1[..100], p2[..100]);
}

/// Rotating the scene keeps volumes, rotates the event centres about the rotation centre, and
/// rotates every point (same random streams), to within the 1 mm quantisation.
#[test]
fn rotation_keeps_volumes_and_rotates_centres() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let o = SynthOptions {
        laz: false,
        ..opts()
    };
    let r = SynthOptions {
        rotate_deg: 30.0,
        ..o.clone()
    };
    let t0 = synth(SceneKind::Cubes, &o, a.path()).unwrap();
    let t1 = synth(SceneKind::Cubes, &r, b.path()).unwrap();
    assert_eq!(t0.rotation_centre, t1.rotation_centre);
    let [cx, cy] = t0.rotation_centre;
    let (s, c) = 30f64.to_radians().sin_cos();
    let rot = |p: [f64; 3]| {
        let (dx, dy) = (p[0] - cx, p[1] - cy);
        [cx + c * dx - s * dy, cy + s * dx + c * dy, p[2]]
    };
    assert_eq!(t0.events.len(), t1.events.len());
    for (e0, e1) in t0.events.iter().zip(&t1.events) {
        assert_eq!(e0.volume_m3, e1.volume_m3);
        let q = rot(e0.centre);
        for (a, b) in q.iter().zip(&e1.centre) {
            assert!((a - b).abs() < 1e-6);
        }
    }
    let (_, p0) = read_points(&a.path().join("after.las"));
    let (_, p1) = read_points(&b.path().join("after.las"));
    assert_eq!(p0.len(), p1.len());
    let worst = p0
        .iter()
        .zip(&p1)
        .map(|(p, q)| {
            let r = rot(*p);
            (r[0] - q[0]).hypot(r[1] - q[1]).max((r[2] - q[2]).abs())
        })
        .fold(0.0, f64::max);
    assert!(worst < 0.0015, "worst {worst}");
    assert!(worst > 0.0, "the rotated scene must differ");
}

#[test]
fn density2_halves_epoch_two() {
    let dir = tempfile::tempdir().unwrap();
    let o = SynthOptions {
        points: Some(100_001),
        density2: 0.5,
        laz: false,
        ..opts()
    };
    let t = synth(SceneKind::Cube, &o, dir.path()).unwrap();
    assert_eq!(t.points, [100_001, 50_001]);
    let (h1, _) = read_points(&dir.path().join("before.las"));
    let (h2, _) = read_points(&dir.path().join("after.las"));
    assert_eq!(h1.number_of_points(), 100_001);
    assert_eq!(h2.number_of_points(), 50_001);
}

/// The large scene streams: its points come as chunks of at most CHUNK_POINTS (more than one at
/// 2M points), and the written files hold exactly the requested count.
#[test]
fn large_scene_streams_exact_count() {
    let o = SynthOptions {
        points: Some(2_000_000),
        ..opts()
    };
    let mut chunks = 0;
    let mut total = 0u64;
    for c in epoch_chunks(SceneKind::Large, &o, 1).unwrap() {
        assert!(!c.is_empty() && c.len() <= CHUNK_POINTS);
        total += c.len() as u64;
        chunks += 1;
    }
    assert_eq!(total, 2_000_000);
    assert!(chunks >= 2, "{chunks} chunks");

    let dir = tempfile::tempdir().unwrap();
    let t = synth(SceneKind::Large, &o, dir.path()).unwrap();
    assert_eq!(t.points, [2_000_000, 2_000_000]);
    assert_eq!(t.events.len(), 9);
    // Features straddle round-number coordinates (tile borders at multiples of 100 m).
    assert!(t
        .events
        .iter()
        .any(|e| ((e.centre[0] - ORIGIN[0]) % 100.0).abs() < 1e-9
            && ((e.centre[1] - ORIGIN[1]) % 100.0).abs() < 1e-9));
    assert!(
        t.events.iter().any(|e| e.volume_m3 > 0.0) && t.events.iter().any(|e| e.volume_m3 < 0.0)
    );
    for e in 0..2 {
        let r = las::Reader::from_path(dir.path().join(&t.epochs[e])).unwrap();
        assert_eq!(r.header().number_of_points(), 2_000_000);
        let b = r.header().bounds();
        let side = (2e6f64).sqrt() * 0.15;
        assert!(b.max.x - b.min.x > side - 0.1 && b.max.x - b.min.x < side + 0.1);
    }
}

/// The cliff's epoch-2 points behind the face plane (y > 3 cm = 6σ of the noise, below the
/// plateau) all lie in the two scars: on the box scar's walls or on the half-ellipsoid; epoch 1
/// has none there. Every scar surface is sampled.
#[test]
fn cliff_scars_are_hollowed_into_the_face() {
    let dir = tempfile::tempdir().unwrap();
    let t = synth(SceneKind::Cliff, &opts(), dir.path()).unwrap();
    let local = |p: &[f64; 3]| [p[0] - ORIGIN[0], p[1] - ORIGIN[1], p[2]];
    let behind = |pts: &[[f64; 3]]| -> Vec<[f64; 3]> {
        pts.iter()
            .map(local)
            .filter(|p| p[1] > 0.03 && p[2] < 129.9)
            .collect()
    };
    let (_, p1) = read_points(&dir.path().join(&t.epochs[0]));
    assert!(behind(&p1).is_empty());
    let (_, p2) = read_points(&dir.path().join(&t.epochs[1]));
    let (mut in_box, mut on_ellipsoid, mut back_wall) = (0, 0, 0);
    for p in behind(&p2) {
        let e = 0.03;
        if p[0] > 10.0 - e && p[0] < 14.0 + e && p[2] > 115.0 - e && p[2] < 118.0 + e {
            assert!(p[1] < 1.0 + e, "{p:?} deeper than the box scar");
            in_box += 1;
            back_wall += usize::from(p[1] > 1.0 - e);
            continue;
        }
        let q =
            ((p[0] - 40.0) / 3.0).powi(2) + (p[1] / 1.5).powi(2) + ((p[2] - 120.0) / 2.5).powi(2);
        assert!((q.sqrt() - 1.0).abs() < 0.02, "{p:?} off both scars");
        on_ellipsoid += 1;
    }
    // Expected counts from areas at ~69 points/m² (250k points over ~3630 m²): the box scar's
    // five walls are 26 m² (~1790 points; back wall 12 m², ~830), the half-ellipsoid ~34 m²
    // (~2340), minus what lies within 3 cm of the face plane. Binomial σ ≈ 30–50 points; the
    // bounds are about ±4σ around the expectations.
    assert!((1600..1950).contains(&in_box), "box scar {in_box}");
    assert!((700..950).contains(&back_wall), "back wall {back_wall}");
    assert!(
        (2100..2500).contains(&on_ellipsoid),
        "ellipsoid {on_ellipsoid}"
    );
}

/// `--shift`: epoch 1 is untouched and every epoch-2 point moves by exactly the shift (the same
/// random streams), for every small scene, with and without rotation (the shift is in global axes,
/// after the rotation); the truth keeps its volumes and centres and records the shift.
#[test]
fn shift_moves_epoch_two_exactly() {
    let shift = [0.3, -0.2, 0.05];
    for (i, kind) in SMALL.into_iter().enumerate() {
        let o = SynthOptions {
            rotate_deg: if i % 2 == 0 { 0.0 } else { 30.0 },
            ..opts()
        };
        let s = SynthOptions {
            shift_m: shift,
            ..o.clone()
        };
        for epoch in 0..2 {
            let a: Vec<[f64; 3]> = epoch_chunks(kind, &o, epoch).unwrap().flatten().collect();
            let b: Vec<[f64; 3]> = epoch_chunks(kind, &s, epoch).unwrap().flatten().collect();
            assert_eq!(a.len(), b.len());
            let d = if epoch == 1 { shift } else { [0.0; 3] };
            let worst = a
                .iter()
                .zip(&b)
                .flat_map(|(p, q)| (0..3).map(move |k| (q[k] - p[k] - d[k]).abs()))
                .fold(0.0, f64::max);
            assert!(worst < 1e-6, "{kind} epoch {epoch}: off by {worst}");
        }
    }
    // Through the files: before.las byte-identical, after.las moved by the shift to within the
    // 1 mm quantisation, truth.json records it.
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let o = SynthOptions {
        laz: false,
        rotate_deg: 30.0,
        ..opts()
    };
    let s = SynthOptions {
        shift_m: shift,
        ..o.clone()
    };
    let t0 = synth(SceneKind::Cliff, &o, a.path()).unwrap();
    let t1 = synth(SceneKind::Cliff, &s, b.path()).unwrap();
    assert_eq!(t0.shift_m, [0.0; 3]);
    assert_eq!(t1.shift_m, shift);
    let back: Truth =
        serde_json::from_slice(&std::fs::read(b.path().join("truth.json")).unwrap()).unwrap();
    same_truth(&back, &t1);
    assert_eq!(t0.events, t1.events);
    assert_eq!(
        std::fs::read(a.path().join("before.las")).unwrap(),
        std::fs::read(b.path().join("before.las")).unwrap()
    );
    let (_, p0) = read_points(&a.path().join("after.las"));
    let (_, p1) = read_points(&b.path().join("after.las"));
    assert_eq!(p0.len(), p1.len());
    for (p, q) in p0.iter().zip(&p1) {
        for k in 0..3 {
            assert!((q[k] - p[k] - shift[k]).abs() < 0.0011, "{p:?} → {q:?}");
        }
    }
    // A truth.json without the field (older files) reads as no shift.
    let old = String::from_utf8(std::fs::read(a.path().join("truth.json")).unwrap()).unwrap();
    let start = old.find("\"shift_m\"").unwrap();
    let end = start + old[start..].find(']').unwrap() + 2;
    let t: Truth = serde_json::from_str(&(old[..start].to_string() + &old[end..])).unwrap();
    assert_eq!(t.shift_m, [0.0; 3]);
}

#[test]
fn shift_parses_and_is_checked() {
    use talus::synth::parse_shift;
    assert_eq!(parse_shift("0.1,-0.2, 3").unwrap(), [0.1, -0.2, 3.0]);
    for bad in ["1,2", "1,2,3,4", "a,b,c", ""] {
        assert_eq!(parse_shift(bad).unwrap_err().exit_code(), 2, "{bad}");
    }
    let dir = tempfile::tempdir().unwrap();
    for shift in [[f64::NAN, 0.0, 0.0], [0.0, 0.0, 1e6]] {
        let o = SynthOptions {
            shift_m: shift,
            ..opts()
        };
        let e = synth(SceneKind::Hill, &o, dir.path()).unwrap_err();
        assert_eq!(e.exit_code(), 2, "{e}");
    }
}
