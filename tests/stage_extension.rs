//! A stage added by writing one module and registering it (`examples/survey_stage.rs`: each
//! survey's point count and heights) runs in every driver without a change to any of them: in
//! the command's own executor, in `worker`, and as a Slurm job array of its own. Its numbers are
//! checked against the surveys read directly, and the comparison's outputs are the same bytes
//! as plain talus's.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The example program `name` (`cargo test` builds the examples; built here when this test
/// runs alone).
fn example(name: &str) -> PathBuf {
    let talus = PathBuf::from(env!("CARGO_BIN_EXE_talus"));
    let dir = talus.parent().unwrap();
    let exe = dir.join("examples").join(name);
    if !exe.is_file() {
        let mut c = Command::new(env!("CARGO"));
        c.args(["build", "--example", name]);
        if dir.ends_with("release") {
            c.arg("--release");
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    exe
}

fn run(exe: &Path, args: &[&str]) -> Output {
    let o = Command::new(exe).args(args).output().unwrap();
    assert!(
        o.status.success(),
        "{} {args:?}: {}",
        exe.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// The heights of each survey as the stage recorded them, by survey label.
fn heights(out: &Path) -> Vec<serde_json::Value> {
    let dir = out.join(".talus/units/survey_heights");
    let mut units: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    units.sort();
    units
        .iter()
        .map(|u| serde_json::from_slice(&std::fs::read(u.join("heights.json")).unwrap()).unwrap())
        .collect()
}

/// Count, min, max and mean height of a cloud, read directly.
fn direct(path: &Path) -> (u64, f64, f64, f64) {
    let mut r = talus::io::open(path).unwrap();
    let mut buf = Vec::new();
    let (mut n, mut sum, mut lo, mut hi) = (0u64, 0.0, f64::INFINITY, f64::NEG_INFINITY);
    while r.fill(&mut buf, 1 << 16).unwrap() > 0 {
        for p in &buf {
            n += 1;
            sum += p[2];
            lo = lo.min(p[2]);
            hi = hi.max(p[2]);
        }
    }
    (n, lo, hi, sum / n as f64)
}

#[test]
fn a_registered_stage_runs_locally_in_a_worker_and_in_a_slurm_plan() {
    let exe = example("survey_stage");
    let tmp = common::tempdir();
    let scene = tmp.path().join("scene");
    let s = scene.to_str().unwrap();
    let o = common::run(&["synth", "hill", "--points", "20000", "--out", s]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (a, b) = (scene.join("before.laz"), scene.join("after.laz"));
    let (a_s, b_s) = (a.to_str().unwrap(), b.to_str().unwrap());
    let small = ["--tile-size", "12"];

    // Locally: the stage is planned, run and counted on its own progress line.
    let local = tmp.path().join("local");
    let mut args = vec!["compare", a_s, b_s, "--out", local.to_str().unwrap()];
    args.extend(small);
    let o = run(&exe, &args);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("survey heights"), "{stderr}");
    let got = heights(&local);
    assert_eq!(got.len(), 2, "{got:?}");
    for h in &got {
        let file = if h["survey"] == "before" { &a } else { &b };
        let (n, lo, hi, mean) = direct(file);
        assert_eq!(h["points"].as_u64(), Some(n), "{h}");
        assert_eq!(h["min_z"].as_f64(), Some(lo), "{h}");
        assert_eq!(h["max_z"].as_f64(), Some(hi), "{h}");
        let m = h["mean_z"].as_f64().unwrap();
        assert!(
            (m - mean).abs() <= 1e-9 * mean.abs().max(1.0),
            "{m} vs {mean}"
        );
    }
    // The comparison itself is plain talus's, byte for byte.
    let plain = tmp.path().join("plain");
    common::run_compare(&a, &b, &plain, &small);
    for f in [
        "events.csv",
        "events.geojson",
        "m3c2.laz",
        "event_regions.geojson",
    ] {
        assert_eq!(
            std::fs::read(local.join(f)).unwrap(),
            std::fs::read(plain.join(f)).unwrap(),
            "{f} differs with the extra stage"
        );
    }

    // In a Slurm plan: a job array of its own, right after the tilings it reads (one unit a
    // task, but at the tiling's end, `exec::slurm::Tail`, it would hold back the arrays that
    // wait for the tiling and not for it).
    let slurm = tmp.path().join("slurm");
    let mut args = vec![
        "compare",
        a_s,
        b_s,
        "--out",
        slurm.to_str().unwrap(),
        "--executor",
        "slurm",
        "--plan-only",
    ];
    args.extend(small);
    let o = run(&exe, &args);
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stages: Vec<&str> = stdout
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert_eq!(
        stages,
        [
            "tiling",
            "survey_heights",
            "align",
            "field",
            "m3c2",
            "volumes",
            "publish"
        ],
        "{stdout}"
    );
    let script = std::fs::read_to_string(slurm.join(".talus/slurm/1/02-survey_heights.sh"))
        .expect("a script for the stage");
    assert!(script.contains("--stage survey_heights"), "{script}");

    // A talus without the stage refuses that plan, naming the kind.
    let o = common::run(&["worker", slurm.to_str().unwrap()]);
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("survey_heights"), "{stderr}");

    // In a worker: the same plan's units, the stage's the same bytes as the local run's.
    run(&exe, &["worker", slurm.to_str().unwrap()]);
    assert_eq!(heights(&slurm), got);
}

/// A stage that provides tiles (`examples/datum_stage.rs`: the later survey's tiles lowered by
/// 0.5 m, a datum's offset), added by its own module and its registration only: every later
/// unit reads its tiles, because the stage says it provides them — none names it. Against
/// plain talus on the same surveys, each core point's distance is lower by 0.5 m along its
/// normal's vertical part.
#[test]
fn a_registered_stage_that_provides_tiles_is_read_by_every_later_unit() {
    let exe = example("datum_stage");
    let tmp = common::tempdir();
    let data = tmp.path().join("scene");
    run(
        Path::new(env!("CARGO_BIN_EXE_talus")),
        &[
            "synth",
            "cliff",
            "--points",
            "20000",
            "--out",
            data.to_str().unwrap(),
        ],
    );
    let (b, a) = (data.join("before.laz"), data.join("after.laz"));
    let compare = |exe: &Path, out: &Path| {
        let args = [
            "compare",
            b.to_str().unwrap(),
            a.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--align",
            "off",
        ];
        run(exe, &args);
        talus::io::result_table::read(&out.join("m3c2.laz")).unwrap()
    };
    let plain = compare(
        Path::new(env!("CARGO_BIN_EXE_talus")),
        &tmp.path().join("plain"),
    );
    let lowered = compare(&exe, &tmp.path().join("datum"));
    let (d0, d1) = (
        plain.column("m3c2_distance").unwrap(),
        lowered.column("m3c2_distance").unwrap(),
    );
    let nz = plain.column("normal_z").unwrap();
    assert_eq!(plain.xyz, lowered.xyz, "the same core points");
    let mut offsets: Vec<f64> = (0..d0.len())
        .filter(|&i| nz[i].abs() > 0.9 && d0[i].is_finite() && d1[i].is_finite())
        .map(|i| (d1[i] - d0[i]) / nz[i])
        .collect();
    assert!(offsets.len() > 1000, "{} core points", offsets.len());
    offsets.sort_by(f64::total_cmp);
    let median = offsets[offsets.len() / 2];
    assert!(
        (median + 0.5).abs() < 0.01,
        "median vertical offset {median}"
    );
    // The units that read tiles read the provider's: its units are in the plan, and nothing
    // but the registration added them.
    let units = tmp.path().join("datum/.talus/units/datum");
    assert_eq!(
        std::fs::read_dir(&units).unwrap().count(),
        1,
        "{}",
        units.display()
    );
}
