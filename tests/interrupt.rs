//! SIGINT and SIGTERM through the binary (SPEC.md §2, src/interrupt.rs): a run signalled while
//! it computes stops at the next safe point with exit code 130 and "interrupted; resume with
//! --resume", publishes nothing, keeps its finished units, and `--resume` then gives the bytes
//! of an uninterrupted run without computing those units again.

mod common;
mod pipeline_common;

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use pipeline_common::{assert_not_redone, assert_same_outputs, compare, spawn_compare, unit_times};

/// Small tiles, so that pass 2 has many units to be interrupted between.
const ARGS: &[&str] = &["--tile-size", "5", "--core-spacing", "0.25"];

/// Run compare, send `signal` once its first M3C2 unit is done, and check how it stopped.
fn interrupted_then_resumed(signal: libc::c_int, before: &Path, after: &Path, reference: &Path) {
    let dir = reference.with_file_name(format!("signal{signal}"));
    let child = spawn_compare(before, after, &dir, ARGS, Stdio::piped());
    let t = Instant::now();
    while unit_times(&dir, "m3c2").is_empty() {
        assert!(t.elapsed() < Duration::from_secs(120), "no M3C2 unit done");
        std::thread::sleep(Duration::from_millis(5));
    }
    let pid = child.id() as libc::pid_t;
    assert_eq!(unsafe { libc::kill(pid, signal) }, 0);
    let signalled = Instant::now();
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "signal {signal}: {err}");
    assert_eq!(
        err.trim().lines().last(),
        Some("talus: interrupted; resume with --resume"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        signalled.elapsed() < Duration::from_secs(20),
        "took {:?} to stop",
        signalled.elapsed()
    );
    // Nothing published, the finished units kept.
    assert!(!dir.join("summary.json").exists());
    assert!(!dir.join("m3c2.laz").exists());
    let finished = unit_times(&dir, "m3c2");
    assert!(!finished.is_empty());
    let stages = |e: &str| e.lines().filter(|l| l.contains(" peak ")).count();
    assert!(stages(&err) < 4, "the run was not cut short: {err}");

    compare(before, after, &dir, &[ARGS, &["--resume"]].concat());
    assert_same_outputs(reference, &dir);
    assert_not_redone(&finished, &unit_times(&dir, "m3c2"));
}

#[test]
fn sigint_and_sigterm_stop_with_130_and_resume_gives_the_uninterrupted_result() {
    let tmp = common::tempdir();
    let (before, after, reference) =
        pipeline_common::cliff_and_reference(tmp.path(), 100_000, ARGS);
    interrupted_then_resumed(libc::SIGINT, &before, &after, &reference);
    interrupted_then_resumed(libc::SIGTERM, &before, &after, &reference);
}
