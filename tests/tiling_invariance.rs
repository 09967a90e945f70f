//! Tiling invariance (SPEC.md §3): the same scene as one tile, as many small tiles, and with one
//! or two threads gives the same outputs, byte for byte.
//!
//! The reference is the whole-cloud run (one tile: no halo, no tile border); a tiled run must
//! reproduce it exactly, because every neighbourhood of a core point lies inside its tile's halo
//! and core points, clusters and event ids are defined on global grids and keys. The files are
//! compared as bytes, and m3c2.laz is also read back column by column with
//! `talus::io::result_table::read` so that a failure says which values differ and where.

mod common;

use std::path::{Path, PathBuf};

use common::run;

/// The outputs that do not hold timings (summary.json does; its counts are compared apart).
const COMPARED: &[&str] = &["m3c2.laz", "events.geojson", "events.csv", "view.json", "terrain.bin"];

/// Write the cliff scene (3 planted events) with `points` per epoch into `dir`.
pub fn cliff(dir: &Path, points: u64) -> (PathBuf, PathBuf) {
    let out = run(&[
        "synth",
        "cliff",
        "--out",
        dir.to_str().unwrap(),
        "--points",
        &points.to_string(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    (dir.join("before.laz"), dir.join("after.laz"))
}

fn compare(before: &Path, after: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "compare",
        before.to_str().unwrap(),
        after.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = run(&args);
    assert!(
        o.status.success(),
        "talus {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Which m3c2.laz values differ between two runs: a readable failure message.
fn describe_differences(a: &Path, b: &Path) -> String {
    let ta = talus::io::result_table::read(a).unwrap();
    let tb = talus::io::result_table::read(b).unwrap();
    if ta.xyz.len() != tb.xyz.len() {
        return format!("{} vs {} core points", ta.xyz.len(), tb.xyz.len());
    }
    let mut msg = String::new();
    let n_xyz = ta.xyz.iter().zip(&tb.xyz).filter(|(p, q)| p != q).count();
    if n_xyz > 0 {
        msg.push_str(&format!("xyz differ at {n_xyz} points; "));
    }
    for name in &ta.names {
        let (ca, cb) = (ta.column(name).unwrap(), tb.column(name).unwrap());
        let diff: Vec<usize> = (0..ca.len())
            .filter(|&i| ca[i].to_bits() != cb[i].to_bits() && !(ca[i].is_nan() && cb[i].is_nan()))
            .collect();
        if let Some(&i) = diff.first() {
            let max = diff
                .iter()
                .map(|&i| (ca[i] - cb[i]).abs())
                .fold(0.0f64, f64::max);
            msg.push_str(&format!(
                "{name}: {} points differ (max |Δ| {max:e}; first at {:?}: {} vs {}); ",
                diff.len(),
                ta.xyz[i],
                ca[i],
                cb[i]
            ));
        }
    }
    msg
}

fn assert_same_outputs(reference: &Path, other: &Path) {
    // The event solids too (meshes/*.ply).
    let meshes = |d: &Path| {
        let mut v: Vec<String> = std::fs::read_dir(d.join("meshes"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    let names = meshes(reference);
    assert!(!names.is_empty(), "no event meshes in {}", reference.display());
    assert_eq!(names, meshes(other));
    let mesh_paths: Vec<String> = names.iter().map(|n| format!("meshes/{n}")).collect();
    let all = COMPARED
        .iter()
        .map(|s| s.to_string())
        .chain(mesh_paths);
    for name in all {
        let name = name.as_str();
        let (a, b) = (reference.join(name), other.join(name));
        let (ba, bb) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        if ba != bb {
            let detail = if name == "m3c2.laz" {
                describe_differences(&a, &b)
            } else {
                String::new()
            };
            panic!(
                "{} differs from {}: {detail}",
                b.display(),
                a.display()
            );
        }
    }
}

/// summary.json without what legitimately differs: timings, tile count and side, thread count.
fn summary_without_timings(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let o = v.as_object_mut().unwrap();
    for k in ["stages", "tiles", "tile_size"] {
        o.remove(k);
    }
    // The thread count is a parameter of the run, echoed back.
    if let Some(p) = v["parameters"].as_object_mut() {
        p.remove("threads");
    }
    v
}

/// The cliff scene's planted scars are centred at x = 500 012 and 500 040 on the face at
/// y = 5 000 000. With core spacing 0.25 the grid is anchored at (500 000, 4 999 980), so 4 m
/// tiles put a tile corner exactly at both scar centres (and 10 m tiles at the second): each
/// scar is then cut into four tiles, the worst case for halos, core-point selection at borders,
/// orientation and the merged DBSCAN.
#[test]
fn tiled_runs_equal_the_whole_cloud_run() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 120_000);
    let whole = tmp.path().join("whole");
    let base = ["--core-spacing", "0.25"];
    compare(&before, &after, &whole, &[&base[..], &["--tile-size", "1000"]].concat());
    let s = summary_without_timings(&whole);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(whole.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["tiles"], 1, "the reference must be one tile");
    // The scene's three planted events are found (else the comparison below proves little).
    assert_eq!(s["events"], 3, "{s}");
    for (ts, threads) in [("4", "1"), ("4", "2"), ("10", "2"), ("13", "1")] {
        let tiled = tmp.path().join(format!("tiles{ts}-threads{threads}"));
        compare(
            &before,
            &after,
            &tiled,
            &[&base[..], &["--tile-size", ts, "--threads", threads]].concat(),
        );
        let t: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(tiled.join("summary.json")).unwrap())
                .unwrap();
        assert!(t["tiles"].as_u64().unwrap() > 1, "{t}");
        assert_same_outputs(&whole, &tiled);
        assert_eq!(s, summary_without_timings(&tiled), "summary.json of {ts} m tiles");
    }
}
