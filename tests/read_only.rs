//! Reading a result needs no write access (issue 44, item 2): `talus status` on a finished
//! result on a read-only mount, with only `.talus/` read-only, and on a full disk; a publish cut
//! short there is left as it is, and said so, until a command that can write finishes it.
//!
//! The mounts are made in a mount namespace of their own (`unshare --map-root-user --mount`:
//! no privilege needed where user namespaces are allowed, and nothing outlives the command),
//! around the one `talus` command under test.

mod common;

use std::path::{Path, PathBuf};

use std::process::{Command, Output};

use common::{Rng, OFFSET};
use talus::io::Point3;

fn plane(seed: u64, n: usize) -> Vec<Point3> {
    let mut r = Rng::new(seed);
    (0..n)
        .map(|_| {
            [
                OFFSET[0] + r.uniform() * 10.0,
                OFFSET[1] + r.uniform() * 10.0,
                OFFSET[2] + 0.002 * r.normal(),
            ]
        })
        .collect()
}

/// A finished compare in `root/D`.
fn finished(root: &Path) -> PathBuf {
    common::write_cloud(&root.join("a.las"), &plane(1, 2000));
    common::write_cloud(&root.join("b.las"), &plane(2, 2000));
    let d = root.join("D");
    let o = common::run_compare(&root.join("a.las"), &root.join("b.las"), &d, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    d
}

/// Run the shell `script` in a new user and mount namespace; `$TALUS` is the binary.
fn in_namespace(script: &str) -> Output {
    Command::new("unshare")
        .args(["--map-root-user", "--mount", "sh", "-ec", script])
        .env("TALUS", env!("CARGO_BIN_EXE_talus"))
        .output()
        .expect("unshare runs (util-linux)")
}

fn text(o: &Output) -> String {
    format!(
        "exit {:?}\nstdout: {}\nstderr: {}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Status ran well and found the plan's whole set published.
fn published(o: &Output) {
    assert_eq!(o.status.code(), Some(0), "{}", text(o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("published (this plan's)"),
        "{}",
        text(o)
    );
}

/// `talus status` of a finished result, read-only: the whole DIR, only its `.talus`.
#[test]
fn status_reads_a_result_on_a_read_only_mount() {
    let tmp = common::tempdir();
    let d = finished(tmp.path());
    for target in [d.clone(), d.join(".talus")] {
        let t = target.display();
        let o = in_namespace(&format!(
            "mount --bind {t} {t}; mount -o remount,bind,ro {t}; \
             if touch {t}/x 2>/dev/null; then echo WRITABLE; exit 9; fi; \
             \"$TALUS\" status {}",
            d.display()
        ));
        published(&o);
    }
}

/// `talus status` of a finished result on a full disk.
#[test]
fn status_reads_a_result_on_a_full_disk() {
    let tmp = common::tempdir();
    let d = finished(tmp.path());
    let mnt = tmp.path().join("mnt");
    std::fs::create_dir(&mnt).unwrap();
    let o = in_namespace(&format!(
        "mount -t tmpfs -o size=8m tmpfs {m}; cp -a {d} {m}/D; \
         dd if=/dev/zero of={m}/fill bs=64k 2>/dev/null || true; \
         if echo x > {m}/D/probe 2>/dev/null; then echo NOT-FULL; exit 9; fi; \
         \"$TALUS\" status {m}/D",
        m = mnt.display(),
        d = d.display()
    ));
    published(&o);
}

/// A publish cut short (its journal left, the marker gone) on a read-only mount: status shows
/// what is there and says the publish could not be finished and why, touching nothing; where
/// DIR can be written, status finishes it.
#[test]
fn status_says_when_it_cannot_finish_an_interrupted_publish() {
    let tmp = common::tempdir();
    let d = finished(tmp.path());
    let journal = common::publish_journal(&d, false);
    std::fs::write(
        d.join(".talus/publishing"),
        serde_json::to_vec(&journal).unwrap(),
    )
    .unwrap();
    std::fs::remove_file(d.join("summary.json")).unwrap();
    let t = d.display();
    let o = in_namespace(&format!(
        "mount --bind {t} {t}; mount -o remount,bind,ro {t}; \"$TALUS\" status {t}"
    ));
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("could not be finished here") && out.contains("Read-only file system"),
        "{}",
        text(&o)
    );
    assert!(out.contains("not published"), "{}", text(&o));
    assert!(d.join(".talus/publishing").exists(), "left as it was");
    assert!(!d.join("summary.json").exists(), "left as it was");
    // Writable again: finished.
    published(&common::run(&["status", d.to_str().unwrap()]));
    assert!(!d.join(".talus/publishing").exists());
}
