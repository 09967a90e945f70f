//! Faults of the work area (SPEC.md §2, §3): a damaged unit file is found when a unit reads it
//! and that unit is rebuilt; an unwritable or full work directory stops the run with exit code 2
//! naming the path, leaves the finished units intact, and the run resumes once the cause is gone.
//!
//! Every case ends by comparing the outputs byte for byte with an undisturbed run of the same
//! scene and parameters.
//!
//! How the faults are made (the tests run as root, for whom permission bits do not block
//! writes): a file where DIR should be; `chattr +i` (immutable, which blocks root too) on a
//! directory, when the file system supports it (else that case says so and is skipped); and a
//! real full disk: DIR on a small tmpfs, grown afterwards with `mount -o remount` (when mounting
//! is not allowed here, that case says so and is skipped).

mod common;
mod pipeline_common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::run_compare;
use pipeline_common::{assert_same_outputs, cliff, compare, stage_line, unit_dir, unit_times};

/// `--keep-units`: the tests damage units' files after a finished run.
const ARGS: &[&str] = &["--tile-size", "5", "--core-spacing", "0.25", "--keep-units"];

/// Flip one byte of a file (the last: inside the compressed payload, so only a checksum can
/// tell).
fn flip_last_byte(path: &Path) {
    let mut b = std::fs::read(path).unwrap();
    let n = b.len();
    b[n - 1] ^= 0x5a;
    std::fs::write(path, b).unwrap();
}

/// `compare ARGS extra --resume` into `dir`, whatever its outcome.
fn resume(before: &Path, after: &Path, dir: &Path, extra: &[&str]) -> std::process::Output {
    run_compare(before, after, dir, &[ARGS, extra, &["--resume"]].concat())
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn damaged_tile_and_result_files_are_rebuilt() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 50_000);
    let dir = tmp.path().join("run");
    compare(&before, &after, &dir, ARGS);

    // A flipped byte in a tile of the after epoch, then a run that needs the tiles again (a
    // changed M3C2 parameter): the M3C2 unit that reads it finds the damage, the after epoch is
    // cut again (same bytes), and the run gives what a clean run with that parameter gives.
    let m3c2 = ["--min-points", "2"];
    let reference = tmp.path().join("reference");
    compare(&before, &after, &reference, &[ARGS, &m3c2].concat());
    flip_last_byte(&unit_dir(&dir, "tiling", "after-").join("t_0001_0001.tile"));
    let out = resume(&before, &after, &dir, &m3c2);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(stderr(&out).contains("damaged"), "{}", stderr(&out));
    assert_eq!(stage_line(&out.stderr, "pass 1: tiling"), (50_000, false));
    assert_same_outputs(&reference, &dir);

    // A flipped byte in a result chunk, then a run that reads the results again (a changed
    // threshold): that tile alone is computed again.
    let events = ["--threshold", "0.05"];
    let reference2 = tmp.path().join("reference2");
    compare(
        &before,
        &after,
        &reference2,
        &[ARGS, &m3c2, &events].concat(),
    );
    let times = unit_times(&dir, "m3c2");
    let damaged = unit_dir(&dir, "m3c2", "pair-t_0002_0001-");
    flip_last_byte(&damaged.join("r_00000.tile"));
    let out = resume(&before, &after, &dir, &[&m3c2[..], &events].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stage_line(&out.stderr, "pass 1: tiling"), (0, true));
    let (redone, reused) = stage_line(&out.stderr, "pass 2: normals and M3C2");
    assert!(
        !reused && redone > 0 && redone < 100_000,
        "{}",
        stderr(&out)
    );
    let now = unit_times(&dir, "m3c2");
    let damaged_name = damaged.file_name().unwrap().to_string_lossy().into_owned();
    for (name, t) in &times {
        if *name != damaged_name {
            assert_eq!(now.get(name), Some(t), "{name} was computed again");
        }
    }
    assert_same_outputs(&reference2, &dir);
}

/// Removes the immutable flag again when the test ends, even by a panic (else the temporary
/// directory cannot be deleted).
struct Immutable(PathBuf);

impl Immutable {
    fn set(p: &Path) -> Option<Immutable> {
        let ok = Command::new("chattr")
            .arg("+i")
            .arg(p)
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| Immutable(p.to_path_buf()))
    }
}

impl Drop for Immutable {
    fn drop(&mut self) {
        let _ = Command::new("chattr").arg("-i").arg(&self.0).status();
    }
}

#[test]
fn an_unwritable_work_directory_stops_the_run_cleanly_and_resume_finishes_it() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 40_000);
    let reference = tmp.path().join("reference");
    compare(&before, &after, &reference, ARGS);

    // DIR is a file.
    let file = tmp.path().join("a-file");
    std::fs::write(&file, b"not a directory").unwrap();
    let out = run_compare(&before, &after, &file, ARGS);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(file.to_str().unwrap()),
        "{}",
        stderr(&out)
    );
    assert_eq!(std::fs::read(&file).unwrap(), b"not a directory");

    // DIR itself cannot be written.
    let dir = tmp.path().join("run");
    std::fs::create_dir(&dir).unwrap();
    let Some(guard) = Immutable::set(&dir) else {
        eprintln!("SKIPPED: chattr +i is not available here: the unwritable-directory cases are not tested");
        return;
    };
    let out = resume(&before, &after, &dir, &[]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(dir.to_str().unwrap()),
        "{}",
        stderr(&out)
    );
    drop(guard);

    // The store's directory of M3C2 units cannot be written, after the tiling is done.
    let m3c2 = dir.join(".talus/units/m3c2");
    std::fs::create_dir_all(&m3c2).unwrap();
    let guard = Immutable::set(&m3c2).expect("chattr worked a moment ago");
    let out = resume(&before, &after, &dir, &[]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(m3c2.to_str().unwrap()),
        "{}",
        stderr(&out)
    );
    assert!(!dir.join("m3c2.laz").exists() && !dir.join("summary.json").exists());
    drop(guard);
    let out = resume(&before, &after, &dir, &[]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stage_line(&out.stderr, "pass 1: tiling"), (0, true));
    assert_same_outputs(&reference, &dir);
}

/// Unmounts the tmpfs when the test ends, even by a panic.
struct Mounted(PathBuf);

impl Mounted {
    fn tmpfs(at: &Path, size: &str) -> Option<Mounted> {
        std::fs::create_dir_all(at).unwrap();
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(at)
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| Mounted(at.to_path_buf()))
    }
    fn grow(&self, size: &str) {
        let ok = Command::new("mount")
            .args(["-o", &format!("remount,size={size}")])
            .arg(&self.0)
            .status()
            .is_ok_and(|s| s.success());
        assert!(ok, "remount of {}", self.0.display());
    }
}

impl Drop for Mounted {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

#[test]
fn a_full_disk_stops_the_run_cleanly_and_resume_finishes_it() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 40_000);
    let reference = tmp.path().join("reference");
    compare(&before, &after, &reference, ARGS);
    // Room for the tiles (72 tiles with halos, two surveys) and the M3C2 results, not for
    // everything: the whole run (its units kept) takes between 12 and 13 MiB of tmpfs since the
    // results store their core points quantised, so 11 MiB runs out in the volumes.
    let disk = tmp.path().join("disk");
    let Some(mounted) = Mounted::tmpfs(&disk, "11m") else {
        eprintln!("SKIPPED: cannot mount a tmpfs here: the disk-full case is not tested");
        return;
    };
    let dir = disk.join("run");
    let out = run_compare(&before, &after, &dir, ARGS);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let msg = stderr(&out);
    assert!(msg.contains(dir.to_str().unwrap()), "{msg}");
    assert!(msg.contains("No space left on device"), "{msg}");
    assert_eq!(
        msg.lines().filter(|l| l.contains("error")).count(),
        1,
        "{msg}"
    );
    assert!(!dir.join("m3c2.laz").exists() && !dir.join("summary.json").exists());
    // What finished before the disk filled up is kept, and not computed again.
    let done: Vec<_> = ["tiling", "m3c2"]
        .iter()
        .flat_map(|k| unit_times(&dir, k).into_iter().map(move |u| (*k, u)))
        .collect();
    assert!(
        !done.is_empty(),
        "nothing finished before the disk was full: {msg}"
    );
    mounted.grow("200m");
    let out = run_compare(&before, &after, &dir, &[ARGS, &["--resume"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    for (kind, (name, t)) in &done {
        assert_eq!(
            unit_times(&dir, kind).get(name),
            Some(t),
            "{kind} unit {name} was computed again"
        );
    }
    assert_same_outputs(&reference, &dir);
}
