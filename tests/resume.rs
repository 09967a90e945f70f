//! Resumable runs (SPEC.md §3 "Resume"): a run killed with SIGKILL at any moment and continued
//! with `--resume` gives the bytes of an uninterrupted run without redoing finished units; a
//! changed parameter or input redoes exactly what depends on it; `--force` starts over.
//!
//! The reference is an uninterrupted run of the same scene and parameters; the finished units
//! are read from the run's store (their directories and the times of their records), so "not
//! redone" is checked on disk, not taken from the program's word.

mod common;
mod pipeline_common;

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use common::run_compare;
use common::Rng;
use pipeline_common::{
    assert_same_outputs, cliff, cliff_seeded, compare, compare_passes, unit_times,
};

/// Small tiles, so that pass 2 has many units to be killed between.
const ARGS: &[&str] = &["--tile-size", "5", "--core-spacing", "0.25"];

fn spawn_compare(before: &Path, after: &Path, out: &Path, extra: &[&str]) -> std::process::Child {
    pipeline_common::spawn_compare(before, after, out, extra, Stdio::null())
}

#[test]
fn sigkill_at_random_moments_then_resume_gives_the_uninterrupted_result() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 100_000);
    let reference = tmp.path().join("reference");
    let t = Instant::now();
    compare(&before, &after, &reference, ARGS);
    let full = t.elapsed();

    let dir = tmp.path().join("killed");
    let mut rng = Rng::new(20_240_601);
    let mut landed = 0;
    // Units finished at some kill, with their records' times then: none may be redone.
    let mut finished = std::collections::BTreeMap::new();
    for attempt in 0..5 {
        let resume: &[&str] = if attempt == 0 { &[] } else { &["--resume"] };
        let mut child = spawn_compare(&before, &after, &dir, &[ARGS, resume].concat());
        // A moment between 5 % and 90 % of an uninterrupted run.
        let at = full.mul_f64(0.05 + 0.85 * rng.uniform());
        std::thread::sleep(at);
        if child.try_wait().unwrap().is_none() {
            child.kill().unwrap(); // SIGKILL on Unix
            landed += 1;
        }
        child.wait().unwrap();
        for (name, time) in unit_times(&dir, "m3c2") {
            finished.entry(name).or_insert(time);
        }
    }
    assert!(landed > 0, "no kill landed while the run was going");
    assert!(
        !finished.is_empty(),
        "no kill came after a finished M3C2 unit"
    );
    let out = run_compare(&before, &after, &dir, &[ARGS, &["--resume"]].concat());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_same_outputs(&reference, &dir);
    pipeline_common::assert_not_redone(&finished, &unit_times(&dir, "m3c2"));

    // A resume after a complete run reuses both passes.
    assert_eq!(
        compare_passes(&before, &after, &dir, &[ARGS, &["--resume"]].concat()),
        [(0, true), (0, true)]
    );
    assert_same_outputs(&reference, &dir);

    // --force starts over: both passes run again, same result.
    assert_eq!(
        compare_passes(&before, &after, &dir, &[ARGS, &["--force"]].concat()),
        [(200_000, false), (200_000, false)]
    );
    assert_same_outputs(&reference, &dir);
}

#[test]
fn a_changed_parameter_or_input_redoes_exactly_what_depends_on_it() {
    // The units' files kept (`--keep-units`): a later run with new parameters starts from them.
    const KEEP: &[&str] = &["--tile-size", "5", "--core-spacing", "0.25", "--keep-units"];
    let tmp = common::tempdir();
    // Uncompressed LAS: another sampling of the scene has exactly the same size.
    let (before, after) = cliff_seeded(&tmp.path().join("scene"), 60_000, 1);
    // `--resume` where nothing ran yet is a fresh run.
    let dir = tmp.path().join("run");
    assert_eq!(
        compare_passes(&before, &after, &dir, &[KEEP, &["--resume"]].concat()),
        [(120_000, false), (120_000, false)]
    );
    // A DIR holding a run is not overwritten without --resume or --force.
    let out = run_compare(&before, &after, &dir, KEEP);
    assert_eq!(out.status.code(), Some(2));

    // Events parameters (threshold, eps) reuse the tiles and every M3C2 unit, and give what a
    // fresh run with those parameters gives.
    let events_params = ["--threshold", "0.2", "--eps", "0.8"];
    let times = unit_times(&dir, "m3c2");
    assert_eq!(
        compare_passes(
            &before,
            &after,
            &dir,
            &[KEEP, &events_params, &["--resume"]].concat()
        ),
        [(0, true), (0, true)]
    );
    assert_eq!(unit_times(&dir, "m3c2"), times);
    let fresh = tmp.path().join("fresh");
    compare(&before, &after, &fresh, &[KEEP, &events_params].concat());
    assert_same_outputs(&fresh, &dir);

    // The registration error enters after M3C2 (LoD95, threshold, volume uncertainty): every
    // unit is reused and the result is a fresh run's.
    let reg_params = [KEEP, &events_params, &["--reg-error", "0.01"]].concat();
    assert_eq!(
        compare_passes(
            &before,
            &after,
            &dir,
            &[reg_params.as_slice(), &["--resume"]].concat()
        ),
        [(0, true), (0, true)]
    );
    let fresh_reg = tmp.path().join("fresh_reg");
    compare(&before, &after, &fresh_reg, &reg_params);
    assert_same_outputs(&fresh_reg, &dir);

    // An M3C2 parameter that does not change the halo (the points a cylinder needs) redoes
    // pass 2 only.
    let m3c2_params = [reg_params.as_slice(), &["--min-points", "3"]].concat();
    let resumed = [m3c2_params.as_slice(), &["--resume"]].concat();
    assert_eq!(
        compare_passes(&before, &after, &dir, &resumed),
        [(0, true), (120_000, false)]
    );

    // Rewriting the before file with the same bytes (a new modification time) redoes nothing:
    // units are keyed by content.
    let bytes = std::fs::read(&before).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    std::fs::write(&before, &bytes).unwrap();
    assert_eq!(
        compare_passes(&before, &after, &dir, &resumed),
        [(0, true), (0, true)]
    );

    // Other content of the same size, with the old modification time put back: that epoch is
    // cut again and pass 2 redone, and the result is a fresh run's on the new file. (The new
    // sampling's spacing differs in the fourth digit, and with it the derived radii and the
    // tiles' halo, so the after epoch is cut again too.)
    let other = tmp.path().join("other");
    let (other_before, _) = cliff_seeded(&other, 60_000, 7);
    let replacement = std::fs::read(&other_before).unwrap();
    let mtime = std::fs::metadata(&before).unwrap().modified().unwrap();
    assert_eq!(
        replacement.len(),
        bytes.len(),
        "same point count, same LAS size"
    );
    assert_ne!(replacement, bytes);
    std::fs::write(&before, &replacement).unwrap();
    let f = std::fs::File::options().write(true).open(&before).unwrap();
    f.set_modified(mtime).unwrap();
    drop(f);
    assert_eq!(
        std::fs::metadata(&before).unwrap().modified().unwrap(),
        mtime
    );
    let [tiling, m3c2] = compare_passes(&before, &after, &dir, &resumed);
    assert!(tiling.0 >= 60_000 && !tiling.1, "{tiling:?}");
    assert_eq!(m3c2, (120_000, false));
    let fresh2 = tmp.path().join("fresh2");
    compare(&before, &after, &fresh2, &m3c2_params);
    assert_same_outputs(&fresh2, &dir);
}

/// By default a finished run releases its intermediate units' files (tiles, M3C2 results): DIR
/// keeps its outputs and the units' records. A resume with nothing changed computes nothing; one
/// with new events parameters computes again the units it needs (the M3C2 results, from tiles
/// made again) and gives a fresh run's outputs, byte for byte.
#[test]
fn a_released_run_resumed_with_new_parameters_gives_a_fresh_runs_outputs() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 60_000);
    let dir = tmp.path().join("run");
    compare(&before, &after, &dir, ARGS);
    let units = dir.join(".talus/units");
    for kind in ["tiling", "field", "orient", "m3c2"] {
        for unit in std::fs::read_dir(units.join(kind)).unwrap() {
            let unit = unit.unwrap().path();
            let names: Vec<String> = std::fs::read_dir(&unit)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            assert_eq!(names, ["record.json"], "{}", unit.display());
            let record: serde_json::Value =
                serde_json::from_slice(&std::fs::read(unit.join("record.json")).unwrap()).unwrap();
            assert_eq!(record["released"], true, "{}", unit.display());
        }
    }
    // Nothing changed: nothing computed, the same outputs.
    let reference = tmp.path().join("reference");
    compare(
        &before,
        &after,
        &reference,
        &[ARGS, &["--keep-units"]].concat(),
    );
    assert_eq!(
        compare_passes(&before, &after, &dir, &[ARGS, &["--resume"]].concat()),
        [(0, true), (0, true)]
    );
    assert_same_outputs(&reference, &dir);
    // A changed parameter says which units it computes again and why, and so does `talus
    // status` afterwards.
    let o = run_compare(
        &before,
        &after,
        &dir,
        &[ARGS, &["--resume", "--threshold", "0.3"]].concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(
        said.contains("computing 1 events unit(s) again: a parameter it computes from changed")
            && said.contains("→ 0.3)"),
        "{said}"
    );
    let status = common::talus()
        .args(["status", dir.to_str().unwrap()])
        .output()
        .unwrap();
    let shown = String::from_utf8_lossy(&status.stdout);
    assert!(
        shown.contains("computed again: 1 events unit(s): a parameter it computes from changed"),
        "{shown}"
    );
    // New events parameters: tiles and M3C2 computed again, a fresh run's outputs.
    let events_params = ["--threshold", "0.2", "--eps", "0.8"];
    assert_eq!(
        compare_passes(
            &before,
            &after,
            &dir,
            &[ARGS, &events_params, &["--resume"]].concat()
        ),
        [(120_000, false), (120_000, false)]
    );
    let fresh = tmp.path().join("fresh");
    compare(&before, &after, &fresh, &[ARGS, &events_params].concat());
    assert_same_outputs(&fresh, &dir);
}

/// A resumed run takes the spacing its store measured on the same file (`plan::measured::cached_spacing`:
/// by content key, class filter and the measurement's version) instead of decoding the before
/// survey again; a fresh run measures and caches it. Seen on disk: an entry's count of measured
/// points, changed by hand, is what the resumed run's plan says; an entry of another version,
/// another filter or one that does not read is measured again.
/// The peak disk (issue 46): a unit's files go as soon as every unit that reads them is done,
/// not after publishing, and m3c2.laz is written once the tiles are gone. Read from the run's
/// timeline (`TALUS_TRACE`: each unit's begin, commit and release, in order) and its plan.
#[test]
fn intermediate_units_go_as_soon_as_their_readers_are_done() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 60_000);
    let dir = tmp.path().join("run");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_talus"))
        .args([
            "compare",
            before.to_str().unwrap(),
            after.to_str().unwrap(),
            "--out",
        ])
        .arg(&dir)
        .args(ARGS)
        .env("TALUS_TRACE", "1")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    // Where in the timeline each unit `what` happened ("begins", "committed", "released").
    let at = |name: &str, what: &str| -> Option<usize> {
        let line = format!("] unit {name} {what}");
        stderr.lines().position(|l| l.ends_with(&line))
    };
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join(".talus/plan.json")).unwrap()).unwrap();
    let units = plan["units"].as_array().unwrap();
    let name = |i: u64| units[i as usize]["name"].as_str().unwrap();
    let kind = |u: &serde_json::Value| u["spec"]["kind"].as_str().unwrap().to_string();
    let published = stderr
        .lines()
        .position(|l| l.ends_with("] published"))
        .expect("a published line");
    let mut released = 0;
    for (i, u) in units.iter().enumerate() {
        if !["tiling", "field", "orient", "aligned", "m3c2"].contains(&kind(u).as_str()) {
            continue;
        }
        let me = u["name"].as_str().unwrap();
        let Some(gone) = at(me, "released") else {
            panic!("unit {me} not released during the run:\n{stderr}");
        };
        assert!(gone < published, "{me} released only when publishing");
        released += 1;
        for r in units.iter().filter(|r| {
            r["deps"]
                .as_array()
                .unwrap()
                .iter()
                .any(|d| d.as_u64() == Some(i as u64))
        }) {
            let reader = r["name"].as_str().unwrap();
            assert!(
                at(reader, "committed").unwrap() < gone,
                "{me} released before its reader {reader} was done"
            );
        }
    }
    assert!(released > 4, "{released} units released");
    // m3c2.laz begins once the pair's volumes are done and every tile is gone.
    let points = units.iter().find(|u| kind(u) == "points").unwrap();
    let starts = at(points["name"].as_str().unwrap(), "begins").unwrap();
    for (i, u) in units.iter().enumerate() {
        match kind(u).as_str() {
            "tiling" => assert!(at(name(i as u64), "released").unwrap() < starts),
            "volumes" => assert!(at(name(i as u64), "committed").unwrap() < starts),
            _ => {}
        }
    }
    assert!(
        points["after"].as_array().is_some_and(|a| !a.is_empty()),
        "the points unit is ordered after the volumes"
    );
    // The timeline changed nothing: the outputs are a run's that keeps its units.
    let kept = tmp.path().join("kept");
    compare(&before, &after, &kept, &[ARGS, &["--keep-units"]].concat());
    assert_same_outputs(&kept, &dir);
}

#[test]
fn a_resumed_run_takes_the_spacing_its_store_measured() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 100_000);
    let dir = tmp.path().join("run");
    compare(&before, &after, &dir, ARGS);
    let cache = dir.join(".talus/cache");
    let entries = || -> Vec<std::path::PathBuf> {
        let mut v: Vec<_> = std::fs::read_dir(&cache)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| {
                p.file_name()
                    .unwrap()
                    .to_string_lossy()
                    .starts_with("spacing-")
            })
            .collect();
        v.sort();
        v
    };
    let [entry] = entries().try_into().expect("one spacing entry after a run");
    let read = |p: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap()
    };
    let planned = || read(&dir.join(".talus/plan.json"))["spacing"].clone();
    let measured = planned();
    assert_eq!(read(&entry)["spacing"], measured);
    let resume = |extra: &[&str]| {
        compare(
            &before,
            &after,
            &dir,
            &[ARGS, &["--resume"], extra].concat(),
        )
    };
    let tamper = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut e = read(&entry);
        edit(&mut e);
        std::fs::write(&entry, serde_json::to_vec(&e).unwrap()).unwrap();
    };
    // Taken as it is.
    tamper(&|e| e["spacing"]["measured_points"] = 12345.into());
    resume(&[]);
    assert_eq!(planned()["measured_points"], 12345);
    // Another version of the measurement, garbage: measured again (and cached again).
    tamper(&|e| e["method"] = 999.into());
    resume(&[]);
    assert_eq!(planned(), measured);
    assert_eq!(read(&entry)["spacing"], measured);
    std::fs::write(&entry, b"{ not json").unwrap();
    resume(&[]);
    assert_eq!(planned(), measured);
    // Another class filter is another entry.
    resume(&["--classes", "all"]);
    assert_eq!(entries().len(), 2);
}

/// A record that lacks a field is damaged, never read as a default (ARCHITECTURE.md, the unit
/// contract): the unit that reads it — here the outputs unit, reading the timing of a tiling it
/// depends on only through the M3C2 units — names the record, the executor computes that unit
/// again and then the reader, and the outputs are those of an undamaged run. The timing lies
/// beside the meta, not in it: a meta field named `seconds` is the stage's own.
#[test]
fn a_damaged_record_is_computed_again_not_read_as_a_default() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 20_000);
    let keep = [ARGS, &["--keep-units"]].concat();
    let dir = tmp.path().join("run");
    compare(&before, &after, &dir, &keep);
    let reference = tmp.path().join("reference");
    compare(&before, &after, &reference, &keep);
    let units = dir.join(".talus/units");
    let tiling = std::fs::read_dir(units.join("tiling"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .min()
        .unwrap();
    let path = tiling.join("record.json");
    let mut record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert!(record["timing"]["seconds"].is_number(), "{record}");
    assert!(record["meta"].get("seconds").is_none(), "{record}");
    record.as_object_mut().unwrap().remove("timing");
    std::fs::write(&path, serde_json::to_vec(&record).unwrap()).unwrap();
    // The outputs unit lost: it is computed again, and reads every timing.
    std::fs::remove_dir_all(units.join("outputs")).unwrap();
    let o = run_compare(
        &before,
        &after,
        &dir,
        &[ARGS, &["--keep-units", "--resume"]].concat(),
    );
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{said}");
    assert!(
        said.contains("record.json: damaged") && said.contains("its record has no timing"),
        "{said}"
    );
    let fixed: serde_json::Value = serde_json::from_slice(
        &std::fs::read(
            std::fs::read_dir(units.join("tiling"))
                .unwrap()
                .map(|e| e.unwrap().path())
                .min()
                .unwrap()
                .join("record.json"),
        )
        .unwrap(),
    )
    .unwrap();
    assert!(fixed["timing"]["seconds"].is_number(), "{fixed}");
    assert_same_outputs(&reference, &dir);
}
