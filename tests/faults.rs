//! Faults of the work area (SPEC.md §2, §3): damaged tile or result files are found by their
//! checksums and rebuilt; an unwritable or full work directory stops the run with exit code 2
//! naming the path, leaves the finished units intact, and the run resumes once the cause is gone.
//!
//! Every case ends by comparing the outputs byte for byte with an undisturbed run of the same
//! scene and parameters.
//!
//! How the faults are made (the tests run as root, for whom permission bits do not block
//! writes): a file where DIR should be; `chattr +i` (immutable, which blocks root too) on a
//! directory, when the file system supports it (else that case says so and is skipped); and a
//! "disk full" by a symbolic link from the temporary name of the next file talus writes to
//! `/dev/full`, so that the kernel answers the write with ENOSPC exactly there.

mod common;
mod pipeline_common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::run_compare;
use pipeline_common::{
    assert_same_outputs, chunk_mtimes, cliff, compare, done_m3c2_tiles, stage_line,
};
use talus::pipeline::progress::Stage;
use talus::pipeline::{m3c2_pass, tiles, workdir::WorkDir, CompareOptions};

const ARGS: &[&str] = &["--tile-size", "5", "--core-spacing", "0.25"];

/// Flip one byte of a file (the last: inside the compressed payload, so only a checksum can
/// tell).
fn flip_last_byte(path: &Path) {
    let mut b = std::fs::read(path).unwrap();
    let n = b.len();
    b[n - 1] ^= 0x5a;
    std::fs::write(path, b).unwrap();
}

/// `compare ARGS --resume` into `dir`, whatever its outcome.
fn resume(before: &Path, after: &Path, dir: &Path) -> std::process::Output {
    run_compare(before, after, dir, &[ARGS, &["--resume"]].concat())
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn damaged_tile_and_result_files_are_rebuilt() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 50_000);
    let reference = tmp.path().join("reference");
    compare(&before, &after, &reference, ARGS);
    let dir = tmp.path().join("run");
    compare(&before, &after, &dir, ARGS);

    // A flipped byte in a tile of the after epoch: that epoch is cut again; its tiles come out
    // the same, so every M3C2 unit stays valid.
    flip_last_byte(&dir.join(".talus/tiles/after/t_0001_0001.tile"));
    let out = resume(&before, &after, &dir);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stage_line(&out.stderr, "pass 1: tiling"), (50_000, false));
    assert_eq!(
        stage_line(&out.stderr, "pass 2: normals and M3C2"),
        (0, true)
    );
    assert_same_outputs(&reference, &dir);

    // A flipped byte in a result chunk: that tile alone is computed again.
    let times = chunk_mtimes(&dir);
    let damaged = "t_0002_0001.00000.tile";
    flip_last_byte(&dir.join(".talus/m3c2").join(damaged));
    let out = resume(&before, &after, &dir);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stage_line(&out.stderr, "pass 1: tiling"), (0, true));
    let (redone, reused) = stage_line(&out.stderr, "pass 2: normals and M3C2");
    assert!(
        !reused && redone > 0 && redone < 100_000,
        "{}",
        stderr(&out)
    );
    let now = chunk_mtimes(&dir);
    for (name, t) in &times {
        if name != damaged {
            assert_eq!(now.get(name), Some(t), "{name} was computed again");
        }
    }
    assert_same_outputs(&reference, &dir);
}

/// Damage found by pass 2 itself (a tile spoiled after pass 1 checked it): the split of that
/// epoch is redone and the pass goes on, with the results of an undamaged run.
#[test]
fn pass_2_redoes_a_split_it_finds_damaged() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 30_000);
    let run_pass_2 = |out: &Path, damage: bool| -> PathBuf {
        let opts = CompareOptions {
            before: before.clone(),
            after: after.clone(),
            out: out.to_path_buf(),
            tile_size: Some(5.0),
            ..CompareOptions::default()
        };
        let user = talus::params::UserParams {
            core_spacing: Some(0.25),
            ..Default::default()
        };
        let bi = talus::io::open(&before).unwrap().info().clone();
        let ai = talus::io::open(&after).unwrap().info().clone();
        let spacing = talus::sampling::measure(&before).unwrap();
        let params = talus::params::Params::resolve(&user, spacing.effective_spacing).unwrap();
        let layout = tiles::Layout::plan(&bi, &ai, None, &params, opts.tile_size).unwrap();
        let mut wd = WorkDir::prepare(out, "test", false, false).unwrap();
        let quiet = Stage::log_only("pass 1", "points");
        let tiled = tiles::tile_epochs(&mut wd, &layout, &opts, &params, &quiet).unwrap();
        if damage {
            flip_last_byte(&tiled.before.join("t_0003_0002.tile"));
        }
        let r = m3c2_pass::run(&mut wd, &layout, &tiled, &params, None, &quiet).unwrap();
        assert!(!r.reused);
        r.dir
    };
    let clean = run_pass_2(&tmp.path().join("clean"), false);
    let damaged = run_pass_2(&tmp.path().join("damaged"), true);
    let mut names: Vec<_> = std::fs::read_dir(&clean)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    assert!(names.len() > 10);
    for n in names {
        assert!(
            std::fs::read(clean.join(&n)).unwrap() == std::fs::read(damaged.join(&n)).unwrap(),
            "{n:?} differs after the split was redone"
        );
    }
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
        eprintln!("chattr +i is not available here: the unwritable-directory cases are not tested");
        return;
    };
    let out = resume(&before, &after, &dir);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(dir.to_str().unwrap()),
        "{}",
        stderr(&out)
    );
    drop(guard);

    // The result directory of pass 2 cannot be written, after pass 1 is done.
    std::fs::create_dir_all(dir.join(".talus/m3c2")).unwrap();
    let m3c2 = dir.join(".talus/m3c2");
    let guard = Immutable::set(&m3c2).expect("chattr worked a moment ago");
    let out = resume(&before, &after, &dir);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(m3c2.to_str().unwrap()),
        "{}",
        stderr(&out)
    );
    assert!(!dir.join("m3c2.laz").exists());
    drop(guard);
    let out = resume(&before, &after, &dir);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stage_line(&out.stderr, "pass 1: tiling"), (0, true));
    assert_same_outputs(&reference, &dir);
}

#[test]
fn a_full_disk_stops_the_run_cleanly_and_resume_finishes_it() {
    let full = Path::new("/dev/full");
    if !full.exists() {
        eprintln!("no /dev/full here: the disk-full cases are not tested");
        return;
    }
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 40_000);
    let reference = tmp.path().join("reference");
    compare(&before, &after, &reference, ARGS);

    // The disk fills up in the middle of pass 2, at the first chunk of tile (1, 1).
    let dir = tmp.path().join("run");
    let m3c2 = dir.join(".talus/m3c2");
    std::fs::create_dir_all(&m3c2).unwrap();
    let tmp_name = m3c2.join("t_0001_0001.00000.tile.tmp");
    std::os::unix::fs::symlink(full, &tmp_name).unwrap();
    let out = resume(&before, &after, &dir);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    let msg = stderr(&out);
    assert!(msg.contains(tmp_name.to_str().unwrap()), "{msg}");
    assert!(msg.contains("No space left on device"), "{msg}");
    assert!(!dir.join("m3c2.laz").exists());
    // The tiles done before the failure are recorded, with intact files.
    let done = done_m3c2_tiles(&dir);
    assert!(
        !done.is_empty() && !done.contains(&"t_0001_0001".to_string()),
        "{done:?}"
    );
    let times = chunk_mtimes(&dir);
    // Space is free again (talus removed its temporary, here the link).
    assert!(std::fs::symlink_metadata(&tmp_name).is_err());
    let out = resume(&before, &after, &dir);
    assert!(out.status.success(), "{}", stderr(&out));
    let now = chunk_mtimes(&dir);
    for tile in &done {
        for (name, t) in times
            .iter()
            .filter(|(n, _)| n.starts_with(&format!("{tile}.")))
        {
            assert_eq!(now.get(name), Some(t), "{name} was computed again");
        }
    }
    assert_same_outputs(&reference, &dir);

    // The disk is full when the manifest is saved: the old manifest stays as it was.
    let manifest = dir.join(".talus/manifest.json");
    let saved = std::fs::read(&manifest).unwrap();
    let bytes = std::fs::read(&before).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(&before, &bytes).unwrap(); // new mtime: the before tiles must be redone
    let link = dir.join(".talus/manifest.json.tmp");
    std::os::unix::fs::symlink(full, &link).unwrap();
    let out = resume(&before, &after, &dir);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains(link.to_str().unwrap()),
        "{}",
        stderr(&out)
    );
    assert_eq!(std::fs::read(&manifest).unwrap(), saved);
    let out = resume(&before, &after, &dir);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_same_outputs(&reference, &dir);
}
