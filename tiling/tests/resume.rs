//! Resume after SIGKILL: a child process writes units (tile file, then manifest entry) in a loop
//! and is killed with SIGKILL at an arbitrary moment. The manifest left behind must load, every
//! unit it lists must have an intact file with the recorded checksum, and a resumed run must skip
//! exactly those units and end with the same files as an uninterrupted run.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};
use talus_tiling::manifest::file_checksum;
use talus_tiling::{read_tile, write_tile, Fnv64, Manifest, TileColumns, UnitEntry};

const UNITS: u32 = 200;
const KEY: &str = "resume-test-key";

fn unit_columns(i: u32) -> TileColumns {
    let n = 2000 + i as usize;
    let f = f64::from(i);
    TileColumns {
        x: (0..n).map(|k| f + k as f64 * 0.5).collect(),
        y: (0..n).map(|k| f * 2.0 - k as f64 * 0.25).collect(),
        z: (0..n).map(|k| (k as f64 * 0.1 + f).sin()).collect(),
        extra: vec![],
    }
}

fn inputs_hash(i: u32) -> String {
    Fnv64::new().write_str("unit").write_u64(u64::from(i)).hex()
}

/// The work loop shared by the child and the resumed run; returns how many units it skipped.
fn run_units(dir: &Path) -> u32 {
    let mpath = dir.join("manifest.json");
    let mut m = Manifest::open(&mpath, KEY).unwrap();
    let mut skipped = 0;
    for i in 0..UNITS {
        let unit = format!("u{i:04}");
        let h = inputs_hash(i);
        if m.is_done(&unit, &h) {
            skipped += 1;
            continue;
        }
        let file = format!("{unit}.tile");
        write_tile(&dir.join(&file), &unit_columns(i)).unwrap();
        let checksum = file_checksum(&dir.join(&file)).unwrap();
        m.record(
            unit,
            UnitEntry {
                file,
                checksum,
                inputs_hash: h,
            },
        );
        m.save(&mpath).unwrap();
    }
    skipped
}

/// Entry point of the child process (does nothing in a normal test run).
#[test]
fn child_worker() {
    if let Ok(dir) = std::env::var("TALUS_TILING_RESUME_CHILD") {
        run_units(Path::new(&dir));
    }
}

#[test]
fn sigkill_then_resume_gives_the_uninterrupted_result() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_worker", "--test-threads", "1"])
        .env("TALUS_TILING_RESUME_CHILD", dir.path())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Kill once a few units are recorded (poll; give up waiting after a generous bound).
    let mpath = dir.path().join("manifest.json");
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(120) {
        if Manifest::load(&mpath).is_ok_and(|m| m.units.len() >= 5) {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL on Unix
    child.wait().unwrap();

    // What the killed run left is consistent.
    let m = Manifest::load(&mpath).unwrap();
    assert!(m.units.len() >= 5);
    for entry in m.units.values() {
        let path = dir.path().join(&entry.file);
        assert_eq!(file_checksum(&path).unwrap(), entry.checksum);
        read_tile(&path).unwrap();
    }
    let recorded = m.units.len() as u32;
    assert!(recorded < UNITS, "the child finished before it was killed");

    // Resume skips exactly what was recorded and completes the rest.
    let skipped = run_units(dir.path());
    assert_eq!(skipped, recorded);
    let m = Manifest::load(&mpath).unwrap();
    assert_eq!(m.units.len() as u32, UNITS);

    // Same files as an uninterrupted run.
    let clean = tempfile::tempdir().unwrap();
    assert_eq!(run_units(clean.path()), 0);
    for i in 0..UNITS {
        let f = format!("u{i:04}.tile");
        let a = std::fs::read(dir.path().join(&f)).unwrap();
        let b = std::fs::read(clean.path().join(&f)).unwrap();
        assert!(a == b, "{f} differs after resume");
    }
    assert_eq!(
        Manifest::load(&mpath).unwrap(),
        Manifest::load(&clean.path().join("manifest.json")).unwrap()
    );
}
