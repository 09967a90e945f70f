//! Shared helpers of the integration tests: deterministic random surfaces, writing clouds,
//! running `talus`.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use talus::io::las_out::ResultWriter;
use talus::io::{Crs, Point3};

/// The library's seeded generator (SplitMix64), for test surfaces.
pub type Rng = talus::rng::SplitMix64;

/// UTM-like offset so that the tests exercise large coordinates.
pub const OFFSET: Point3 = [500_000.0, 5_000_000.0, 100.0];

/// Write `points` (global coordinates) as LAS/LAZ by the extension.
pub fn write_cloud(path: &Path, points: &[Point3]) {
    let mut w = ResultWriter::create(path, &Crs::default(), &[], OFFSET).unwrap();
    for p in points {
        w.write(*p, &[]).unwrap();
    }
    w.finish().unwrap();
}

/// Write a text cloud "x y z" per line.
pub fn write_text(path: &Path, header: &str, points: &[Point3]) {
    let mut s = String::from(header);
    for p in points {
        s.push_str(&format!("{:.4},{:.4},{:.4}\n", p[0], p[1], p[2]));
    }
    std::fs::write(path, s).unwrap();
}

/// The talus binary built for these tests.
pub fn talus() -> Command {
    Command::new(env!("CARGO_BIN_EXE_talus"))
}

/// Run talus with `args`; returns the output.
pub fn run(args: &[&str]) -> Output {
    talus().args(args).output().expect("talus runs")
}

/// `talus ARGS...`, which must succeed (else the test fails with its stderr).
pub fn run_ok(args: &[&str]) {
    let o = run(args);
    assert!(
        o.status.success(),
        "talus {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// `talus compare BEFORE AFTER --out OUT EXTRA...`, whatever its outcome.
pub fn run_compare(before: &Path, after: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "compare",
        before.to_str().unwrap(),
        after.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// `talus synth cliff --points POINTS` into `dir/scene`: (before.laz, after.laz).
pub fn synth_cliff(dir: &Path, points: u64) -> (PathBuf, PathBuf) {
    let scene = dir.join("scene");
    let out = run(&[
        "synth",
        "cliff",
        "--out",
        scene.to_str().unwrap(),
        "--points",
        &points.to_string(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (scene.join("before.laz"), scene.join("after.laz"))
}

/// A fresh temporary directory.
pub fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

/// The shared data folder, or None (tests that need it then say so and skip).
pub fn data(sub: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(sub);
    assert!(
        p.is_dir(),
        "{} is missing: the real data the tests use travels in tests/data (see its README)",
        p.display()
    );
    p
}
/// Assert that `talus status DIR` says DIR holds its plan's whole published set.
pub fn assert_published(dir: &Path) {
    let o = run(&["status", dir.to_str().unwrap()]);
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("published (this plan's)"),
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// The journal a publish of DIR's finished outputs unit writes (`.talus/publishing`): its files,
/// the marker last, each source as a path in `.talus/units` (`absolute`) or relative to it (as
/// journals are written since sources were made relative).
pub fn publish_journal(dir: &Path, absolute: bool) -> serde_json::Value {
    let units = dir.join(".talus/units");
    let unit = std::fs::read_dir(units.join("outputs"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(unit.join("record.json")).unwrap()).unwrap();
    let mut files: Vec<(String, String)> = record["meta"]["publish"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let rel = Path::new(p["kind"].as_str().unwrap())
                .join(p["unit"].as_str().unwrap())
                .join(p["file"].as_str().unwrap());
            let src = if absolute { units.join(rel) } else { rel };
            (
                src.to_string_lossy().into_owned(),
                p["name"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    files.sort_by_key(|(_, n)| n == "summary.json");
    serde_json::json!({ "files": files, "marker": "summary.json", "remove": [], "dirs": [] })
}

pub mod dod;
pub mod laspy;
pub mod scan;
