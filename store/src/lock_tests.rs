//! Tests of the run lock: busy, stale (a killed holder), release on drop, not removing a lock
//! that is no longer ours, the note.

use super::unit_tests::{spawn_child, store, wait_for};
use super::*;

#[test]
fn a_second_lock_is_busy_and_names_the_holder() {
    let (_t, s) = store();
    let lock = s
        .lock("run1", "talus compare a.laz b.laz --out out")
        .unwrap();
    let e = s.lock("run2", "talus compare again").unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(&e, Error::Busy { dir, .. } if dir == s.dir()),
        "{msg}"
    );
    assert_eq!(e.exit_code(), 2);
    assert!(msg.contains(&s.dir().display().to_string()), "{msg}");
    assert!(
        msg.contains(&format!("pid {}", std::process::id())),
        "{msg}"
    );
    assert!(msg.contains("talus compare a.laz b.laz --out out"), "{msg}");
    assert!(msg.contains(".talus/lock"), "{msg}");
    let holder = s.lock_holder().unwrap();
    assert_eq!(holder.run, "run1");
    drop(lock);
    assert!(s.lock_holder().is_none() && !s.work().join("lock").exists());
    let again = s.lock("run2", "x").unwrap();
    again.release().unwrap();
    assert!(s.lock_holder().is_none());
}

#[test]
fn a_killed_holders_lock_is_replaced() {
    let (_t, s) = store();
    let mut child = spawn_child("hold-lock", s.dir());
    wait_for(&s.dir().join("ready"));
    let held = s.lock_holder().unwrap();
    assert_eq!(held.owner.pid, child.id());
    assert!(matches!(s.lock("run2", "x"), Err(Error::Busy { .. })));
    child.kill().unwrap();
    child.wait().unwrap();
    let lock = s.lock("run2", "x").unwrap();
    assert_eq!(s.lock_holder().unwrap().owner.pid, std::process::id());
    assert_eq!(s.lock_holder().unwrap().run, "run2");
    drop(lock);
}

#[test]
fn a_lock_that_is_not_ours_stays() {
    let (_t, s) = store();
    let lock = s.lock("run1", "x").unwrap();
    // Replaced by hand (someone removed ours and another run took it, on another host).
    let other = LockInfo {
        owner: Owner {
            pid: 77,
            host: "elsewhere".into(),
            started: 0,
            pid_start: None,
            renewed: None,
            token: "theirs".into(),
        },
        run: "run9".into(),
        command: "talus compare".into(),
        note: None,
    };
    std::fs::write(s.work().join("lock"), serde_json::to_vec(&other).unwrap()).unwrap();
    drop(lock);
    assert_eq!(s.lock_holder(), Some(other));
    // Another host's lock is never taken over by age.
    assert!(matches!(s.lock("run2", "x"), Err(Error::Busy { .. })));
}
