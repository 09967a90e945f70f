//! Helpers shared by the pipeline tests (tiling invariance, resume, faults): a scene with planted
//! events, running `talus compare`, and comparing two runs' outputs byte for byte.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};

use crate::common::{run, run_compare};

/// The outputs that do not hold timings (summary.json does; its counts are compared apart).
pub const COMPARED: &[&str] = &[
    "m3c2.laz",
    "events.geojson",
    "events.csv",
    "event_regions.geojson",
    "view.json",
    "terrain.bin",
];

/// `talus synth cliff` (3 planted events) with `points` per epoch into `dir`, with `extra`
/// options; the epochs' paths.
pub fn synth_cliff(dir: &Path, points: u64, extra: &[&str]) -> (PathBuf, PathBuf) {
    let n = points.to_string();
    let mut args = vec![
        "synth",
        "cliff",
        "--out",
        dir.to_str().unwrap(),
        "--points",
        &n,
    ];
    args.extend_from_slice(extra);
    let out = run(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ext = if extra.contains(&"--las") {
        "las"
    } else {
        "laz"
    };
    (
        dir.join(format!("before.{ext}")),
        dir.join(format!("after.{ext}")),
    )
}

/// Write the cliff scene (3 planted events) with `points` per epoch into `dir`.
pub fn cliff(dir: &Path, points: u64) -> (PathBuf, PathBuf) {
    synth_cliff(dir, points, &[])
}

/// `talus synth cliff` as uncompressed LAS with `seed` (so that two seeds give files of one size).
pub fn cliff_seeded(dir: &Path, points: u64, seed: u64) -> (PathBuf, PathBuf) {
    synth_cliff(dir, points, &["--seed", &seed.to_string(), "--las"])
}

pub fn compare(before: &Path, after: &Path, out: &Path, extra: &[&str]) {
    let o = run_compare(before, after, out, extra);
    assert!(
        o.status.success(),
        "talus compare {extra:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Which m3c2.laz values differ between two runs: a readable failure message.
pub fn describe_differences(a: &Path, b: &Path) -> String {
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

pub fn assert_same_outputs(reference: &Path, other: &Path) {
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
    assert!(
        !names.is_empty(),
        "no event meshes in {}",
        reference.display()
    );
    assert_eq!(names, meshes(other));
    let mesh_paths: Vec<String> = names.iter().map(|n| format!("meshes/{n}")).collect();
    let all = COMPARED.iter().map(|s| s.to_string()).chain(mesh_paths);
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
            panic!("{} differs from {}: {detail}", b.display(), a.display());
        }
    }
}

/// `compare` that must succeed; returns the stage lines of its two passes, tiling and M3C2, as
/// [`stage_line`] reads them.
pub fn compare_passes(before: &Path, after: &Path, out: &Path, extra: &[&str]) -> [(u64, bool); 2] {
    let o = run_compare(before, after, out, extra);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    [
        stage_line(&o.stderr, "pass 1: tiling"),
        stage_line(&o.stderr, "pass 2: normals and M3C2"),
    ]
}

/// The stage line `talus: <stage>: <count> ...` of a run's stderr: (count, reused).
pub fn stage_line(stderr: &[u8], stage: &str) -> (u64, bool) {
    let text = String::from_utf8_lossy(stderr);
    let prefix = format!("talus: {stage}: ");
    // The last line of the stage: a stage redone after damage prints a line again.
    let line = text
        .lines()
        .rfind(|l| l.starts_with(&prefix))
        .unwrap_or_else(|| panic!("no line for stage '{stage}' in:\n{text}"));
    let count = line[prefix.len()..]
        .split(' ')
        .next()
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no count in '{line}'"));
    (count, line.ends_with(", reused"))
}

/// The finished units of `kind` in DIR's store, by name, with the time their record was
/// written: a unit computed again gets a new record (its name holds its key).
pub fn unit_times(
    dir: &Path,
    kind: &str,
) -> std::collections::BTreeMap<String, std::time::SystemTime> {
    let mut m = std::collections::BTreeMap::new();
    let Ok(rd) = std::fs::read_dir(dir.join(".talus/units").join(kind)) else {
        return m;
    };
    for e in rd {
        let e = e.unwrap();
        if let Ok(meta) = std::fs::metadata(e.path().join("record.json")) {
            m.insert(
                e.file_name().to_string_lossy().into_owned(),
                meta.modified().unwrap(),
            );
        }
    }
    m
}

/// The directory of the finished unit of `kind` whose name starts with `prefix` (e.g.
/// "after-" for the after survey's tiling, "pair-t_0001_0002-" for a tile's M3C2).
pub fn unit_dir(dir: &Path, kind: &str, prefix: &str) -> PathBuf {
    let names: Vec<String> = unit_times(dir, kind)
        .into_keys()
        .filter(|n| n.starts_with(prefix))
        .collect();
    assert_eq!(names.len(), 1, "one {kind} unit {prefix}*: {names:?}");
    dir.join(".talus/units").join(kind).join(&names[0])
}

/// Start `talus compare BEFORE AFTER --out OUT EXTRA...` (stdout discarded, stderr as `stderr`).
pub fn spawn_compare(
    before: &Path,
    after: &Path,
    out: &Path,
    extra: &[&str],
    stderr: Stdio,
) -> Child {
    crate::common::talus()
        .args([
            "compare",
            before.to_str().unwrap(),
            after.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(stderr)
        .spawn()
        .expect("talus starts")
}

/// Every unit of `finished` (name → record time) still has its record of then in `now`.
pub fn assert_not_redone(
    finished: &std::collections::BTreeMap<String, std::time::SystemTime>,
    now: &std::collections::BTreeMap<String, std::time::SystemTime>,
) {
    for (name, time) in finished {
        assert_eq!(
            now.get(name),
            Some(time),
            "{name} was finished but computed again"
        );
    }
}

/// The cliff scene with `points` per epoch under `tmp`, and an uninterrupted run of it with
/// `args` in `tmp/reference`: (before, after, reference).
pub fn cliff_and_reference(tmp: &Path, points: u64, args: &[&str]) -> (PathBuf, PathBuf, PathBuf) {
    let (before, after) = cliff(&tmp.join("scene"), points);
    let reference = tmp.join("reference");
    compare(&before, &after, &reference, args);
    (before, after, reference)
}
