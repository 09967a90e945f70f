//! Where the scenes put their changes: the cliff's scars, the deposit, the hole, the events
//! scene drawn from the seed; and `--shift`.

use super::*;

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
