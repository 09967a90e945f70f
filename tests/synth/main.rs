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

mod campaigns;
mod features;

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
