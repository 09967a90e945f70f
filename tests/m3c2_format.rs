//! m3c2.laz from a real `compare` run, read back by name from its Extra Bytes VLR with our reader
//! and with laspy (independent): every SPEC.md §2 dimension is there with the right type and
//! values that agree with each other and with the M3C2 definitions.

mod common;

use talus::io::result_table;

const NAMES: [(&str, &str); 14] = [
    ("m3c2_distance", "float32"),
    ("m3c2_uncertainty", "float32"),
    ("m3c2_significant", "uint8"),
    ("m3c2_std_dev1", "float32"),
    ("m3c2_std_dev2", "float32"),
    ("m3c2_count1", "uint32"),
    ("m3c2_count2", "uint32"),
    ("normal_x", "float32"),
    ("normal_y", "float32"),
    ("normal_z", "float32"),
    ("m3c2_smoothed", "float32"),
    ("event_id", "uint32"),
    ("m3c2_beyond_reach", "uint8"),
    ("normal_sign_unknown", "uint8"),
];

/// `talus synth cube` into `dir/scene`.
fn cube_scene(dir: &std::path::Path) -> std::path::PathBuf {
    let scene = dir.join("scene");
    let o = common::run(&["synth", "cube", "--out", scene.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    scene
}

/// `talus compare` of the scene's epochs into `dir/res`, with `extra` arguments.
fn compare(scene: &std::path::Path, dir: &std::path::Path, extra: &[&str]) -> std::path::PathBuf {
    let res = dir.join("res");
    let o = common::run_compare(
        &scene.join("before.laz"),
        &scene.join("after.laz"),
        &res,
        extra,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    res
}

#[test]
fn m3c2_laz_dimensions_and_values() {
    let dir = common::tempdir();
    let scene = cube_scene(dir.path());
    let res = compare(&scene, dir.path(), &[]);
    let laz = res.join("m3c2.laz");
    let t = result_table::read(&laz).unwrap();
    assert_eq!(
        t.names,
        NAMES.iter().map(|n| n.0.to_string()).collect::<Vec<_>>()
    );
    let col = |n: &str| t.column(n).unwrap();
    let (d, lod, sig) = (
        col("m3c2_distance"),
        col("m3c2_uncertainty"),
        col("m3c2_significant"),
    );
    let (s1, s2, n1, n2) = (
        col("m3c2_std_dev1"),
        col("m3c2_std_dev2"),
        col("m3c2_count1"),
        col("m3c2_count2"),
    );
    let (nx, ny, nz) = (col("normal_x"), col("normal_y"), col("normal_z"));
    let (sm, ev) = (col("m3c2_smoothed"), col("event_id"));
    // The registration error the run measured on the stable ground (summary.json).
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(res.join("summary.json")).unwrap()).unwrap();
    let reg = summary["parameters"]["reg_error"]["value"]
        .as_f64()
        .unwrap();
    assert!(summary["parameters"]["reg_error"]["source"]
        .as_str()
        .unwrap()
        .starts_with("measured"));
    let mut computed = 0;
    for i in 0..t.xyz.len() {
        if !d[i].is_finite() {
            assert_eq!(sig[i], 0.0);
            continue;
        }
        computed += 1;
        // LoD95 = 1.96 (sqrt(σ1²/n1 + σ2²/n2) + reg_error), significant = |d| > LoD95; the file
        // holds them as float32 (relative rounding 6e-8 each), and rounding keeps their order.
        let want = 1.96 * ((s1[i] * s1[i] / n1[i] + s2[i] * s2[i] / n2[i]).sqrt() + reg);
        assert!(
            (lod[i] - want).abs() <= 1e-6 * want.max(1.0),
            "{} vs {want}",
            lod[i]
        );
        if sig[i] == 1.0 {
            assert!(d[i].abs() >= lod[i], "{} vs {}", d[i], lod[i]);
        } else {
            assert!(d[i].abs() <= lod[i], "{} vs {}", d[i], lod[i]);
        }
        assert!(n1[i] >= 1.0 && n2[i] >= 1.0);
        let len = (nx[i] * nx[i] + ny[i] * ny[i] + nz[i] * nz[i]).sqrt();
        assert!((len - 1.0).abs() < 1e-6, "normal length {len}");
        // Event members are kept points: smoothed distance present, sign of their event.
        if ev[i] > 0.0 {
            assert!(sm[i].is_finite());
        }
    }
    assert!(computed > 1000);
    // Event ids agree with events.geojson (n_points per event).
    let fc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(res.join("events.geojson")).unwrap())
            .unwrap();
    for f in fc["features"].as_array().unwrap() {
        let id = f["properties"]["id"].as_f64().unwrap();
        let n = f["properties"]["n_points"].as_u64().unwrap() as usize;
        assert_eq!(ev.iter().filter(|&&e| e == id).count(), n, "event {id}");
    }

    // laspy decodes the same names, types and values from our VLR.
    let Some(py) = common::laspy::laspy_python() else {
        return;
    };
    let n = 500;
    let j = common::laspy::laspy_read(&py, &laz, n);
    assert_eq!(j["point_count"].as_u64().unwrap() as usize, t.xyz.len());
    let dims = j["extra_dims"].as_array().unwrap();
    assert_eq!(dims.len(), NAMES.len());
    for (dim, (name, ty)) in dims.iter().zip(NAMES) {
        assert_eq!(dim["name"], name);
        assert_eq!(dim["type"], ty);
        let vals = j["extra"][name].as_array().unwrap();
        for (k, v) in vals.iter().enumerate() {
            let ours = t.columns[name][k];
            match common::laspy::num(v) {
                Some(x) => assert_eq!(x, ours, "{name}[{k}]"),
                None => assert!(ours.is_nan(), "{name}[{k}]: laspy NaN, ours {ours}"),
            }
        }
    }
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        for (i, v) in j[axis].as_array().unwrap().iter().enumerate() {
            let x = common::laspy::num(v).unwrap();
            assert!((x - t.xyz[i][k]).abs() < 1e-9, "{axis}[{i}]");
        }
    }
}

/// Core points from a LAS file at 0.1 mm scale come back in m3c2.laz at their coordinates to the
/// 0.1 mm, in file order (m3c2.laz takes the inputs' finest coordinate quantum), and the header
/// says so (checked with laspy too).
#[test]
fn user_core_points_keep_their_precision_and_order() {
    use talus::io::las_out::{CoordinateGrid, ResultWriter};
    let dir = common::tempdir();
    let scene = cube_scene(dir.path());
    let (_, c1) = talus::io::read_all(&scene.join("before.laz")).unwrap();
    // Every 97th point of C1, moved by fractions of a millimetre, in reverse order.
    let cores: Vec<[f64; 3]> = c1
        .iter()
        .step_by(97)
        .enumerate()
        .map(|(i, p)| {
            let f = (i % 9) as f64 * 1e-4;
            [p[0] + f, p[1] - f, p[2] + 0.5 * f]
        })
        .rev()
        .collect();
    let grid = CoordinateGrid {
        scale: [1e-4; 3],
        offset: [500_000.0, 5_000_000.0, 0.0],
    };
    let path = dir.path().join("cores.las");
    let mut w =
        ResultWriter::create_on_grid(&path, &talus::io::Crs::default(), &[], grid, None).unwrap();
    for p in &cores {
        w.write(*p, &[]).unwrap();
    }
    w.finish().unwrap();
    // What the file holds: the points on the 0.1 mm grid.
    let (_, stored) = talus::io::read_all(&path).unwrap();
    let res = compare(
        &scene,
        dir.path(),
        &["--core-points", path.to_str().unwrap()],
    );
    let t = result_table::read(&res.join("m3c2.laz")).unwrap();
    assert_eq!(t.xyz.len(), stored.len());
    for (got, want) in t.xyz.iter().zip(&stored) {
        for a in 0..3 {
            assert!(
                (got[a] - want[a]).abs() < 1e-7,
                "core point {want:?} came back as {got:?}"
            );
        }
    }
    let Some(py) = common::laspy::laspy_python() else {
        return;
    };
    let j = common::laspy::laspy_read(&py, &res.join("m3c2.laz"), 0);
    let scales: Vec<f64> = j["scales"]
        .as_array()
        .expect("laspy scales")
        .iter()
        .map(|v| common::laspy::num(v).expect("a number"))
        .collect();
    assert_eq!(scales, vec![1e-4; 3]);
}
