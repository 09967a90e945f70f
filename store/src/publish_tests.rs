//! Tests of publishing outputs into DIR and of recovering an interrupted publish.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::publish::fault::{self, Fault};
use super::unit_tests::{store, unit};
use super::*;

/// Talus's outputs by name (the caller's `ours`).
fn ours(name: &str) -> bool {
    matches!(
        name,
        "summary.json" | "m3c2.laz" | "events.csv" | "events.geojson" | "meshes"
    ) || (name.starts_with("meshes/event_") && name.ends_with(".ply"))
}

/// Every file below DIR but `.talus`, with its content.
fn listing(dir: &Path) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    super::hostile_tests::walk(dir, &mut |name, path, m| {
        if !m.is_dir() {
            out.insert(name.to_string(), std::fs::read_to_string(path).unwrap());
        }
    });
    out
}

fn put(dir: &Path, name: &str, text: &str) {
    let p = dir.join(name);
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, text).unwrap();
}

const OLD: &[&str] = &[
    "summary.json",
    "m3c2.laz",
    "events.csv",
    "meshes/event_0001_before.ply",
];
const USER: &[&str] = &["notes.txt", "meshes/mine.ply"];
const NEW: &[&str] = &[
    "m3c2.laz",
    "meshes/event_0002_after.ply",
    "meshes/event_0002_before.ply",
    "summary.json",
];

/// A DIR holding an old output set and the user's files, and a committed unit holding the new
/// set; returns the files to publish (the marker in the middle: publish puts it last).
fn setup() -> (tempfile::TempDir, Store, Vec<(PathBuf, String)>) {
    let (t, s) = store();
    for name in OLD {
        put(s.dir(), name, &format!("old {name}"));
    }
    for name in USER {
        put(s.dir(), name, &format!("user's {name}"));
    }
    let u = unit("outputs", "pair0-abc");
    let mut w = s.begin(&u).unwrap();
    for name in NEW {
        std::fs::write(w.path(name).unwrap(), format!("new {name}")).unwrap();
        w.add_file(name).unwrap();
    }
    w.commit(serde_json::Value::Null, None).unwrap();
    let dir = s.unit_dir(&u).unwrap();
    let files = NEW.iter().map(|n| (dir.join(n), n.to_string())).collect();
    (t, s, files)
}

fn expected(new: &[&str]) -> BTreeMap<String, String> {
    let mut m: BTreeMap<String, String> = new
        .iter()
        .map(|n| (n.to_string(), format!("new {n}")))
        .collect();
    for n in USER {
        m.insert(n.to_string(), format!("user's {n}"));
    }
    m
}

#[test]
fn publish_replaces_the_old_set_and_keeps_the_users_files() {
    let (_t, s, files) = setup();
    s.publish(&files, "summary.json", &ours).unwrap();
    assert_eq!(listing(s.dir()), expected(NEW));
    assert!(!s.work().join("publishing").exists());
    // Hard links to the unit's files: no copy of 100M-point outputs.
    use std::os::unix::fs::MetadataExt;
    let a = std::fs::metadata(s.dir().join("m3c2.laz")).unwrap().ino();
    assert_eq!(std::fs::metadata(&files[0].0).unwrap().ino(), a);
    assert!(super::unit_tests::tmp_entries(&s).is_empty());
    assert_eq!(s.recover(&ours).unwrap(), Recovery::Nothing);

    // A set without meshes: meshes/ stays for the user's file; without it, it goes.
    let few: Vec<_> = files
        .iter()
        .filter(|(_, n)| !n.starts_with("meshes/"))
        .cloned()
        .collect();
    s.publish(&few, "summary.json", &ours).unwrap();
    assert_eq!(listing(s.dir()), expected(&["m3c2.laz", "summary.json"]));
    std::fs::remove_file(s.dir().join("meshes/mine.ply")).unwrap();
    s.publish(&files, "summary.json", &ours).unwrap();
    s.publish(&few, "summary.json", &ours).unwrap();
    assert!(!s.dir().join("meshes").exists());
}

#[test]
fn publish_refuses_before_touching_anything() {
    let (_t, s, files) = setup();
    let before = listing(s.dir());
    let mut missing = files.clone();
    missing.insert(
        1,
        (
            s.dir().join("nowhere.ply"),
            "meshes/event_0003_before.ply".into(),
        ),
    );
    assert!(matches!(
        s.publish(&missing, "summary.json", &ours),
        Err(Error::Output { .. })
    ));
    assert!(matches!(
        s.publish(&files, "view.json", &ours),
        Err(Error::Internal(_))
    ));
    // A new name held by a user file (not ours) is never replaced.
    let mut clash = files.clone();
    clash.push((files[0].0.clone(), "notes.txt".into()));
    let e = s.publish(&clash, "summary.json", &ours).unwrap_err();
    assert!(e.to_string().contains("notes.txt"), "{e}");
    assert_eq!(listing(s.dir()), before);
    assert!(!s.work().join("publishing").exists());
}

#[test]
fn a_failing_publish_leaves_no_outputs() {
    let (_t, s, files) = setup();
    fault::arm(2, Fault::Fail);
    assert!(s.publish(&files, "summary.json", &ours).is_err());
    assert_eq!(listing(s.dir()), expected(&[]));
    assert!(!s.work().join("publishing").exists());
    assert_eq!(s.recover(&ours).unwrap(), Recovery::Nothing);
}

#[test]
fn a_crash_at_any_step_never_mixes_sets_and_recover_finishes_it() {
    for at in 0..NEW.len() {
        let (_t, s, files) = setup();
        fault::arm(at, Fault::Crash);
        assert!(s.publish(&files, "summary.json", &ours).is_err());
        // No old output left, no marker, only new files (the first `at` of them).
        let now = listing(s.dir());
        assert!(!now.contains_key("summary.json"), "crash at {at}: {now:?}");
        let talus: Vec<&String> = now.keys().filter(|n| ours(n)).collect();
        assert_eq!(talus.len(), at, "crash at {at}: {now:?}");
        for n in talus {
            assert!(now[n].starts_with("new "), "crash at {at}: {now:?}");
        }
        assert!(s.work().join("publishing").exists());
        assert_eq!(s.recover(&ours).unwrap(), Recovery::RolledForward);
        assert_eq!(listing(s.dir()), expected(NEW), "crash at {at}");
        assert_eq!(s.recover(&ours).unwrap(), Recovery::Nothing);
    }
}

#[test]
fn recover_undoes_a_publish_whose_sources_are_gone() {
    let (_t, s, files) = setup();
    fault::arm(1, Fault::Crash);
    assert!(s.publish(&files, "summary.json", &ours).is_err());
    s.invalidate(&unit("outputs", "pair0-abc")).unwrap();
    assert_eq!(s.recover(&ours).unwrap(), Recovery::RolledBack);
    assert_eq!(listing(s.dir()), expected(&[]));
    assert!(!s.dir().join("meshes/event_0002_after.ply").exists());
    assert!(!s.work().join("publishing").exists());
}

#[test]
fn recover_finishes_a_journal_left_after_the_old_marker_went() {
    let (_t, s, files) = setup();
    // As a crash in step 2 leaves it: the old marker removed, the rest of the old set not yet.
    std::fs::remove_file(s.dir().join("summary.json")).unwrap();
    let mut ordered: Vec<(PathBuf, String)> = files
        .iter()
        .filter(|(_, n)| n != "summary.json")
        .cloned()
        .collect();
    ordered.extend(files.iter().filter(|(_, n)| n == "summary.json").cloned());
    let journal = serde_json::json!({
        "files": ordered,
        "marker": "summary.json",
        "remove": ["summary.json", "events.csv", "m3c2.laz", "meshes/event_0001_before.ply"],
        "dirs": ["meshes"],
    });
    std::fs::write(
        s.work().join("publishing"),
        serde_json::to_vec(&journal).unwrap(),
    )
    .unwrap();
    assert_eq!(s.recover(&ours).unwrap(), Recovery::RolledForward);
    assert_eq!(listing(s.dir()), expected(NEW));

    std::fs::write(s.work().join("publishing"), b"{damaged").unwrap();
    assert!(matches!(s.recover(&ours), Err(Error::Input { .. })));
}

/// Issue "Trust, second round", item 6: `talus status` and `talus view` finish a publish a
/// crash cut short (they call this), unless a run holds DIR's lock (it finishes it itself).
#[test]
fn a_reading_command_finishes_an_interrupted_publish_unless_a_run_holds_dir() {
    let (_t, s, files) = setup();
    fault::arm(2, Fault::Crash);
    assert!(s.publish(&files, "summary.json", &ours).is_err());
    let lock = s.lock("run", "talus compare …").unwrap();
    assert_eq!(
        s.finish_interrupted_publish("talus status", &ours).unwrap(),
        Recovery::Nothing
    );
    assert!(s.work().join("publishing").exists(), "left to the run");
    lock.release().unwrap();
    assert_eq!(
        s.finish_interrupted_publish("talus status", &ours).unwrap(),
        Recovery::RolledForward
    );
    assert_eq!(listing(s.dir()), expected(NEW));
    assert!(s.lock_holder().is_none(), "the lock is released again");
}

/// Item 2: a published file edited in place (a hard link: the unit's file too) is found by
/// `edited_files`; an untouched one, or one rewritten with the same bytes, is not.
#[test]
fn a_published_file_edited_in_place_is_found() {
    let (_t, s, files) = setup();
    s.publish(&files, "summary.json", &ours).unwrap();
    let u = unit("outputs", "pair0-abc");
    let record = s.done(&u).unwrap();
    assert!(s.edited_files(&u, &record).is_empty());
    let dest = s.dir().join("m3c2.laz");
    let original = std::fs::read(&dest).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(&dest, &original).unwrap();
    assert!(
        s.edited_files(&u, &record).is_empty(),
        "same bytes: not edited"
    );
    let mut bad = original.clone();
    bad[0] ^= 0xff;
    std::fs::write(&dest, &bad).unwrap();
    assert_eq!(s.edited_files(&u, &record), vec!["m3c2.laz".to_string()]);
}

/// Item 7: a damaged journal is refused naming what DIR holds.
#[test]
fn a_damaged_journal_names_the_files() {
    let (_t, s, _files) = setup();
    std::fs::write(s.work().join("publishing"), b"{ not json").unwrap();
    let e = s.recover(&ours).unwrap_err().to_string();
    for name in [
        "summary.json",
        "m3c2.laz",
        "events.csv",
        "meshes",
        "notes.txt",
    ] {
        assert!(e.contains(name), "{name} not named in: {e}");
    }
    assert!(e.contains("--resume"), "{e}");
}
