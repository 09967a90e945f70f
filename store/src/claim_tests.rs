//! Tests of claims: races, take-over of dead and expired claims, release.

use std::sync::{Arc, Barrier};
use std::time::Duration;

use super::unit_tests::{store, unit};
use super::*;

/// Write a claim file by hand, as another process would have left it.
fn plant_claim(s: &Store, run: &str, u: &UnitRef, owner: Owner) -> std::path::PathBuf {
    let dir = s.work().join("claims").join(run).join(&u.kind);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(&u.name);
    let info = ClaimInfo {
        owner,
        label: "planted".into(),
        attempt: None,
    };
    std::fs::write(&path, serde_json::to_vec(&info).unwrap()).unwrap();
    path
}

fn owner(pid: u32, host: &str, started: u64, pid_start: Option<u64>) -> Owner {
    Owner {
        pid,
        host: host.into(),
        started,
        pid_start,
        renewed: None,
        token: format!("planted-{pid}-{host}"),
    }
}

fn dead_pid() -> u32 {
    let mut c = std::process::Command::new("true").spawn().unwrap();
    let pid = c.id();
    c.wait().unwrap();
    pid
}

#[test]
fn racing_claimers_one_wins() {
    let (_t, s) = store();
    let u = unit("m3c2", "tile_0_0-1234");
    let n = 8;
    let barrier = Arc::new(Barrier::new(n));
    let claims: Vec<Option<Claim>> = std::thread::scope(|sc| {
        let hs: Vec<_> = (0..n)
            .map(|i| {
                let (s, u, b) = (&s, &u, barrier.clone());
                sc.spawn(move || {
                    b.wait();
                    s.claim("run1", u, &format!("thread {i}")).unwrap()
                })
            })
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let won: Vec<&Claim> = claims.iter().flatten().collect();
    assert_eq!(won.len(), 1);
    let path = won[0].path().to_path_buf();
    let info = s.claim_holder("run1", &u).unwrap();
    assert_eq!(info.owner.pid, std::process::id());
    assert!(info.label.starts_with("thread "));
    drop(claims);
    assert!(!path.exists());
    // Free again, and the claim of another run is independent.
    let a = s.claim("run1", &u, "again").unwrap().unwrap();
    let b = s.claim("run2", &u, "other run").unwrap();
    assert!(b.is_some());
    drop(a);
    assert!(!path.exists());
}

#[test]
fn a_dead_claimer_is_taken_over_a_live_one_is_not() {
    let (_t, s) = store();
    let u = unit("m3c2", "tile_0_1-1234");
    let me = process::host();
    plant_claim(
        &s,
        "r",
        &u,
        owner(dead_pid(), me, process::now_secs(), None),
    );
    let c = s
        .claim("r", &u, "taker")
        .unwrap()
        .expect("dead pid taken over");
    assert_eq!(s.claim_holder("r", &u).unwrap().label, "taker");
    drop(c);

    // A live process of this host: a sleeping child, with its real start time.
    let mut child = std::process::Command::new("sleep")
        .arg("30")
        .spawn()
        .unwrap();
    let pid = child.id();
    plant_claim(
        &s,
        "r",
        &u,
        owner(pid, me, process::now_secs(), process::pid_start(pid)),
    );
    assert!(s.claim("r", &u, "taker").unwrap().is_none());
    // The same pid with another start time is a process that has gone (its pid reused).
    let reused = process::pid_start(pid).map(|t| t + 1);
    plant_claim(&s, "r", &u, owner(pid, me, process::now_secs(), reused));
    assert!(s.claim("r", &u, "taker").unwrap().is_some());
    child.kill().unwrap();
    child.wait().unwrap();
    // No stale files left behind in tmp/.
    assert!(super::unit_tests::tmp_entries(&s).is_empty());
}

#[test]
fn a_claim_from_another_host_expires_after_the_lease() {
    let (_t, s) = store();
    let u = unit("m3c2", "tile_2_2-1234");
    let now = process::now_secs();
    plant_claim(&s, "r", &u, owner(1, "elsewhere", now - 60, None));
    assert!(s.claim("r", &u, "x").unwrap().is_none());
    plant_claim(&s, "r", &u, owner(1, "elsewhere", now - 7 * 3600, None));
    assert!(s.claim("r", &u, "x").unwrap().is_some());
    // A shorter lease; a renewal counts like a fresh start (a claim file renewed elsewhere).
    let s = s.with_lease(Duration::from_secs(30));
    let mut renewed = owner(1, "elsewhere", now - 60, None);
    renewed.renewed = Some(now - 5);
    plant_claim(&s, "r", &u, renewed);
    assert!(s.claim("r", &u, "x").unwrap().is_none(), "renewed");
    // An unparseable claim (being written, or damaged) holds for a minute.
    let path = plant_claim(&s, "r", &u, owner(1, "x", 0, None));
    std::fs::write(&path, b"").unwrap();
    assert!(s.claim("r", &u, "x").unwrap().is_none());
}

#[test]
fn a_claim_taken_over_by_another_is_not_released_by_us() {
    let (_t, s) = store();
    let u = unit("events", "pair0-99");
    let c = s.claim("r", &u, "mine").unwrap().unwrap();
    let path = c.path().to_path_buf();
    plant_claim(
        &s,
        "r",
        &u,
        owner(1, "elsewhere", process::now_secs(), None),
    );
    drop(c);
    assert_eq!(s.claim_holder("r", &u).unwrap().owner.host, "elsewhere");
    assert!(path.exists());
    assert!(matches!(
        s.claim("bad/run", &u, "x"),
        Err(Error::Internal(_))
    ));
}

/// A Slurm task requeued after its node died runs again with the same label and a higher
/// attempt: the claims of its earlier attempt, on a host whose pids it cannot check, are taken
/// over at once; any other claim of another host holds for the lease.
#[test]
fn a_later_attempt_of_a_task_takes_over_its_earlier_attempts_claims() {
    let (_t, s) = store();
    let u = unit("m3c2", "tile_0_0-77");
    let now = process::now_secs();
    let plant = |label: &str, attempt: Option<u32>| {
        let dir = s.work().join("claims").join("r").join(&u.kind);
        std::fs::create_dir_all(&dir).unwrap();
        let info = ClaimInfo {
            owner: owner(1, "node-that-died", now - 5, None),
            label: label.into(),
            attempt,
        };
        std::fs::write(dir.join(&u.name), serde_json::to_vec(&info).unwrap()).unwrap();
    };
    // Not an earlier attempt of ours: another task, the same attempt, a later one, no attempt.
    for (label, attempt) in [
        ("slurm 88_3", Some(0)),
        ("slurm 88_4", Some(1)),
        ("slurm 88_4", Some(2)),
        ("slurm 88_4", None),
    ] {
        plant(label, attempt);
        let c = s.claim_attempt("r", &u, "slurm 88_4", 1).unwrap();
        assert!(c.is_none(), "{label} attempt {attempt:?} holds");
    }
    // Plain claims never take over by label.
    plant("slurm 88_4", Some(0));
    assert!(s.claim("r", &u, "slurm 88_4").unwrap().is_none());
    let c = s.claim_attempt("r", &u, "slurm 88_4", 1).unwrap();
    let c = c.expect("the earlier attempt's claim is taken over");
    let info: ClaimInfo = serde_json::from_slice(&std::fs::read(c.path()).unwrap()).unwrap();
    assert_eq!((info.label.as_str(), info.attempt), ("slurm 88_4", Some(1)));
}

/// A renewal rewrites a claim that is still ours with its new time, and nothing once it is
/// released or taken over by another.
#[test]
fn a_renewal_rewrites_only_a_claim_still_ours() {
    let (_t, s) = store();
    let u = unit("events", "pair0-5");
    let c = s.claim("r", &u, "mine").unwrap().unwrap();
    let mut info: ClaimInfo = serde_json::from_slice(&std::fs::read(c.path()).unwrap()).unwrap();
    info.owner.renewed = Some(info.owner.started + 60);
    let bytes = serde_json::to_vec(&info).unwrap();
    let path = c.path().to_path_buf();
    let token = info.owner.token.clone();
    assert!(owner_file::renew(&path, &s.tmp(), &token, &bytes).unwrap());
    let read: ClaimInfo = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(read, info);
    // Held by its renewed time: another host's view of it is fresh.
    assert!(!read.owner.gone(Some(Duration::from_secs(120))));
    drop(c);
    assert!(!path.exists());
    assert!(!owner_file::renew(&path, &s.tmp(), &token, &bytes).unwrap());
    assert!(!path.exists(), "a released claim is not written again");
    // Taken over by another (planted): not ours, left alone.
    plant_claim(
        &s,
        "r",
        &u,
        owner(1, "elsewhere", process::now_secs(), None),
    );
    assert!(!owner_file::renew(&path, &s.tmp(), &token, &bytes).unwrap());
    assert!(super::unit_tests::tmp_entries(&s).is_empty());
}

/// Claims of tasks known to have ended are dropped, whatever their host; others stay, and a
/// planted link never leads the removal outside DIR.
#[test]
fn claims_of_ended_tasks_are_dropped_and_only_those() {
    let (t, s) = store();
    let now = process::now_secs();
    let plant = |run: &str, u: &UnitRef, label: &str| {
        let dir = s.work().join("claims").join(run).join(&u.kind);
        std::fs::create_dir_all(&dir).unwrap();
        let info = ClaimInfo {
            owner: owner(1, "node-that-died", now, None),
            label: label.into(),
            attempt: Some(0),
        };
        std::fs::write(dir.join(&u.name), serde_json::to_vec(&info).unwrap()).unwrap();
        dir.join(&u.name)
    };
    let a = plant("r1", &unit("m3c2", "tile_0_0-1"), "slurm 90_0");
    let b = plant("r2", &unit("events", "pair0-1"), "slurm 90_3");
    let c = plant("r1", &unit("m3c2", "tile_1_0-1"), "slurm 91_0");
    // A link planted as a kind folder, to claim-like files outside DIR.
    let outside = t.path().join("outside");
    std::fs::create_dir_all(&outside).unwrap();
    let victim = outside.join("tile_2_0-1");
    std::fs::copy(&a, &victim).unwrap();
    std::os::unix::fs::symlink(&outside, s.work().join("claims").join("r1").join("volumes"))
        .unwrap();
    let ended = |i: &ClaimInfo| i.label.starts_with("slurm 90_");
    assert_eq!(s.drop_claims(ended).unwrap(), 2);
    assert!(!a.exists() && !b.exists());
    assert!(c.exists(), "another job's claim stays");
    assert!(victim.exists(), "nothing outside DIR is removed");
}
