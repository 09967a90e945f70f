//! Tests of `talus synth`: files read back by las-rs (an independent reader), closed-form volumes
//! checked against numerical integration of the two analytic surfaces, volumes re-measured from the
//! written points, noise and density statistics, determinism, rotation, shift, density2, holes,
//! the seeded events scene, streaming, and `synth campaign` (per-pair and baseline truths against
//! integration, accumulation through the written surveys, dates and names, the recurring change,
//! the layout for every number of surveys, determinism, the command line).

use std::path::Path;
use std::process::Command;

use talus::synth::campaign::{self, CampaignModel, CampaignOptions, CampaignTruth, PairModel};
use talus::synth::{
    epoch_chunks, scene_model, synth, Footprint, ModelEvent, SceneKind, SceneModel, SynthOptions,
    Truth, CHUNK_POINTS, CRS_EPSG, ORIGIN, UTM33N_WKT,
};

const SMALL: [SceneKind; 9] = [
    SceneKind::Hill,
    SceneKind::Cube,
    SceneKind::Spheres,
    SceneKind::Cubes,
    SceneKind::Cliff,
    SceneKind::Deposit,
    SceneKind::Hole,
    SceneKind::Events,
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
        assert_eq!(e.covered_volume_m3.is_some(), f.covered_volume_m3.is_some());
        if let (Some(x), Some(y)) = (e.covered_volume_m3, f.covered_volume_m3) {
            assert!(close(x, y));
        }
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
        // The hole scene's epoch 1 misses 160 m² of its 1600 m²: 10 % fewer points.
        let n = kind.default_points();
        let n1 = if kind == SceneKind::Hole {
            n * 9 / 10
        } else {
            n
        };
        assert_eq!(truth.points, [n1, n]);
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

/// The numerical integral of event `ev`'s change, the difference of the two analytic surfaces,
/// over its footprint grown by 0.5 m (so that it holds the whole change) on an n × n grid, where
/// `keep` holds: ∫∫(z2 − z1) dx dy on the ground, −∫∫(d2 − d1) dx dz into the face.
fn integrated_volume(
    m: &SceneModel,
    ev: &ModelEvent,
    n: usize,
    keep: impl Fn(f64, f64) -> bool,
) -> f64 {
    let g = 0.5;
    let (min, max, sign) = match ev.footprint {
        Footprint::Ground { min, max } => (min, max, 1.0),
        Footprint::Face { min, max } => (min, max, -1.0),
        // A scanned face's events are integrated in its own frame (`synth::face`'s tests).
        Footprint::Frame { .. } => panic!("a scanned face's event"),
    };
    let change = |x: f64, y: f64| match ev.footprint {
        Footprint::Ground { .. } => m.height(1, x, y).unwrap() - m.height(0, x, y).unwrap(),
        Footprint::Face { .. } => m.face_depth(1, x, y).unwrap() - m.face_depth(0, x, y).unwrap(),
        Footprint::Frame { .. } => unreachable!(),
    };
    sign * integrate(min[0] - g, max[0] + g, min[1] - g, max[1] + g, n, |x, y| {
        if keep(x, y) {
            change(x, y)
        } else {
            0.0
        }
    })
}

/// Every event's closed-form volume is within 0.5 % of the numerical integral of its change.
fn check_volumes(kind: impl std::fmt::Display, m: &SceneModel, n: usize) -> usize {
    for ev in m.events() {
        let num = integrated_volume(m, ev, n, |_, _| true);
        let rel = (num - ev.volume_m3).abs() / ev.volume_m3.abs();
        assert!(
            rel < 0.005,
            "{kind} {}: closed form {} vs integral {num}",
            ev.description,
            ev.volume_m3
        );
    }
    m.events().len()
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
        checked += check_volumes(kind, &m, 1500);
        // The events scene's volumes are checked against their range in its own test.
        if kind != SceneKind::Events {
            assert!(
                m.events().iter().all(|e| e.volume_m3.abs() > 1.0),
                "{kind}: realistic volumes"
            );
        }
    }
    // hill 1, cube 1, spheres 5, cubes 4, cliff 3, deposit 1, hole 1, events 12, large (2M
    // points: 150 m² … 3 × 3 grid) 9.
    assert_eq!(checked, 1 + 1 + 5 + 4 + 3 + 1 + 1 + 12 + 9);
}

/// Outside the events nothing changes: the whole-ground integral of z2 − z1 equals the sum of
/// the event volumes (heightfield scenes; the deposit scene's beach), within 0.5 % of the summed
/// absolute volumes, and the stable scene differs by exactly its 5 mm shift.
#[test]
fn no_change_outside_events() {
    for kind in [
        SceneKind::Hill,
        SceneKind::Cube,
        SceneKind::Spheres,
        SceneKind::Cubes,
        SceneKind::Hole,
        SceneKind::Events,
        SceneKind::Deposit,
    ] {
        let m = scene_model(kind, &opts()).unwrap();
        // The heightfield scenes span [0, 2 × centre]; the deposit scene's beach [0, 60] × [−20, 0].
        let [cx, cy] = m.centre();
        let (min, max) = if kind == SceneKind::Deposit {
            ([0.0, -20.0], [60.0, 0.0])
        } else {
            ([0.0, 0.0], [2.0 * cx, 2.0 * cy])
        };
        let total: f64 = m.events().iter().map(|e| e.volume_m3).sum();
        let scale: f64 = m.events().iter().map(|e| e.volume_m3.abs()).sum();
        let num = integrate(min[0], max[0], min[1], max[1], 3000, |x, y| {
            m.height(1, x, y).unwrap() - m.height(0, x, y).unwrap()
        });
        assert!(
            (num - total).abs() < 0.005 * scale.max(1.0),
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
    for kind in [
        SceneKind::Cliff,
        SceneKind::Deposit,
        SceneKind::Hole,
        SceneKind::Events,
    ] {
        let (a, b, c) = (
            tempfile::tempdir().unwrap(),
            tempfile::tempdir().unwrap(),
            tempfile::tempdir().unwrap(),
        );
        // The hole scene shifted: the shift is part of the determinism.
        let o = SynthOptions {
            shift_m: if kind == SceneKind::Hole {
                [0.1, 0.0, -0.02]
            } else {
                [0.0; 3]
            },
            ..opts()
        };
        synth(kind, &o, a.path()).unwrap();
        // The second run on one thread: the bytes must not depend on the thread count.
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| synth(kind, &o, b.path()))
            .unwrap();
        let other = SynthOptions { seed: 2, ..o };
        synth(kind, &other, c.path()).unwrap();
        for f in ["before.laz", "after.laz", "truth.json"] {
            let x = std::fs::read(a.path().join(f)).unwrap();
            assert_eq!(x, std::fs::read(b.path().join(f)).unwrap(), "{kind} {f}");
            // The seed changes the points, and for the events scene the events too.
            if f != "truth.json" || kind == SceneKind::Events {
                assert_ne!(x, std::fs::read(c.path().join(f)).unwrap(), "{kind} {f}");
            }
        }
        // The two epochs of one run come from different random streams.
        let (_, p1) = read_points(&a.path().join("before.laz"));
        let (_, p2) = read_points(&a.path().join("after.laz"));
        assert_ne!(p1[..100], p2[..100]);
    }
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

/// The deposit scene: the cliff's frame, its face and plateau unchanged, one gain on the beach
/// whose edge stays 1.5 m in front of the face foot (the beach is unchanged over the gap).
#[test]
fn deposit_lies_on_the_beach_clear_of_the_face() {
    let m = scene_model(SceneKind::Deposit, &opts()).unwrap();
    let [ev] = m.events() else {
        panic!("one event")
    };
    assert!(ev.volume_m3 > 0.0);
    let Footprint::Ground { min, max } = ev.footprint else {
        panic!("a ground event")
    };
    assert!(
        (max[1] + 1.5).abs() < 1e-9,
        "gap to the face foot {}",
        -max[1]
    );
    assert!(min[1] > -20.0 + 5.0 && min[0] > 5.0 && max[0] < 55.0);
    for i in 0..=600 {
        let x = i as f64 * 0.1;
        for y in [-1.5, -1.0, -0.5, -1e-9] {
            assert_eq!(m.height(0, x, y), m.height(1, x, y), "beach at ({x}, {y})");
        }
        for z in [100.0, 103.0, 115.0, 130.0] {
            assert_eq!(m.face_depth(1, x, z), Some(0.0));
        }
    }
    // The deposit rises above the beach: 1.2 m at its centre.
    let c = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
    let dz = m.height(1, c[0], c[1]).unwrap() - m.height(0, c[0], c[1]).unwrap();
    assert!((dz - 1.2).abs() < 1e-9, "height {dz}");
}

/// The hole scene: epoch 1 has no points over the hole (x ∈ [20, 30), y ∈ [12, 28)), epoch 2 has
/// its share there; epoch 1's density elsewhere is epoch 2's (its points are sampled only outside
/// the hole, 90 % of them); the hole covers half of the event's footprint; `covered_volume_m3`
/// equals the integral of the change outside the hole and is in truth.json for that event only.
#[test]
fn hole_is_empty_in_epoch_one_and_halves_the_event() {
    let dir = tempfile::tempdir().unwrap();
    let o = SynthOptions {
        laz: false,
        ..opts()
    };
    let t = synth(SceneKind::Hole, &o, dir.path()).unwrap();
    let m = scene_model(SceneKind::Hole, &o).unwrap();
    let [ev] = m.events() else {
        panic!("one event")
    };
    let covered = ev.covered_volume_m3.expect("a covered volume");
    assert_eq!(t.events[0].covered_volume_m3, Some(covered));
    let num = integrated_volume(&m, ev, 2000, |x, y| !m.unobserved(0, x, y));
    assert!(
        (num - covered).abs() < 0.005 * covered,
        "covered {covered} vs integral {num}"
    );
    // Half of the footprint's disk (radius 4 m about (20, 20)) lies in the hole.
    let disk = |x: f64, y: f64| (x - 20.0).hypot(y - 20.0) < 4.0;
    let inside = integrate(16.0, 24.0, 16.0, 24.0, 2000, |x, y| {
        f64::from(u8::from(disk(x, y) && m.unobserved(0, x, y)))
    });
    let all = integrate(16.0, 24.0, 16.0, 24.0, 2000, |x, y| {
        f64::from(u8::from(disk(x, y)))
    });
    assert!((inside / all - 0.5).abs() < 0.002, "{inside} of {all}");
    assert!(!m.unobserved(1, 25.0, 20.0) && m.unobserved(0, 25.0, 20.0));
    let text = std::fs::read_to_string(dir.path().join("truth.json")).unwrap();
    assert_eq!(text.matches("covered_volume_m3").count(), 1);

    let (_, p1) = read_points(&dir.path().join(&t.epochs[0]));
    let (_, p2) = read_points(&dir.path().join(&t.epochs[1]));
    let local = |p: &[f64; 3]| [p[0] - ORIGIN[0], p[1] - ORIGIN[1]];
    // 3 mm inside the hole's edges: the noise moves points by at most 0.02 × 4 × 5 mm
    // horizontally, the 1 mm quantisation by 0.5 mm.
    let e = 0.003;
    let in_hole = |p: &[f64; 3]| {
        let [x, y] = local(p);
        x > 20.0 + e && x < 30.0 - e && y > 12.0 + e && y < 28.0 - e
    };
    assert_eq!(p1.iter().filter(|p| in_hole(p)).count(), 0);
    // Epoch 2's share of points in a region is its share of the surface area (the area element
    // sqrt(1 + |∇z|²) by central differences); binomial bounds at 4σ.
    let area = |x0: f64, x1: f64, y0: f64, y1: f64| {
        let z = |x: f64, y: f64| m.height(1, x, y).unwrap();
        let h = 1e-4;
        integrate(x0, x1, y0, y1, 800, |x, y| {
            let gx = (z(x + h, y) - z(x - h, y)) / (2.0 * h);
            let gy = (z(x, y + h) - z(x, y - h)) / (2.0 * h);
            (1.0 + gx * gx + gy * gy).sqrt()
        })
    };
    let total = area(0.0, 40.0, 0.0, 40.0);
    let expect = |n: usize, share: f64| {
        let mean = n as f64 * share;
        (mean, 4.0 * (mean * (1.0 - share)).sqrt())
    };
    let count =
        |pts: &[[f64; 3]], f: &dyn Fn(&[f64; 3]) -> bool| pts.iter().filter(|p| f(p)).count();
    let (mean, bound) = expect(
        p2.len(),
        area(20.0 + e, 30.0 - e, 12.0 + e, 28.0 - e) / total,
    );
    let n2 = count(&p2, &in_hole) as f64;
    assert!(
        (n2 - mean).abs() < bound,
        "epoch 2 in the hole: {n2} vs {mean}"
    );
    // The same density elsewhere: in x < 15 (600 m², clear of the bump) epoch 1 expects
    // 144000 × 600 / 1440 = 60 000 points (its area element is constant), epoch 2 its share of
    // the surface. Sampling all 160 000 points of epoch 1 outside the hole would give 66 667.
    let west = |p: &[f64; 3]| local(p)[0] < 15.0;
    let (mean, bound) = expect(p1.len(), 600.0 / 1440.0);
    let w1 = count(&p1, &west) as f64;
    assert!((w1 - mean).abs() < bound, "epoch 1 west {w1} vs {mean}");
    let (mean, bound) = expect(p2.len(), area(0.0, 15.0, 0.0, 40.0) / total);
    let w2 = count(&p2, &west) as f64;
    assert!((w2 - mean).abs() < bound, "epoch 2 west {w2} vs {mean}");
    assert!((w1 / w2 - 1.0).abs() < 0.02, "densities {w1} vs {w2}");
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

/// The events scene for seeds 1..=8: twelve events each, of all six kinds (two each) with
/// volumes in [0.2, 6] m³ spread over the range (one per twelfth of it on a log scale),
/// footprints at least 5 m apart and 5 m from the border, ground slopes below 10 %; the
/// closed-form volumes match numerical integration (seeds 2 and 3 here, seed 1 with the other
/// scenes); different seeds give different events and grounds, the same seed the same.
#[test]
fn events_scene_is_drawn_from_the_seed() {
    let kinds = [
        "box raised",
        "box dug",
        "spherical cap",
        "spherical dent",
        "cos² bump",
        "cos² dent",
    ];
    let mut all: Vec<(u64, f64, [f64; 3])> = Vec::new();
    for seed in 1..=8 {
        let o = SynthOptions { seed, ..opts() };
        let m = scene_model(SceneKind::Events, &o).unwrap();
        let ev = m.events();
        assert_eq!(ev.len(), 12, "seed {seed}");
        for k in kinds {
            let n = ev.iter().filter(|e| e.description.starts_with(k)).count();
            assert_eq!(n, 2, "seed {seed}: {k}");
        }
        for e in ev {
            let dug = ["dug", "dent"].iter().any(|w| e.description.contains(w));
            assert_eq!(e.volume_m3 < 0.0, dug, "{}", e.description);
        }
        let mut strata: Vec<usize> = ev
            .iter()
            .map(|e| (12.0 * (e.volume_m3.abs() / 0.2).ln() / 30f64.ln()) as usize)
            .collect();
        strata.sort_unstable();
        assert_eq!(strata, (0..12).collect::<Vec<_>>(), "seed {seed}: volumes");
        let [cx, cy] = m.centre();
        let size = [2.0 * cx, 2.0 * cy];
        let boxes: Vec<([f64; 2], [f64; 2])> = ev
            .iter()
            .map(|e| match e.footprint {
                Footprint::Ground { min, max } => (min, max),
                Footprint::Face { .. } | Footprint::Frame { .. } => panic!("a ground event"),
            })
            .collect();
        for (i, (a0, a1)) in boxes.iter().enumerate() {
            for k in 0..2 {
                assert!(
                    a0[k] >= 5.0 - 1e-9 && a1[k] <= size[k] - 5.0 + 1e-9,
                    "seed {seed}"
                );
            }
            for (b0, b1) in &boxes[i + 1..] {
                // Axis-aligned boxes containing the footprints: their gap is the larger of the
                // gaps along x and y.
                let gap = (0..2)
                    .map(|k| (b0[k] - a1[k]).max(a0[k] - b1[k]))
                    .fold(f64::NEG_INFINITY, f64::max);
                assert!(gap >= 5.0 - 1e-9, "seed {seed}: gap {gap}");
            }
        }
        // Slopes of the ground by central differences on a 0.5 m grid.
        let h = 0.01;
        let z = |x: f64, y: f64| m.height(0, x, y).unwrap();
        let mut steepest: f64 = 0.0;
        for j in 1..(size[1] / 0.5) as usize {
            for i in 1..(size[0] / 0.5) as usize {
                let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
                let gx = (z(x + h, y) - z(x - h, y)) / (2.0 * h);
                let gy = (z(x, y + h) - z(x, y - h)) / (2.0 * h);
                steepest = steepest.max(gx.hypot(gy));
            }
        }
        assert!(steepest < 0.1, "seed {seed}: slope {steepest}");
        if (2..=3).contains(&seed) {
            check_volumes(SceneKind::Events, &m, 1000);
        }
        assert_eq!(
            m.events(),
            scene_model(SceneKind::Events, &o).unwrap().events()
        );
        all.extend(ev.iter().map(|e| (seed, e.volume_m3, e.centre)));
    }
    // No event repeats across seeds (nor does the ground: the event centres' heights differ).
    for (i, a) in all.iter().enumerate() {
        for b in &all[i + 1..] {
            if a.0 != b.0 {
                assert!(a.1 != b.1 && a.2 != b.2, "seeds {} and {}", a.0, b.0);
            }
        }
    }
    assert_eq!(all.len(), 96);
}

/// The events scene's boxes stand on the undulating ground: the epoch-2 points within 2 cm of a
/// box wall lie between the ground and the box's top or floor along the wall (a wall of constant
/// height would leave the ground or cut into it), and each wall holds its share of points by area.
#[test]
fn events_box_walls_follow_the_ground() {
    let o = opts();
    let m = scene_model(SceneKind::Events, &o).unwrap();
    let pts: Vec<[f64; 3]> = epoch_chunks(SceneKind::Events, &o, 1)
        .unwrap()
        .flatten()
        .map(|p| [p[0] - ORIGIN[0], p[1] - ORIGIN[1], p[2]])
        .collect();
    let [cx, cy] = m.centre();
    let density = pts.len() as f64 / (4.0 * cx * cy);
    let mut walls = 0;
    for e in m
        .events()
        .iter()
        .filter(|e| e.description.starts_with("box"))
    {
        let Footprint::Ground { min, max } = e.footprint else {
            unreachable!()
        };
        let c = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
        let dz = m.height(1, c[0], c[1]).unwrap() - m.height(0, c[0], c[1]).unwrap();
        // The wall x = min[0], clear of the corners by 5 cm.
        let near: Vec<&[f64; 3]> = pts
            .iter()
            .filter(|p| {
                (p[0] - min[0]).abs() < 0.02 && p[1] > min[1] + 0.05 && p[1] < max[1] - 0.05
            })
            .collect();
        let mut on_wall = 0;
        for p in &near {
            let g = m.height(0, min[0] - 0.03, p[1]).unwrap();
            let (lo, hi) = (g + dz.min(0.0), g + dz.max(0.0));
            assert!(
                p[2] > lo - 0.05 && p[2] < hi + 0.05,
                "{}: {p:?} off the wall [{lo}, {hi}]",
                e.description
            );
            on_wall += usize::from(p[2] > lo + 0.05 && p[2] < hi - 0.05);
        }
        // Expected: density × wall area (length × (|dz| − 0.1 m)) × P(|noise| < 2 cm = 2σ),
        // within 4σ + 10 % (the density is per m² of ground, a little above per m² of surface).
        let expect = density * (max[1] - min[1] - 0.1) * (dz.abs() - 0.1) * 0.9545;
        let got = on_wall as f64;
        assert!(
            (got - expect).abs() < 4.0 * expect.sqrt() + 0.1 * expect,
            "{}: {got} wall points, expected {expect}",
            e.description
        );
        walls += 1;
    }
    assert_eq!(walls, 4);
}

// ---- synth campaign ----

/// The pair (before, after) of campaign `m`.
fn pair(m: &CampaignModel, before: usize, after: usize) -> PairModel {
    m.pair(before, after).unwrap()
}

/// Survey j's surfaces: epoch 1 of the pair (j − 1, j), or epoch 0 of (0, 1) for j = 0.
fn survey(m: &CampaignModel, j: usize) -> (SceneModel, usize) {
    if j == 0 {
        (pair(m, 0, 1).model, 0)
    } else {
        (pair(m, j - 1, j).model, 1)
    }
}

/// Whether (x, y) lies in the rectangle [min − e, max + e].
fn in_rect(min: [f64; 2], max: [f64; 2], e: f64, x: f64, y: f64) -> bool {
    x >= min[0] - e && x <= max[0] + e && y >= min[1] - e && y <= max[1] + e
}

/// Every campaign pair's truth, consecutive (one interval's changes, the recurring scar's growth
/// among them as the difference of two half-ellipsoids) and baseline (0, k) (the accumulated
/// changes), matches the numerical integral of the difference of the pair's two analytic surfaces
/// within 0.5 %, for 5 surveys (the scar grows again in interval 3) and 3 (in interval 2);
/// outside the events' footprints the two surfaces are identical (beach, plateau and face on a
/// 5 cm grid); a baseline event's volume is the sum of its place's interval volumes.
#[test]
fn campaign_truths_match_numerical_integration() {
    for n in [5, 3] {
        let m = CampaignModel::new(n).unwrap();
        let ([x0, x1], beach, [z0, z1]) = m.site();
        let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
        pairs.extend((2..n).map(|k| (0, k)));
        let mut checked = 0;
        for (before, after) in pairs {
            let p = pair(&m, before, after);
            let name = format!("campaign {n}: pair ({before}, {after})");
            checked += check_volumes(&name, &p.model, 1500);
            let (ground, face): (Vec<_>, Vec<_>) = p
                .model
                .events()
                .iter()
                .map(|e| e.footprint)
                .partition(|f| matches!(f, Footprint::Ground { .. }));
            let outside = |fs: &[Footprint], x: f64, y: f64| {
                fs.iter().all(|f| match *f {
                    Footprint::Ground { min, max }
                    | Footprint::Face { min, max }
                    | Footprint::Frame { min, max } => !in_rect(min, max, 1e-9, x, y),
                })
            };
            let h = 0.05;
            for i in 0..=((x1 - x0) / h) as usize {
                let x = x0 + i as f64 * h;
                for j in 0..=((beach + 10.0) / h) as usize {
                    let y = -beach + j as f64 * h;
                    if outside(&ground, x, y) {
                        assert_eq!(p.model.height(0, x, y), p.model.height(1, x, y), "{name}");
                    }
                }
                for j in 0..=((z1 - z0) / h) as usize {
                    let z = z0 + j as f64 * h;
                    if outside(&face, x, z) {
                        let d = p.model.face_depth(1, x, z).unwrap();
                        assert_eq!(p.model.face_depth(0, x, z), Some(d), "{name}");
                    }
                }
            }
            if before == 0 && after >= 2 {
                for (e, t) in p.model.events().iter().zip(&p.tracks) {
                    let sum: f64 = (1..=after)
                        .flat_map(|k| {
                            let q = pair(&m, k - 1, k);
                            q.tracks
                                .iter()
                                .zip(q.model.events())
                                .filter(|(u, _)| *u == t)
                                .map(|(_, f)| f.volume_m3)
                                .collect::<Vec<_>>()
                        })
                        .sum();
                    assert!((e.volume_m3 - sum).abs() < 1e-9, "{name}: track {t}");
                }
            }
        }
        // 5 surveys: 2 + 3 + 3 + 3 interval events, baselines 5 + 7 + 10; 3 surveys: 2 + 3, and
        // 4 places in the baseline (0, 2) (the scar opened and grew: one event).
        assert_eq!(checked, if n == 5 { 11 + 22 } else { 5 + 4 });
    }
}

/// The campaign's layout for every number of surveys from 3 to 41, and for 100 and 401 (the
/// most): two or three events per interval of 1–20 m³; one recurring place (its track in
/// intervals 1 and min(3, N − 1), the later shape containing the earlier, their footprints and
/// truth circles overlapping, the second volume the difference); every other place changes in
/// one interval only; in the last survey all places are ≥ 5 m apart on the beach and on the
/// face, ≥ 5 m from the site's ends, the beach's seaward border, the face's foot and its top;
/// deposits (gains on the beach) stay ≥ 1.5 m in front of the foot; a place's change stays in
/// every later survey.
#[test]
fn campaign_layout_for_every_size() {
    for n in (campaign::MIN_EPOCHS..=41).chain([100, campaign::MAX_EPOCHS]) {
        let m = CampaignModel::new(n).unwrap();
        assert_eq!(m.epochs(), n);
        let recur = 3.min(n - 1);
        assert_eq!(m.recurring_interval(), recur);
        let mut seen: Vec<(u32, usize, ModelEvent)> = Vec::new();
        for k in 1..n {
            let p = pair(&m, k - 1, k);
            let ev = p.model.events();
            assert!((2..=3).contains(&ev.len()), "{n}: interval {k}");
            assert_eq!(p.tracks.len(), ev.len());
            for (e, &t) in ev.iter().zip(&p.tracks) {
                assert!(
                    (1.0..=20.0).contains(&e.volume_m3.abs()),
                    "{n}: {}",
                    e.volume_m3
                );
                seen.push((t, k, e.clone()));
            }
        }
        let recurring: Vec<&(u32, usize, ModelEvent)> = seen
            .iter()
            .filter(|(t, _, _)| seen.iter().filter(|(u, _, _)| u == t).count() > 1)
            .collect();
        assert_eq!(recurring.len(), 2, "{n}");
        let [(t1, k1, e1), (t2, k2, e2)] = [recurring[0], recurring[1]];
        assert_eq!(
            (*t1, *t2),
            (campaign::RECURRING_TRACK, campaign::RECURRING_TRACK)
        );
        assert_eq!((*k1, *k2), (1, recur));
        let (Footprint::Face { min: a0, max: a1 }, Footprint::Face { min: b0, max: b1 }) =
            (e1.footprint, e2.footprint)
        else {
            panic!("the recurring change is a scar")
        };
        // The later footprint contains the earlier: they overlap.
        assert!(in_rect(b0, b1, 0.0, a0[0], a0[1]) && in_rect(b0, b1, 0.0, a1[0], a1[1]));
        let d = (0..3)
            .map(|i| (e1.centre[i] - e2.centre[i]).powi(2))
            .sum::<f64>();
        assert!(d.sqrt() < e1.radius_m + e2.radius_m);
        assert!(e1.volume_m3 < 0.0 && e2.volume_m3 < 0.0);
        // The last survey against the first: one event per place, each place once.
        let all = pair(&m, 0, n - 1);
        let mut tracks = all.tracks.clone();
        tracks.sort_unstable();
        tracks.dedup();
        assert_eq!(tracks.len(), all.tracks.len());
        assert_eq!(tracks.len(), seen.len() - 1);
        let ([x0, x1], beach, [z0, z1]) = m.site();
        let ev = all.model.events();
        for (i, e) in ev.iter().enumerate() {
            let (min, max, lo, hi) = match e.footprint {
                Footprint::Ground { min, max } => (min, max, -beach, 0.0),
                Footprint::Face { min, max } => (min, max, z0, z1),
                Footprint::Frame { .. } => panic!("a campaign has no scanned face"),
            };
            assert!(
                min[0] >= x0 + 5.0 - 1e-9 && max[0] <= x1 - 5.0 + 1e-9,
                "{n}"
            );
            assert!(min[1] >= lo + 5.0 - 1e-9, "{n}: {}", e.description);
            if let Footprint::Face { .. } = e.footprint {
                assert!(max[1] <= hi - 5.0 + 1e-9, "{n}: {}", e.description);
            } else if e.volume_m3 > 0.0 {
                assert!(max[1] <= -1.5, "{n}: {} touches the face", e.description);
            }
            for f in &ev[i + 1..] {
                let (b0, b1) = match (e.footprint, f.footprint) {
                    (Footprint::Ground { .. }, Footprint::Ground { min, max })
                    | (Footprint::Face { .. }, Footprint::Face { min, max }) => (min, max),
                    _ => continue,
                };
                let gap = (0..2)
                    .map(|k| (b0[k] - max[k]).max(min[k] - b1[k]))
                    .fold(f64::NEG_INFINITY, f64::max);
                assert!(gap >= 5.0 - 1e-9, "{n}: gap {gap}");
            }
        }
        // Accumulation on the surfaces: at each event's centre survey j (j ≥ its interval k)
        // differs from survey k − 1 as survey k does, but for the recurring scar after it grew.
        if n <= 6 {
            for (t, k, e) in &seen {
                let change = |j: usize| {
                    let (s, ep) = survey(&m, j);
                    let (b, bp) = survey(&m, k - 1);
                    let c = e.centre;
                    match e.footprint {
                        Footprint::Ground { .. } => {
                            s.height(ep, c[0], c[1]).unwrap() - b.height(bp, c[0], c[1]).unwrap()
                        }
                        Footprint::Frame { .. } => unreachable!("a campaign has no scanned face"),
                        Footprint::Face { .. } => {
                            b.face_depth(bp, c[0], c[2]).unwrap()
                                - s.face_depth(ep, c[0], c[2]).unwrap()
                        }
                    }
                };
                let first = change(*k);
                assert!(first.abs() > 0.3, "{n}: {}", e.description);
                for j in *k..n {
                    let grown = *t == campaign::RECURRING_TRACK && *k == 1 && j >= recur;
                    if !grown {
                        assert_eq!(change(j), first, "{n}: {} in survey {j}", e.description);
                    }
                }
            }
        }
    }
}

/// The written campaign: `survey_YYYYMMDD.laz` every three months from 2021-03-01 (dates in
/// order, each name holding its date), LAS 1.4 point format 6 LAZ, 1 mm scale, the WKT CRS, the
/// advertised point count (100 per m² of plan: ≈ 0.1 m spacing) and point source id k + 1;
/// truth.json holds the returned truth, consecutive pairs and baseline pairs (0, k), ids from 1,
/// kinds by sign. Through the points: near every event's centre each survey's points lie on that
/// survey's analytic surface, and every survey from the event's interval on holds its change
/// (deposits raise, pits lower the beach, scars take the face back), the recurring scar 0.8 m
/// deep until it grows and 1.3 m after.
#[test]
fn campaign_files_dates_and_accumulation() {
    let dir = tempfile::tempdir().unwrap();
    let o = CampaignOptions::default();
    let truth = campaign::write(dir.path(), &o).unwrap();
    let m = campaign::model(&o).unwrap();
    let n = campaign::DEFAULT_EPOCHS;
    let dates = [
        "2021-03-01",
        "2021-06-01",
        "2021-09-01",
        "2021-12-01",
        "2022-03-01",
    ];
    assert_eq!(truth.epochs.len(), n);
    assert_eq!(campaign::date(40), "2031-03-01");
    let ([x0, x1], beach, _) = m.site();
    assert_eq!(
        m.default_points(),
        (100.0 * (x1 - x0) * (beach + 40.0)).round() as u64
    );
    let back: CampaignTruth =
        serde_json::from_slice(&std::fs::read(dir.path().join("truth.json")).unwrap()).unwrap();
    assert_eq!(
        (
            &back.scene,
            back.seed,
            &back.epochs,
            back.crs_epsg,
            &back.crs_wkt
        ),
        (
            &truth.scene,
            truth.seed,
            &truth.epochs,
            CRS_EPSG,
            &truth.crs_wkt
        )
    );
    assert_eq!(back.crs_wkt, UTM33N_WKT);
    let pairs = |t: &CampaignTruth| -> Vec<(usize, usize)> {
        t.pairs
            .iter()
            .chain(&t.baseline_pairs)
            .map(|p| (p.before, p.after))
            .collect()
    };
    let mut expect: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
    expect.extend((2..n).map(|k| (0, k)));
    assert_eq!(pairs(&truth), expect);
    assert_eq!(pairs(&back), expect);
    for (p, q) in truth
        .pairs
        .iter()
        .chain(&truth.baseline_pairs)
        .zip(back.pairs.iter().chain(&back.baseline_pairs))
    {
        assert_eq!(p.events.len(), q.events.len());
        for (i, (e, f)) in p.events.iter().zip(&q.events).enumerate() {
            assert_eq!(e.event.id as usize, i + 1);
            assert_eq!(
                (e.track, &e.event.description),
                (f.track, &f.event.description)
            );
            assert_eq!(e.event.kind == "gain", e.event.volume_m3 > 0.0);
            assert!((e.event.volume_m3 - f.event.volume_m3).abs() < 1e-9);
            assert!((0..3).all(|k| (e.event.centre[k] - f.event.centre[k]).abs() < 1e-6));
        }
    }
    let mut points = Vec::new();
    for (k, ep) in truth.epochs.iter().enumerate() {
        assert_eq!(ep.date, dates[k]);
        assert_eq!(
            ep.file.to_str().unwrap(),
            format!("survey_{}.laz", dates[k].replace('-', ""))
        );
        assert_eq!(ep.points, m.default_points());
        let path = dir.path().join(&ep.file);
        let mut reader = las::Reader::from_path(&path).unwrap();
        let h = reader.header().clone();
        assert_eq!(h.version(), las::Version::new(1, 4));
        assert_eq!(h.point_format().to_u8().unwrap(), 6);
        assert!(h.point_format().is_compressed);
        assert_eq!(h.number_of_points(), ep.points);
        assert_eq!(
            (h.transforms().x.scale, h.transforms().z.scale),
            (0.001, 0.001)
        );
        let wkt = h.get_wkt_crs_bytes().expect("WKT CRS VLR");
        assert_eq!(
            std::str::from_utf8(wkt).unwrap().trim_end_matches('\0'),
            UTM33N_WKT
        );
        let data = reader.read_all().unwrap();
        assert!(data.point_source_id().all(|id| id as usize == k + 1));
        let local: Vec<[f64; 3]> = data
            .x()
            .zip(data.y())
            .zip(data.z())
            .map(|((x, y), z)| [x - ORIGIN[0], y - ORIGIN[1], z])
            .collect();
        assert_eq!(local.len() as u64, ep.points);
        points.push(local);
    }
    for f in std::fs::read_dir(dir.path()).unwrap() {
        let name = f.unwrap().file_name();
        assert!(!name.to_string_lossy().ends_with(".tmp"), "{name:?}");
    }
    let recur = m.recurring_interval();
    // Each place's first interval: the recurring scar's is 1.
    let first_interval = |t: u32| {
        (1..n)
            .find(|&k| pair(&m, k - 1, k).tracks.contains(&t))
            .unwrap()
    };
    for k in 1..n {
        let p = pair(&m, k - 1, k);
        for (e, &t) in p.model.events().iter().zip(&p.tracks) {
            let since = first_interval(t);
            // Scars go into the rock (+y), deposits raise the beach, pits lower it.
            let up = matches!(e.footprint, Footprint::Face { .. }) || e.volume_m3 > 0.0;
            let c = e.centre;
            for (j, pts) in points.iter().enumerate() {
                let (s, ep) = survey(&m, j);
                let (s0, _) = survey(&m, 0);
                // Points within 0.3 m of the centre across the surface: their mean offset from
                // survey j's surface (noise only, ≤ 1.2 × 5 mm along z on the slopes:
                // 6 mm / √(≈ 28) per mean, bound at 5σ) and from the intact site's (the change
                // held by survey j).
                let (mut on, mut off, mut count) = (0.0, 0.0, 0.0);
                for q in pts {
                    match e.footprint {
                        Footprint::Ground { .. } if (q[0] - c[0]).hypot(q[1] - c[1]) < 0.3 => {
                            on += q[2] - s.height(ep, q[0], q[1]).unwrap();
                            off += q[2] - s0.height(0, q[0], q[1]).unwrap();
                        }
                        Footprint::Face { .. }
                            if (q[0] - c[0]).hypot(q[2] - c[2]) < 0.3 && q[1].abs() < 3.0 =>
                        {
                            on += q[1] - s.face_depth(ep, q[0], q[2]).unwrap();
                            off += q[1];
                        }
                        _ => continue,
                    }
                    count += 1.0;
                }
                assert!(count > 10.0, "{}: {count} points", e.description);
                let (on, off) = (on / count, off / count);
                assert!(
                    on.abs() < 0.006,
                    "{} survey {j}: {on} off its surface",
                    e.description
                );
                if j < since {
                    assert!(off.abs() < 0.006, "{} survey {j}: {off}", e.description);
                } else {
                    assert!(
                        off.abs() > 0.3,
                        "{} survey {j}: change {off}",
                        e.description
                    );
                    assert_eq!(off > 0.0, up, "{}", e.description);
                }
                if t == campaign::RECURRING_TRACK && j >= 1 {
                    let deep = if j >= recur { 1.3 } else { 0.8 };
                    assert!(
                        (off - deep).abs() < 0.01,
                        "recurring scar survey {j}: {off}"
                    );
                }
            }
        }
    }
}

/// Same options → identical bytes of every survey and truth.json (also on one thread); another
/// seed → other points in every survey and the same planted changes (the layout does not depend
/// on the seed); the surveys of one campaign come from different random streams.
#[test]
fn campaign_same_seed_same_bytes() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    let o = CampaignOptions {
        epochs: 4,
        ..CampaignOptions::default()
    };
    let ta = campaign::write(a.path(), &o).unwrap();
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| campaign::write(b.path(), &o))
        .unwrap();
    let tc = campaign::write(
        c.path(),
        &CampaignOptions {
            seed: 2,
            ..o.clone()
        },
    )
    .unwrap();
    for ep in &ta.epochs {
        let x = std::fs::read(a.path().join(&ep.file)).unwrap();
        assert_eq!(
            x,
            std::fs::read(b.path().join(&ep.file)).unwrap(),
            "{:?}",
            ep.file
        );
        assert_ne!(
            x,
            std::fs::read(c.path().join(&ep.file)).unwrap(),
            "{:?}",
            ep.file
        );
    }
    let json = std::fs::read(a.path().join("truth.json")).unwrap();
    assert_eq!(json, std::fs::read(b.path().join("truth.json")).unwrap());
    assert_eq!((ta.pairs.clone(), tc.seed), (tc.pairs.clone(), 2));
    let first: Vec<Vec<[f64; 3]>> = (0..4)
        .map(|k| {
            campaign::survey_chunks(&o, k)
                .unwrap()
                .flatten()
                .take(100)
                .collect()
        })
        .collect();
    for k in 1..4 {
        assert_ne!(first[k], first[k - 1]);
    }
}

/// Out-of-range options are usage errors: 2 or 402 surveys, too few points, bad noise, a pair not
/// in order, a survey past the last.
#[test]
fn campaign_bad_options_are_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let o = CampaignOptions::default();
    for bad in [
        CampaignOptions {
            epochs: 2,
            ..o.clone()
        },
        CampaignOptions {
            epochs: campaign::MAX_EPOCHS + 1,
            ..o.clone()
        },
        CampaignOptions {
            points: Some(10),
            ..o.clone()
        },
        CampaignOptions {
            noise: Some(-0.1),
            ..o.clone()
        },
    ] {
        let e = campaign::write(dir.path(), &bad).unwrap_err();
        assert_eq!(e.exit_code(), 2, "{e}");
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    let m = campaign::model(&o).unwrap();
    for (i, j) in [(1, 1), (2, 1), (0, 5)] {
        assert_eq!(m.pair(i, j).unwrap_err().exit_code(), 2, "({i}, {j})");
    }
    let e = campaign::survey_chunks(&o, 5).err().expect("no survey 5");
    assert_eq!(e.exit_code(), 2);
}

/// The command line: `talus synth campaign --out DIR --epochs 3 --points P --seed S --noise M
/// --las` writes three LAS surveys and truth.json with those settings; `--rotate` with a campaign
/// and `--epochs` with a pair scene are usage errors (exit 2).
#[test]
fn campaign_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_talus"))
            .args(args)
            .output()
            .unwrap()
    };
    let o = out.to_str().unwrap();
    let r = run(&[
        "synth", "campaign", "--out", o, "--epochs", "3", "--points", "20000", "--seed", "7",
        "--noise", "0.01", "--las",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let t: CampaignTruth =
        serde_json::from_slice(&std::fs::read(out.join("truth.json")).unwrap()).unwrap();
    assert_eq!((t.seed, t.noise_m, t.epochs.len()), (7, 0.01, 3));
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|f| f.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            ".talus-synth.json",
            "survey_20210301.las",
            "survey_20210601.las",
            "survey_20210901.las",
            "truth.json"
        ]
    );
    for e in &t.epochs {
        assert_eq!(e.points, 20000);
        let r = las::Reader::from_path(out.join(&e.file)).unwrap();
        assert!(!r.header().point_format().is_compressed);
    }
    for args in [
        &["synth", "campaign", "--out", o, "--rotate", "10"][..],
        &["synth", "campaign", "--out", o, "--epochs", "2"],
        &["synth", "hill", "--out", o, "--epochs", "3"],
    ] {
        let r = run(args);
        assert_eq!(r.status.code(), Some(2), "{args:?}");
    }
}

/// Run the talus binary with `args`.
fn talus_cmd(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_talus"))
        .args(args)
        .output()
        .unwrap()
}

/// Issue 44, item 4: `synth` and `demo` never replace a file they did not write — a user's
/// `before.laz`, `truth.json`, a survey or a `.tmp` of one in `--out` is named and left, and
/// nothing of the scene is written; synth's own files are replaced, and those of an earlier scene
/// the new one does not write (a campaign of fewer surveys) removed, the user's beside them kept.
#[test]
fn synth_and_demo_never_replace_a_users_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scene");
    let o = out.to_str().unwrap();
    std::fs::create_dir(&out).unwrap();
    for name in ["before.laz", "truth.json", "after.laz.tmp"] {
        std::fs::write(out.join(name), format!("the user's {name}")).unwrap();
        let r = talus_cmd(&["synth", "cliff", "--out", o, "--points", "20000"]);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{name}: {err}");
        assert!(
            err.contains(name) && err.contains("did not write it"),
            "{name}: {err}"
        );
        assert_eq!(
            std::fs::read_to_string(out.join(name)).unwrap(),
            format!("the user's {name}")
        );
        std::fs::remove_file(out.join(name)).unwrap();
        let left: Vec<_> = std::fs::read_dir(&out).unwrap().flatten().collect();
        assert!(left.is_empty(), "{name}: wrote {left:?}");
    }
    // Its own files: written again at will.
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    for _ in 0..2 {
        let r = talus_cmd(&["synth", "cliff", "--out", o, "--points", "20000"]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    // A campaign of 4 surveys, then of 3: the fourth (synth's) goes, the user's file stays.
    let camp = dir.path().join("camp");
    let c = camp.to_str().unwrap();
    std::fs::create_dir(&camp).unwrap();
    std::fs::write(camp.join("notes.txt"), "mine").unwrap();
    for epochs in ["4", "3"] {
        let r = talus_cmd(&[
            "synth", "campaign", "--out", c, "--epochs", epochs, "--points", "20000",
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    }
    let surveys = std::fs::read_dir(&camp)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("survey_"))
        .count();
    assert_eq!(surveys, 3);
    for folder in [&out, &camp] {
        assert_eq!(
            std::fs::read_to_string(folder.join("notes.txt")).unwrap(),
            "mine"
        );
    }
    // A user's survey file where the campaign would write one.
    let name = campaign::file_name(3, true);
    std::fs::write(camp.join(&name), "the user's survey").unwrap();
    let r = talus_cmd(&["synth", "campaign", "--out", c, "--epochs", "4"]);
    assert_eq!(r.status.code(), Some(2));
    assert_eq!(
        std::fs::read_to_string(camp.join(&name)).unwrap(),
        "the user's survey"
    );
    // demo: its scene folder holding the user's before.laz.
    let demo = dir.path().join("demo");
    std::fs::create_dir_all(demo.join("scene")).unwrap();
    std::fs::write(demo.join("scene/before.laz"), "the user's").unwrap();
    let r = talus_cmd(&["demo", "--out", demo.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(2), "{err}");
    assert!(err.contains("before.laz"), "{err}");
    assert_eq!(
        std::fs::read_to_string(demo.join("scene/before.laz")).unwrap(),
        "the user's"
    );
    assert!(!demo.join("result").exists());
}
