//! SIGINT and SIGTERM through the binary (SPEC.md §2, src/interrupt.rs): a run signalled while
//! it computes stops at the next safe point with exit code 130 and "interrupted; resume with
//! --resume", publishes nothing, keeps its finished units, and `--resume` then gives the bytes
//! of an uninterrupted run without computing those units again.

mod common;
mod pipeline_common;

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use pipeline_common::{assert_same_outputs, cliff, compare, unit_times};

/// Small tiles, so that pass 2 has many units to be interrupted between.
const ARGS: &[&str] = &["--tile-size", "5", "--core-spacing", "0.25"];

/// Run compare, send `signal` once its first M3C2 unit is done, and check how it stopped.
fn interrupted_then_resumed(signal: libc::c_int, before: &Path, after: &Path, reference: &Path) {
    let dir = reference.with_file_name(format!("signal{signal}"));
    let child = common::talus()
        .args([
            "compare",
            before.to_str().unwrap(),
            after.to_str().unwrap(),
            "--out",
            dir.to_str().unwrap(),
        ])
        .args(ARGS)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("talus starts");
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
    let now = unit_times(&dir, "m3c2");
    for (name, time) in &finished {
        assert_eq!(now.get(name), Some(time), "{name} was computed again");
    }
}

#[test]
fn sigint_and_sigterm_stop_with_130_and_resume_gives_the_uninterrupted_result() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 100_000);
    let reference = tmp.path().join("reference");
    compare(&before, &after, &reference, ARGS);
    interrupted_then_resumed(libc::SIGINT, &before, &after, &reference);
    interrupted_then_resumed(libc::SIGTERM, &before, &after, &reference);
}

/// `talus view` has no unit to finish: the first SIGTERM or SIGINT ends it (the browser tests stop
/// their server so; a server that only noted the signal kept them waiting for ever).
#[test]
fn the_viewer_server_ends_at_the_first_signal() {
    let dir = common::tempdir();
    // The server asks only for a view.json to be there; it is not read before a browser asks.
    std::fs::write(dir.path().join("view.json"), "{}").unwrap();
    for signal in [libc::SIGTERM, libc::SIGINT] {
        let mut child = common::talus()
            .args(["view", dir.path().to_str().unwrap(), "--port", "0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("talus starts");
        // Serving once it printed its address.
        let mut line = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(child.stdout.take().unwrap()),
            &mut line,
        )
        .unwrap();
        assert!(line.contains("http://"), "not serving: {line:?}");
        assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
        let t = Instant::now();
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                assert!(!status.success(), "signal {signal}: {status}");
                break;
            }
            assert!(
                t.elapsed() < Duration::from_secs(10),
                "signal {signal} did not end it"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}
