//! Tests of units: commit, done, verify, invalidate, gc, and concurrent commits of one unit by
//! threads and by processes. Child processes are this test binary run again with
//! [`CHILD_ROLE`] set, selecting what [`child_role`] does.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::{Arc, Barrier};
use std::time::{Duration, Instant};

use super::*;

pub(super) const CHILD_ROLE: &str = "TALUS_STORE_CHILD_ROLE";
pub(super) const CHILD_DIR: &str = "TALUS_STORE_CHILD_DIR";

pub(super) fn unit(kind: &str, name: &str) -> UnitRef {
    UnitRef::new(kind, name).unwrap()
}

pub(super) fn store() -> (tempfile::TempDir, Store) {
    let tmp = tempfile::tempdir().unwrap();
    let s = Store::open(&tmp.path().join("out"), true).unwrap();
    (tmp, s)
}

/// Write `unit` with two files of deterministic content (one noted with its CRC, one read back).
pub(super) fn write_unit(s: &Store, u: &UnitRef) -> UnitWriter {
    let mut w = s.begin(u).unwrap();
    let a = format!("points of {u}").repeat(1000);
    std::fs::write(w.path("a.bin").unwrap(), &a).unwrap();
    w.add("a.bin", crc32fast::hash(a.as_bytes()), a.len() as u64);
    std::fs::write(w.path("sub/b.txt").unwrap(), b"second file").unwrap();
    w.add_file("sub/b.txt").unwrap();
    w
}

pub(super) fn tmp_entries(s: &Store) -> Vec<String> {
    fsops::sorted_names(&s.tmp()).unwrap()
}

/// Run this test binary as a child in `role`, on store `dir`.
pub(super) fn spawn_child(role: &str, dir: &Path) -> Child {
    Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "unit_tests::child_role",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_ROLE, role)
        .env(CHILD_DIR, dir)
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap()
}

/// Wait (at most 30 s) until `path` exists.
pub(super) fn wait_for(path: &Path) {
    let t = Instant::now();
    while !path.exists() {
        assert!(t.elapsed() < Duration::from_secs(30), "{}", path.display());
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Set the modification time of `path` (a file or a directory).
pub(super) fn set_mtime(path: &Path, t: std::time::SystemTime) {
    std::fs::File::open(path).unwrap().set_modified(t).unwrap();
}

/// What a child process does; without [`CHILD_ROLE`] (the normal test run) nothing.
#[test]
fn child_role() {
    let Ok(role) = std::env::var(CHILD_ROLE) else {
        return;
    };
    let dir = PathBuf::from(std::env::var(CHILD_DIR).unwrap());
    let s = Store::open(&dir, true).unwrap();
    let u = unit("m3c2", "pair0-0123456789abcdef");
    match role.as_str() {
        // Commit the shared unit as soon as the parent says go.
        "commit" => {
            let w = write_unit(&s, &u);
            wait_for(&dir.join("go"));
            w.commit(serde_json::json!({"n": 1}), None).unwrap();
        }
        // Start writing, then wait to be killed.
        "hold-writer" => {
            let w = write_unit(&s, &u);
            std::fs::write(dir.join("ready"), b"").unwrap();
            std::thread::sleep(Duration::from_secs(60));
            drop(w);
        }
        // Take the lock, then wait to be killed.
        "hold-lock" => {
            let _lock = s.lock("run1", "talus compare a b --out d").unwrap();
            std::fs::write(dir.join("ready"), b"").unwrap();
            std::thread::sleep(Duration::from_secs(60));
        }
        other => panic!("unknown child role {other}"),
    }
}

#[test]
fn commit_done_verify_invalidate_round_trip() {
    let (_t, s) = store();
    let u = unit("tiling", "survey0-3f2a9c01d4e5b6a7");
    assert!(s.done(&u).is_none());
    let w = write_unit(&s, &u);
    let rec = w.commit(serde_json::json!({"points": 42}), None).unwrap();
    assert_eq!(rec.unit, u);
    let names: Vec<&str> = rec.files.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["a.bin", "sub/b.txt"]);
    assert_eq!(rec.file("sub/b.txt").unwrap().size, 11);
    assert_eq!(rec.meta["points"], 42);
    assert_eq!(s.done(&u), Some(rec.clone()));
    assert!(s.verify(&u, &rec).unwrap());
    let dir = s.unit_dir(&u).unwrap();
    assert!(dir.join(RECORD_FILE).is_file());
    assert!(tmp_entries(&s).is_empty());
    s.invalidate(&u).unwrap();
    assert!(s.done(&u).is_none() && !dir.exists());
    s.invalidate(&u).unwrap();
    assert!(tmp_entries(&s).is_empty());
}

#[test]
fn damage_is_seen_by_done_or_verify() {
    let (_t, s) = store();
    let u = unit("m3c2", "tile_3_4-00ff");
    let rec = write_unit(&s, &u)
        .commit(serde_json::Value::Null, None)
        .unwrap();
    let a = s.unit_dir(&u).unwrap().join("a.bin");
    // One byte flipped, same size: cheap `done` cannot tell, `verify` does.
    let mut bytes = std::fs::read(&a).unwrap();
    bytes[100] ^= 1;
    std::fs::write(&a, &bytes).unwrap();
    assert!(s.done(&u).is_some());
    assert!(!s.verify(&u, &rec).unwrap());
    // Another size.
    bytes.pop();
    std::fs::write(&a, &bytes).unwrap();
    assert!(s.done(&u).is_none());
    // Missing.
    std::fs::remove_file(&a).unwrap();
    assert!(s.done(&u).is_none());
    assert!(!s.verify(&u, &rec).unwrap());
    // A record that does not parse.
    let rpath = s.unit_dir(&u).unwrap().join(RECORD_FILE);
    std::fs::write(&rpath, b"{").unwrap();
    assert!(s.done(&u).is_none());
}

#[test]
fn writer_checks_its_files() {
    let (_t, s) = store();
    let u = unit("m3c2", "x");
    let mut w = s.begin(&u).unwrap();
    assert!(matches!(w.path("../escape"), Err(Error::Internal(_))));
    assert!(matches!(w.path(RECORD_FILE), Err(Error::Internal(_))));
    std::fs::write(w.path("a").unwrap(), b"abc").unwrap();
    std::fs::write(w.path("stray").unwrap(), b"abc").unwrap();
    w.add("a", crc32fast::hash(b"abc"), 3);
    assert!(
        matches!(w.commit(serde_json::Value::Null, None), Err(Error::Internal(m)) if m.contains("stray"))
    );
    // The failed writer's directory is gone with it.
    assert!(tmp_entries(&s).is_empty());
    let mut w = s.begin(&u).unwrap();
    std::fs::write(w.path("a").unwrap(), b"abc").unwrap();
    w.add("a", 0, 4);
    assert!(w.commit(serde_json::Value::Null, None).is_err());
    assert!(s.done(&u).is_none());
    // Dropping an uncommitted writer deletes its directory.
    drop(write_unit(&s, &u));
    assert!(tmp_entries(&s).is_empty());
}

#[test]
fn two_threads_commit_one_unit() {
    let (_t, s) = store();
    let u = unit("m3c2", "pair0-0123456789abcdef");
    let barrier = Arc::new(Barrier::new(2));
    let records: Vec<Record> = std::thread::scope(|sc| {
        let hs: Vec<_> = (0..2)
            .map(|_| {
                let (s, u, b) = (&s, &u, barrier.clone());
                sc.spawn(move || {
                    let w = write_unit(s, u);
                    b.wait();
                    w.commit(serde_json::json!({"n": 1}), None).unwrap()
                })
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(records[0].files, records[1].files);
    assert_eq!(
        fsops::sorted_names(&s.units().join("m3c2")).unwrap().len(),
        1
    );
    let kept = s.done(&u).unwrap();
    assert!(records.contains(&kept));
    assert!(s.verify(&u, &kept).unwrap());
    assert!(tmp_entries(&s).is_empty());
}

#[test]
fn two_processes_commit_one_unit() {
    let (_t, s) = store();
    let mut children: Vec<Child> = (0..2).map(|_| spawn_child("commit", s.dir())).collect();
    // Both children have written their unit (two writer directories) before the go.
    let t = Instant::now();
    while tmp_entries(&s).len() < 2 {
        assert!(t.elapsed() < Duration::from_secs(30));
        std::thread::sleep(Duration::from_millis(5));
    }
    std::fs::write(s.dir().join("go"), b"").unwrap();
    for c in &mut children {
        assert!(c.wait().unwrap().success());
    }
    let u = unit("m3c2", "pair0-0123456789abcdef");
    assert_eq!(
        fsops::sorted_names(&s.units().join("m3c2")).unwrap().len(),
        1
    );
    let rec = s.done(&u).unwrap();
    assert!(s.verify(&u, &rec).unwrap());
    assert!(tmp_entries(&s).is_empty());
}

#[test]
fn a_killed_writer_is_never_done_and_gc_clears_it() {
    let (_t, s) = store();
    let mut child = spawn_child("hold-writer", s.dir());
    wait_for(&s.dir().join("ready"));
    child.kill().unwrap();
    child.wait().unwrap();
    let u = unit("m3c2", "pair0-0123456789abcdef");
    assert!(s.done(&u).is_none());
    let left = tmp_entries(&s);
    assert_eq!(left.len(), 1, "{left:?}");
    // A writer of this (live) process is kept, the dead one's directory goes.
    let mine = write_unit(&s, &unit("m3c2", "mine"));
    let report = s.gc(&HashSet::new()).unwrap();
    assert_eq!(report.tmp, left);
    assert!(report.bytes > 0);
    assert_eq!(tmp_entries(&s).len(), 1);
    mine.commit(serde_json::Value::Null, None).unwrap();
    assert!(tmp_entries(&s).is_empty());
}

#[test]
fn gc_removes_units_not_kept_and_old_foreign_tmp() {
    let (_t, s) = store();
    let keep_u = unit("tiling", "survey0-1");
    let old_u = unit("tiling", "survey0-2");
    write_unit(&s, &keep_u)
        .commit(serde_json::Value::Null, None)
        .unwrap();
    write_unit(&s, &old_u)
        .commit(serde_json::Value::Null, None)
        .unwrap();
    // Left by a writer on another host: kept while recent, removed after an idle hour.
    let foreign = s.tmp().join("unit.x.y~elsewhere~123~456~0~0");
    std::fs::create_dir(&foreign).unwrap();
    std::fs::write(foreign.join("f"), b"12345").unwrap();
    let keep: HashSet<UnitRef> = [keep_u.clone()].into();
    let report = s.gc(&keep).unwrap();
    assert_eq!(report.units, vec![old_u.clone()]);
    assert!(report.tmp.is_empty());
    assert!(s.done(&keep_u).is_some() && s.done(&old_u).is_none());
    let hour_ago = std::time::SystemTime::now() - Duration::from_secs(3700);
    for p in [foreign.join("f"), foreign.clone()] {
        set_mtime(&p, hour_ago);
    }
    let report = s.gc(&keep).unwrap();
    assert_eq!(
        report.tmp,
        vec!["unit.x.y~elsewhere~123~456~0~0".to_string()]
    );
    assert_eq!(report.bytes, 5);
    assert!(tmp_entries(&s).is_empty());
    assert!(s.done(&keep_u).is_some());
}

#[test]
fn open_refuses_a_file_and_a_missing_store() {
    let t = tempfile::tempdir().unwrap();
    let file = t.path().join("f");
    std::fs::write(&file, b"").unwrap();
    let e = Store::open(&file, true).unwrap_err();
    assert!(
        matches!(&e, Error::Output { path, .. } if path == &file),
        "{e}"
    );
    let missing = t.path().join("none");
    assert!(matches!(
        Store::open(&missing, false),
        Err(Error::Input { .. })
    ));
    let s = Store::open(&missing, true).unwrap();
    assert_eq!(s.work(), missing.join(".talus"));
    for sub in ["units", "tmp", "claims", "cache"] {
        assert!(s.work().join(sub).is_dir());
    }
    Store::open(&missing, false).unwrap();
}
