//! Many processes, one DIR (issue "A plan of units and a store that many processes share"):
//! - a plan executed by three OS processes — the `compare` that planned it and two `talus worker
//!   DIR` — one worker SIGKILLed mid-way and started again, gives the bytes of a one-process run,
//!   and the units' records show that every process computed some;
//! - one run per DIR: a second `compare` on a DIR in use refuses at once (exit 2, naming DIR and
//!   the other process); the lock of a killed run does not block;
//! - a reader never sees a mix of two runs: a changed-parameter resume killed at random moments
//!   leaves DIR with the files of one run (the old or the new), never some of each;
//! - `--force` reads its inputs before anything is replaced (here the result's own m3c2.laz as
//!   core points) and never removes a file talus did not write.

mod common;
mod pipeline_common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use common::{run_compare, Rng};
use pipeline_common::{assert_same_outputs, cliff, compare, unit_times, COMPARED};

/// Small tiles, so that there are many units to share.
const ARGS: &[&str] = &[
    "--tile-size",
    "5",
    "--core-spacing",
    "0.25",
    "--threads",
    "1",
];

fn spawn(args: &[&str]) -> Child {
    common::talus()
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("talus starts")
}

fn compare_args<'a>(
    before: &'a Path,
    after: &'a Path,
    out: &'a Path,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut a = vec![
        "compare",
        before.to_str().unwrap(),
        after.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    a.extend_from_slice(extra);
    a
}

fn wait_for(what: &str, limit: Duration, mut ready: impl FnMut() -> bool) {
    let t = Instant::now();
    while !ready() {
        assert!(t.elapsed() < limit, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The process (host~pid) that wrote each finished unit of `kind`, from its record.
fn writers(dir: &Path, kind: &str) -> BTreeMap<String, String> {
    unit_times(dir, kind)
        .into_keys()
        .map(|name| {
            let rec = dir
                .join(".talus/units")
                .join(kind)
                .join(&name)
                .join("record.json");
            let v: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(rec).unwrap()).unwrap();
            (name, v["writer"].as_str().unwrap_or_default().to_string())
        })
        .collect()
}

#[test]
fn three_processes_one_killed_give_the_one_process_bytes() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 100_000);
    let reference = tmp.path().join("reference");
    compare(&before, &after, &reference, ARGS);

    let dir = tmp.path().join("shared");
    let d = dir.to_str().unwrap().to_string();
    let driver = spawn(&compare_args(&before, &after, &dir, ARGS));
    wait_for("the plan", Duration::from_secs(60), || {
        dir.join(".talus/plan.json").exists()
    });
    let worker = || spawn(&["worker", &d, "--slots", "1", "--threads", "1"]);
    let mut w1 = worker();
    let mut w2 = worker();
    // Kill the first worker once a few M3C2 units are done, then start it again.
    wait_for("M3C2 units", Duration::from_secs(120), || {
        unit_times(&dir, "m3c2").len() >= 10
    });
    w1.kill().unwrap(); // SIGKILL
    w1.wait().unwrap();
    let mut w3 = worker();
    let driver_out = driver.wait_with_output().unwrap();
    assert!(
        driver_out.status.success(),
        "{}",
        String::from_utf8_lossy(&driver_out.stderr)
    );
    for w in [&mut w2, &mut w3] {
        let status = w.wait().unwrap();
        assert!(status.success(), "a worker failed: {status}");
    }
    assert_same_outputs(&reference, &dir);
    // Every process computed M3C2 units (the killed worker's finished ones survive).
    let by: BTreeSet<String> = writers(&dir, "m3c2").into_values().collect();
    assert!(by.len() >= 3, "M3C2 units written by {by:?}");
    // Nothing half-done is taken for done: no unit directory without its record, and every
    // unit of the plan finished once.
    let plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(".talus/plan.json")).unwrap())
            .unwrap();
    let planned = plan["units"].as_array().unwrap().len();
    let finished: usize = [
        "tiling", "align", "aligned", "field", "orient", "m3c2", "stable", "events", "points",
        "volumes", "outputs",
    ]
    .iter()
    .map(|k| unit_times(&dir, k).len())
    .sum();
    assert_eq!(finished, planned);
}

#[test]
fn one_run_per_dir_and_a_killed_run_does_not_block() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 100_000);
    let dir = tmp.path().join("run");
    let mut first = spawn(&compare_args(&before, &after, &dir, ARGS));
    wait_for("the first run's lock", Duration::from_secs(60), || {
        dir.join(".talus/lock").exists()
    });
    let t = Instant::now();
    let second = run_compare(&before, &after, &dir, &[ARGS, &["--resume"]].concat());
    assert!(t.elapsed() < Duration::from_secs(5), "refused at once");
    assert_eq!(second.status.code(), Some(2));
    let msg = String::from_utf8_lossy(&second.stderr);
    assert_eq!(msg.lines().count(), 1, "{msg}");
    assert!(msg.contains(dir.to_str().unwrap()), "{msg}");
    assert!(msg.contains(&format!("pid {}", first.id())), "{msg}");
    // SIGKILL leaves the lock behind; a new run finds it stale and goes on.
    first.kill().unwrap();
    first.wait().unwrap();
    assert!(dir.join(".talus/lock").exists());
    let third = run_compare(&before, &after, &dir, &[ARGS, &["--resume"]].concat());
    assert!(
        third.status.success(),
        "{}",
        String::from_utf8_lossy(&third.stderr)
    );
    assert!(!dir.join(".talus/lock").exists());
}

/// The bytes of DIR's published files (those present), by name; summary.json (whose stage
/// timings differ between runs) as its counts and totals.
fn published(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut m = BTreeMap::new();
    if let Ok(text) = std::fs::read_to_string(dir.join("summary.json")) {
        let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
        v.as_object_mut().unwrap().remove("stages");
        m.insert("summary.json".into(), v.to_string().into_bytes());
    }
    let mut names: Vec<String> = COMPARED.iter().map(|s| s.to_string()).collect();
    if let Ok(rd) = std::fs::read_dir(dir.join("meshes")) {
        names.extend(rd.map(|e| format!("meshes/{}", e.unwrap().file_name().to_string_lossy())));
    }
    for n in names {
        if let Ok(b) = std::fs::read(dir.join(&n)) {
            m.insert(n, b);
        }
    }
    m
}

#[test]
fn a_killed_resume_never_leaves_a_mix_of_two_runs() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 60_000);
    // The two runs: defaults and a changed threshold (other events, other meshes).
    let changed = [ARGS, &["--threshold", "0.2", "--eps", "0.8"]].concat();
    let old = tmp.path().join("old");
    compare(&before, &after, &old, ARGS);
    let new = tmp.path().join("new");
    compare(&before, &after, &new, &changed);
    let (old_set, new_set) = (published(&old), published(&new));
    assert_ne!(old_set, new_set);
    let dir = tmp.path().join("run");
    let mut rng = Rng::new(7);
    let t = Instant::now();
    compare(&before, &after, &dir, ARGS);
    let full = t.elapsed();
    for attempt in 0..8 {
        // Alternate between the two parameter sets, each time a resume from the other's result,
        // killed at a random moment of the events-to-publish part (the M3C2 units are reused).
        let args = if attempt % 2 == 0 {
            &changed
        } else {
            &ARGS.to_vec()
        };
        let mut child = spawn(&compare_args(
            &before,
            &after,
            &dir,
            &[args.as_slice(), &["--resume"]].concat(),
        ));
        std::thread::sleep(full.mul_f64(0.02 + 0.4 * rng.uniform()));
        let _ = child.kill();
        child.wait().unwrap();
        let now = published(&dir);
        let of = |set: &BTreeMap<String, Vec<u8>>| now.iter().all(|(n, b)| set.get(n) == Some(b));
        assert!(
            of(&old_set) || of(&new_set),
            "attempt {attempt}: DIR holds files of both runs: {:?}",
            now.keys().collect::<Vec<_>>()
        );
        if now.contains_key("summary.json") {
            // A set with its marker is complete.
            assert!(
                now == old_set || now == new_set,
                "attempt {attempt}: incomplete set"
            );
        }
    }
    let out = run_compare(
        &before,
        &after,
        &dir,
        &[&changed[..], &["--resume"]].concat(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(published(&dir), new_set);
}

#[test]
fn force_reads_inputs_first_and_spares_user_files() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 40_000);
    let r = tmp.path().join("R");
    compare(&before, &after, &r, ARGS);
    // The user's own files beside the results, one inside meshes/.
    std::fs::write(r.join("notes.txt"), b"field notes").unwrap();
    std::fs::write(r.join("meshes/my_surface.ply"), b"ply\nmine").unwrap();
    // The previous result as the core points, where the new result will be published: refused
    // (it would be replaced), nothing touched.
    let published: PathBuf = r.join("m3c2.laz");
    let kept = std::fs::read(&published).unwrap();
    let out = run_compare(
        &before,
        &after,
        &r,
        &["--force", "--core-points", published.to_str().unwrap()],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("lies where talus writes its output"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read(&published).unwrap(), kept);
    // A copy of it outside DIR: read first, then DIR's outputs replaced.
    let cores: PathBuf = tmp.path().join("cores.laz");
    std::fs::copy(&published, &cores).unwrap();
    let out = run_compare(
        &before,
        &after,
        &r,
        &[
            "--tile-size",
            "5",
            "--force",
            "--core-points",
            cores.to_str().unwrap(),
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read(r.join("notes.txt")).unwrap(), b"field notes");
    assert_eq!(
        std::fs::read(r.join("meshes/my_surface.ply")).unwrap(),
        b"ply\nmine"
    );
    // The core points were the previous result's: the new m3c2.laz has them, in their order.
    let t = talus::io::result_table::read(&cores).unwrap();
    assert!(t.xyz.len() > 1000);
    for s in [
        "summary.json",
        "events.geojson",
        "meshes/event_0001_before.ply",
    ] {
        assert!(r.join(s).exists(), "{s}");
    }
}
