//! LAS classes (SPEC.md §4 "classification first"): vegetation (3, 4, 5) and noise (7, 18) left
//! out by default, `--classes` choosing, summary.json saying what was left out; every point
//! format 0 to 10, LAS and LAZ alike.

mod common;

use std::path::Path;

use talus::io::classes::Classes;
use talus::io::{self, Point3};

/// Classes of the fixture's points, in turn: ground, unclassified, the three vegetation classes,
/// building, low noise, high noise, water.
const CYCLE: [u8; 9] = [2, 1, 3, 4, 5, 6, 7, 18, 9];

/// `n` points on a small slope, with their classes from [`CYCLE`].
fn classified_points(n: usize) -> Vec<(Point3, u8)> {
    (0..n)
        .map(|i| {
            let (x, y) = ((i % 50) as f64 * 0.25, (i / 50) as f64 * 0.25);
            (
                [300_000.0 + x, 5_773_000.0 + y, 10.0 + 0.1 * x],
                CYCLE[i % CYCLE.len()],
            )
        })
        .collect()
}

/// Write `points` with their classes in point format `format` (LAZ when `laz`), las-rs's writer.
fn write_las(path: &Path, format: u8, laz: bool, points: &[(Point3, u8)]) {
    let mut f = las::point::Format::new(format).unwrap();
    f.is_compressed = laz;
    let mut b = las::Builder::from((1, 4));
    b.point_format = f;
    b.transforms = las::Vector {
        x: las::Transform {
            scale: 0.001,
            offset: 300_000.0,
        },
        y: las::Transform {
            scale: 0.001,
            offset: 5_773_000.0,
        },
        z: las::Transform {
            scale: 0.001,
            offset: 0.0,
        },
    };
    let header = b.into_header().unwrap();
    let mut w = las::Writer::from_path(path, header).unwrap();
    for &(p, c) in points {
        let mut q = las::Point {
            x: p[0],
            y: p[1],
            z: p[2],
            classification: las::point::Classification::new(c).unwrap(),
            ..Default::default()
        };
        if f.has_gps_time {
            q.gps_time = Some(0.0);
        }
        if f.has_color {
            q.color = Some(las::Color::default());
        }
        if f.has_nir {
            q.nir = Some(0);
        }
        if f.has_waveform {
            q.waveform = Some(las::raw::point::Waveform::default());
        }
        w.write_point(q).unwrap();
    }
    w.close().unwrap();
}

/// Every point of `path` through `io::open_with(classes)`, and its class counts.
fn read(path: &Path, classes: Option<&Classes>) -> (Vec<Point3>, Option<io::classes::ClassCounts>) {
    let mut r = io::open_with(path, classes).unwrap();
    let (mut all, mut buf) = (Vec::new(), Vec::new());
    // Small chunks: a decoded chunk is split over several calls.
    while r.fill(&mut buf, 7).unwrap() > 0 {
        all.extend_from_slice(&buf);
    }
    (all, r.class_counts())
}

/// Every point format 0 to 10, LAS and LAZ: the default leaves out exactly the points of classes
/// 3, 4, 5, 7 and 18, in order, and counts them per class; `all` and no filter read every point;
/// a list keeps only its classes. (Legacy formats 0–5 hold the class in 5 bits: 18 fits.)
#[test]
fn every_point_format_leaves_out_vegetation_and_noise_by_default() {
    let dir = common::tempdir();
    let pts = classified_points(1000);
    let per = |c: u8| pts.iter().filter(|p| p.1 == c).count() as u64;
    for format in 0..=10u8 {
        for laz in [false, true] {
            let path = dir
                .path()
                .join(format!("f{format}.{}", if laz { "laz" } else { "las" }));
            write_las(&path, format, laz, &pts);
            let what = format!("format {format} {}", if laz { "LAZ" } else { "LAS" });
            let (kept, counts) = read(&path, Some(&Classes::default()));
            let expect: Vec<Point3> = pts
                .iter()
                .filter(|p| ![3, 4, 5, 7, 18].contains(&p.1))
                .map(|p| p.0)
                .collect();
            assert_eq!(kept.len(), expect.len(), "{what}");
            for (a, b) in kept.iter().zip(&expect) {
                for k in 0..3 {
                    assert!((a[k] - b[k]).abs() < 1e-6, "{what}: {a:?} vs {b:?}");
                }
            }
            let counts = counts.expect("counts with a filter");
            assert!(counts.classified(), "{what}");
            let expect_rows: Vec<(u8, u64, u64)> = {
                let mut c: Vec<u8> = CYCLE.to_vec();
                c.sort_unstable();
                c.iter()
                    .map(|&k| {
                        let n = per(k);
                        (k, n, if [3, 4, 5, 7, 18].contains(&k) { n } else { 0 })
                    })
                    .collect()
            };
            assert_eq!(counts.classes, expect_rows, "{what}");
            // Everything: with `all` (the classification is not even read) and without a filter.
            let (every, none) = read(&path, Some(&Classes::all()));
            assert_eq!(every.len(), pts.len(), "{what}");
            assert!(none.is_none(), "{what}");
            assert_eq!(read(&path, None).0.len(), pts.len(), "{what}");
            // A list keeps its classes only.
            let (ground, _) = read(&path, Some(&Classes::parse("2").unwrap()));
            assert_eq!(ground.len() as u64, per(2), "{what}");
        }
    }
}

/// A survey delivered classified, with shrubs (class 4) that differ between the two surveys —
/// grown, moved, one of them new — on an otherwise unchanged cliff scene with one planted
/// rockfall: by default the shrubs are left out, every output but summary.json is the same bytes
/// as the comparison of the unclassified surveys without shrubs, and summary.json says how many
/// points of which class each survey left out. With `--classes all` the shrubs enter the
/// comparison and change its events; `--classes` with a bad list is refused, exit 2.
#[test]
fn classified_shrubs_are_left_out_and_the_results_are_those_without_them() {
    let dir = common::tempdir();
    let d = dir.path();
    let (scene_before, scene_after) = common::synth_cliff(d, 120_000);
    // Both surveys as ground (class 2), plus shrubs: on the plateau and on the beach, a cloud of
    // points scattered through a 2 × 2 × 1.5 m box above the ground; the after survey's grown by
    // 20 % and one more on the beach.
    let shrubs = |boxes: &[([f64; 3], f64)], seed: u64| -> Vec<(Point3, u8)> {
        let mut rng = common::Rng::new(seed);
        let mut v = Vec::new();
        for &(c, grow) in boxes {
            for _ in 0..4000 {
                let u = [rng.uniform(), rng.uniform(), rng.uniform()];
                v.push((
                    [
                        c[0] + (u[0] - 0.5) * 2.0 * grow,
                        c[1] + (u[1] - 0.5) * 2.0 * grow,
                        c[2] + 0.2 + u[2] * 1.5 * grow,
                    ],
                    4u8,
                ));
            }
        }
        v
    };
    let ground_of = |path: &Path| -> Vec<(Point3, u8)> {
        let (pts, _) = read(path, None);
        pts.into_iter().map(|p| (p, 2u8)).collect()
    };
    let (before, after) = (ground_of(&scene_before), ground_of(&scene_after));
    // Shrub places: over the middle of the plateau and of the beach, from the points' bounds.
    let b = bounds(&before);
    let mid_x = 0.5 * (b.0[0] + b.1[0]);
    let top = |x: f64, y: f64| {
        before
            .iter()
            .filter(|p| (p.0[0] - x).abs() < 1.0 && (p.0[1] - y).abs() < 1.0)
            .map(|p| p.0[2])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let plateau = [mid_x + 8.0, b.1[1] - 3.0];
    let beach = [mid_x - 8.0, b.0[1] + 5.0];
    let beach2 = [mid_x + 14.0, b.0[1] + 6.0];
    let at = |c: [f64; 2]| [c[0], c[1], top(c[0], c[1])];
    let mut before_c = before.clone();
    before_c.extend(shrubs(&[(at(plateau), 1.0), (at(beach), 1.0)], 7));
    let mut after_c = after.clone();
    after_c.extend(shrubs(
        &[(at(plateau), 1.2), (at(beach), 1.2), (at(beach2), 1.0)],
        8,
    ));
    for (name, pts) in [
        ("before_c.laz", &before_c),
        ("after_c.laz", &after_c),
        ("before_g.laz", &before),
        ("after_g.laz", &after),
    ] {
        write_las(&d.join(name), 6, true, pts);
    }
    let compare = |b: &str, a: &str, res: &str, extra: &[&str]| {
        let out = common::run_compare(&d.join(b), &d.join(a), &d.join(res), extra);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr)
    };
    compare("before_g.laz", "after_g.laz", "ground", &[]);
    let line = compare("before_c.laz", "after_c.laz", "default", &[]);
    assert!(
        line.contains("left out: before 8000 (class 4), after 12000 (class 4)"),
        "{line}"
    );
    for f in [
        "events.geojson",
        "events.csv",
        "m3c2.laz",
        "event_regions.geojson",
    ] {
        assert_eq!(
            std::fs::read(d.join("ground").join(f)).unwrap(),
            std::fs::read(d.join("default").join(f)).unwrap(),
            "{f} differs with the shrubs left out"
        );
    }
    let summary = json(&d.join("default/summary.json"));
    let c = &summary["classes"];
    assert_eq!(c["used"], "all but 3,4,5,7,18");
    assert_eq!(c["surveys"][0]["left_out"], 8000);
    assert_eq!(c["surveys"][1]["left_out"], 12000);
    assert_eq!(c["surveys"][1]["classified"], true);
    assert_eq!(
        c["surveys"][1]["per_class"],
        serde_json::json!([
            {"class": 2, "points": after.len(), "left_out": 0},
            {"class": 4, "points": 12000, "left_out": 12000}
        ])
    );
    assert!(summary["parameters"]["classes"]["source"]
        .as_str()
        .unwrap()
        .starts_with("default"));
    // Every class: the shrubs are compared, and the events change.
    compare("before_c.laz", "after_c.laz", "all", &["--classes", "all"]);
    let all = json(&d.join("all/summary.json"));
    assert_eq!(all["classes"]["used"], "all");
    assert!(all["classes"]["surveys"][0].is_null());
    assert_ne!(
        std::fs::read(d.join("ground/events.geojson")).unwrap(),
        std::fs::read(d.join("all/events.geojson")).unwrap(),
        "the shrubs did not change the events"
    );
    // A bad list.
    let out = common::run_compare(
        &d.join("before_c.laz"),
        &d.join("after_c.laz"),
        &d.join("bad"),
        &["--classes", "2,veg"],
    );
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--classes") && err.contains("'veg'"), "{err}");
    assert!(!d.join("bad").join("summary.json").exists());
}

fn bounds(p: &[(Point3, u8)]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for (q, _) in p {
        for k in 0..3 {
            lo[k] = lo[k].min(q[k]);
            hi[k] = hi[k].max(q[k]);
        }
    }
    (lo, hi)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// `talus info` says which classes a LAS file carries and how many points a comparison leaves
/// out by default, and measures the spacing on the rest (as `compare` does).
#[test]
fn info_lists_the_classes_and_what_a_comparison_leaves_out() {
    let dir = common::tempdir();
    let pts = classified_points(2000);
    let path = dir.path().join("c.laz");
    write_las(&path, 6, true, &pts);
    let left_out = pts
        .iter()
        .filter(|p| [3, 4, 5, 7, 18].contains(&p.1))
        .count();
    let o = common::run(&["info", path.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("classes        1: 223, 2: 223, 3: 222, 4: 222"),
        "{text}"
    );
    assert!(
        text.contains(&format!("a comparison leaves out {left_out} points")),
        "{text}"
    );
    let o = common::run(&["info", "--json", path.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v[0]["classes"]["left_out"], left_out as u64);
    assert_eq!(v[0]["classes"]["classified"], true);
}

/// The spacing pass keeps what it decodes (`io::replay`), and the file's later readers in this
/// process read that copy: the same points in the same order, bit for bit, the same header and
/// class counts as decoding the file, for a cloud measured whole (3,000 points, LAZ) and one
/// measured in a window (450,000 points, more than `sampling::WHOLE`). Only the same filter
/// reads the copy; a damaged copy is an error naming it, after which the file is decoded
/// again; a file changed since is decoded; the copy is removed with its `Replay`.
#[test]
fn a_file_decoded_once_reads_back_from_its_copy_as_it_decodes() {
    use std::io::{Read, Seek, Write};
    use talus::io::replay::Recorder;
    let dir = common::tempdir();
    // Kept as f64 triples (no transform given), and as the LAS integers (the file's transform).
    for (n, laz, quantised) in [(3_000, true, false), (450_000, false, true)] {
        assert!(laz || n as u64 > talus::sampling::WHOLE);
        let path = dir
            .path()
            .join(format!("r{n}.{}", if laz { "laz" } else { "las" }));
        write_las(&path, 6, laz, &classified_points(n));
        let keep = Classes::default();
        let (decoded, counts) = read(&path, Some(&keep));
        let info = io::open(&path).unwrap().info().clone();
        let copy = dir.path().join(format!("copy{n}"));
        let transform = info.transform.filter(|_| quantised);
        // The spacing pass, recording what it decodes into `copy`.
        let record = || {
            let mut recorder = Recorder::create(&path, Some(&keep), transform, copy.clone());
            let measured =
                talus::sampling::measure_keeping(&path, Some(&keep), &mut |p| recorder.push(p))
                    .unwrap();
            recorder
                .finish(&measured.info, measured.classes.clone())
                .expect("a copy")
        };
        let replay = record();
        assert_eq!(replay.file(), copy.as_path());
        assert_eq!(
            std::fs::metadata(&copy).unwrap().len(),
            if quantised { 12 } else { 24 } * decoded.len() as u64,
            "{n}: the copy holds every point kept, once"
        );
        // Read through the copy: the same bits, counts and header.
        let mut r = io::open_with(&path, Some(&keep)).unwrap();
        assert_eq!(r.info().point_count, info.point_count);
        assert_eq!(r.info().bounds, info.bounds);
        assert_eq!(r.info().transform, info.transform);
        let (mut again, mut buf) = (Vec::new(), Vec::new());
        while r.fill(&mut buf, 7_777).unwrap() > 0 {
            again.extend_from_slice(&buf);
        }
        assert_eq!(r.left_out(), counts.as_ref().unwrap().left_out());
        assert_eq!(r.class_counts(), counts);
        let bits =
            |v: &[Point3]| -> Vec<[u64; 3]> { v.iter().map(|p| p.map(f64::to_bits)).collect() };
        assert_eq!(bits(&again), bits(&decoded), "{n}: replayed as decoded");
        // Read whole once, the copy is gone (its one reader, the tiling, is done): the next
        // reader decodes the file.
        assert!(!copy.exists(), "{n}: the copy is removed once read whole");
        assert_eq!(bits(&read(&path, Some(&keep)).0), bits(&decoded));
        drop(replay);
        // Recorded again and damaged before it is read: an error naming it (another filter
        // decodes the file).
        let replay = record();
        let mut f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&copy)
            .unwrap();
        let mut byte = [0u8; 1];
        f.seek(std::io::SeekFrom::Start(100)).unwrap();
        f.read_exact(&mut byte).unwrap();
        f.seek(std::io::SeekFrom::Start(100)).unwrap();
        f.write_all(&[byte[0] ^ 0x10]).unwrap();
        drop(f);
        assert_eq!(read(&path, Some(&Classes::all())).0.len(), n);
        let mut r = io::open_with(&path, Some(&keep)).unwrap();
        let err = loop {
            match r.fill(&mut buf, 1 << 16) {
                Ok(0) => panic!("{n}: a damaged copy read back without an error"),
                Ok(_) => continue,
                Err(e) => break e,
            }
        };
        let text = err.to_string();
        assert!(
            text.contains(&copy.display().to_string()) && text.contains("checksum"),
            "{text}"
        );
        assert_eq!(err.exit_code(), 1, "{text}");
        // Given up: the file is decoded again.
        assert_eq!(bits(&read(&path, Some(&keep)).0), bits(&decoded));
        drop(replay);
        assert!(!copy.exists(), "{n}: the copy is removed with its Replay");
    }
    // A file changed after its copy was made is decoded, not replayed.
    let path = dir.path().join("changed.laz");
    write_las(&path, 6, true, &classified_points(500));
    let copy = dir.path().join("copy-changed");
    let mut recorder = Recorder::create(&path, None, None, copy.clone());
    talus::sampling::measure_keeping(&path, None, &mut |p| recorder.push(p)).unwrap();
    let info = io::open(&path).unwrap().info().clone();
    let replay = recorder.finish(&info, None).expect("a copy");
    std::thread::sleep(std::time::Duration::from_millis(20));
    write_las(&path, 6, true, &classified_points(700));
    assert_eq!(read(&path, None).0.len(), 700);
    drop(replay);
    // Integers that would not give the points back (a coarser scale than the file's) give the
    // copy up.
    let coarse = info.transform.map(|t| t.map(|[s, o]| [10.0 * s, o]));
    let mut recorder = Recorder::create(&path, None, coarse, dir.path().join("copy-coarse"));
    talus::sampling::measure_keeping(&path, None, &mut |p| recorder.push(p)).unwrap();
    assert!(recorder.finish(&info, None).is_none());
    assert!(!dir.path().join("copy-coarse").exists());
    // A copy that cannot be written is given up: nothing is kept, nothing fails.
    let mut recorder = Recorder::create(&path, None, None, dir.path().join("no/such/dir/copy"));
    talus::sampling::measure_keeping(&path, None, &mut |p| recorder.push(p)).unwrap();
    assert!(recorder.finish(&info, None).is_none());
}

/// Issue 44, item 5: classes that leave no point are named as such — `--classes 9` on class-2
/// data (as BEFORE), an all-noise file (as AFTER: it said "the epochs do not overlap"; as
/// BEFORE "all points coincide or there are fewer than two") — and `talus info` describes such a
/// file (its count, its classes, what is left out) instead of failing.
#[test]
fn classes_that_leave_no_point_are_named() {
    let dir = common::tempdir();
    let slope = |n: usize, class: u8| -> Vec<(Point3, u8)> {
        classified_points(n)
            .into_iter()
            .map(|(p, _)| (p, class))
            .collect()
    };
    let ground = dir.path().join("ground.laz");
    let ground2 = dir.path().join("ground2.laz");
    let noise = dir.path().join("noise.laz");
    write_las(&ground, 6, true, &slope(2000, 2));
    write_las(&ground2, 6, true, &slope(1800, 2));
    write_las(&noise, 6, true, &slope(2000, 7));
    let out = dir.path().join("out");
    let cases: [(&Path, &Path, &[&str], &Path, String); 3] = [
        (
            &ground,
            &ground2,
            &["--classes", "9"],
            &ground,
            "none of its 2000 points is of the classes compared (9): it holds class 2 (2000 \
             points)"
                .to_string(),
        ),
        (
            &ground,
            &noise,
            &[],
            &noise,
            "none of its 2000 points is of the classes compared (all but 3,4,5,7,18): it holds \
             class 7 (2000 points)"
                .to_string(),
        ),
        (
            &noise,
            &ground,
            &[],
            &noise,
            "none of its 2000 points is of the classes compared".to_string(),
        ),
    ];
    for (before, after, extra, named, needle) in cases {
        let o = common::run_compare(before, after, &out, extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        let last = err.trim().lines().last().unwrap_or("");
        assert!(
            last.contains(named.to_str().unwrap()) && last.contains(&needle),
            "{needle}: {err}"
        );
        for untrue in ["coincide", "fewer than two", "do not overlap"] {
            assert!(!err.contains(untrue), "{err}");
        }
        assert!(!out.exists(), "{} left behind", out.display());
    }
    let o = common::run(&["info", noise.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for needle in [
        "points         2000",
        "classes        7: 2000; a comparison leaves out 2000 points",
        "not measurable: none of its 2000 points is of the classes compared",
    ] {
        assert!(text.contains(needle), "{needle}: {text}");
    }
    let o = common::run(&["info", "--json", noise.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v[0]["classes"]["left_out"], 2000);
    assert!(
        v[0]["spacing"].is_null() && v[0]["derived"].is_null(),
        "{v}"
    );
    assert!(
        v[0]["spacing_note"].as_str().unwrap().contains("class 7"),
        "{v}"
    );
}
