//! A result folder from someone else (issue 44, item 1): the store's readers of what lies in
//! DIR — the publish journal, unit records, claims, `.talus/` itself — given hostile content,
//! never read, write or remove anything outside DIR, never remove a file of the user's, and
//! never panic. The journal and record readers are run on hundreds of generated journals and
//! records (mutations of valid ones by paths that climb out, absolute paths, links planted in
//! `.talus/` and in DIR, names in `.talus`, user files, garbage and truncated JSON).

use std::collections::BTreeMap;
use std::os::unix::fs::{symlink, MetadataExt};
use std::path::{Path, PathBuf};

use super::unit_tests::{store, unit, write_unit};
use super::*;
use talus_base::rng::SplitMix64;

/// Talus's outputs by name, as a comparison's `ours`.
fn ours(name: &str) -> bool {
    matches!(name, "summary.json" | "m3c2.laz" | "events.csv" | "meshes")
        || (name.starts_with("meshes/event_") && name.ends_with(".ply"))
}

/// Visit every entry below `dir` without following links (DIR's `.talus` left out): its name
/// (`/`-separated), path and metadata; a folder before what it holds.
pub(super) fn walk(dir: &Path, visit: &mut dyn FnMut(&str, &Path, &std::fs::Metadata)) {
    fn go(dir: &Path, rel: &str, visit: &mut dyn FnMut(&str, &Path, &std::fs::Metadata)) {
        for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let name = if rel.is_empty() {
                name
            } else {
                format!("{rel}/{name}")
            };
            if name == ".talus" {
                continue;
            }
            let m = std::fs::symlink_metadata(e.path()).unwrap();
            visit(&name, &e.path(), &m);
            if m.is_dir() {
                go(&e.path(), &name, visit);
            }
        }
    }
    go(dir, "", visit)
}

/// Every entry below `dir` (not following links, `.talus` left out): its kind and content,
/// with the inode of a file (to tell a hard link into the store from a file of the user's).
fn tree(dir: &Path) -> BTreeMap<String, (String, u64)> {
    let mut out = BTreeMap::new();
    walk(dir, &mut |name, path, m| {
        let entry = if m.file_type().is_symlink() {
            let to = std::fs::read_link(path).unwrap();
            (format!("link {}", to.display()), 0)
        } else if m.is_dir() {
            ("dir".into(), 0)
        } else {
            let text = String::from_utf8_lossy(&std::fs::read(path).unwrap()).into();
            (text, m.ino())
        };
        out.insert(name.to_string(), entry);
    });
    out
}

/// The inodes of every file below `.talus/units`.
fn unit_inodes(s: &Store) -> Vec<u64> {
    let mut out = Vec::new();
    walk(&s.units(), &mut |_, _, m| {
        if m.is_file() {
            out.push(m.ino());
        }
    });
    out
}

/// A DIR with an old output set, the user's files and a finished outputs unit, beside a folder
/// `outside` holding a file `secret.txt` and a folder `keep/`; `.talus/units/outputs/planted`
/// is a link to `outside`, DIR's `links` too. Returns the store, the outside folder and the
/// valid journal entries (source relative to `.talus/units`, name).
fn scene() -> (tempfile::TempDir, Store, PathBuf, Vec<(String, String)>) {
    let (t, s) = store();
    let outside = t.path().join("outside");
    std::fs::create_dir_all(outside.join("keep")).unwrap();
    std::fs::write(outside.join("secret.txt"), "not talus's").unwrap();
    std::fs::write(outside.join("keep/events.csv"), "not talus's either").unwrap();
    for (name, text) in [
        ("summary.json", "old summary"),
        ("events.csv", "old events"),
        ("notes.txt", "the user's notes"),
    ] {
        std::fs::write(s.dir().join(name), text).unwrap();
    }
    let u = unit("outputs", "pair0-abc");
    let mut w = s.begin(&u).unwrap();
    for name in ["m3c2.laz", "summary.json", "meshes/event_0001_before.ply"] {
        std::fs::write(w.path(name).unwrap(), format!("new {name}")).unwrap();
        w.add_file(name).unwrap();
    }
    w.commit(serde_json::Value::Null, None).unwrap();
    symlink(&outside, s.units().join("outputs/planted")).unwrap();
    symlink(&outside, s.dir().join("links")).unwrap();
    let files = ["m3c2.laz", "meshes/event_0001_before.ply", "summary.json"]
        .iter()
        .map(|n| (format!("outputs/pair0-abc/{n}"), n.to_string()))
        .collect();
    (t, s, outside, files)
}

/// One hostile value for a journal's source, name, marker, removal or folder.
fn hostile(r: &mut SplitMix64, s: &Store, outside: &Path) -> String {
    let atoms: Vec<String> = vec![
        outside.join("secret.txt").display().to_string(),
        "/etc/hostname".into(),
        "../outside/escape.txt".into(),
        "../../outside/secret.txt".into(),
        "outputs/pair0-abc/../../../../outside/secret.txt".into(),
        "outputs/planted/secret.txt".into(),
        s.units()
            .join("outputs/planted/secret.txt")
            .display()
            .to_string(),
        s.units()
            .join("..")
            .join(super::PLAN_FILE)
            .display()
            .to_string(),
        "outputs/pair0-abc".into(),
        "outputs".into(),
        format!(".talus/{}", super::PLAN_FILE),
        ".talus".into(),
        ".talus/units/outputs/pair0-abc/m3c2.laz".into(),
        "notes.txt".into(),
        "links/events.csv".into(),
        "links/keep/events.csv".into(),
        "meshes/../../outside/secret.txt".into(),
        "a//b".into(),
        String::new(),
        "/".into(),
        ".".into(),
        "..".into(),
        "x\u{0}y".into(),
        "é/ü".into(),
        "m".repeat(5000),
    ];
    atoms[r.below(atoms.len())].clone()
}

/// A journal: the valid one with some of its entries replaced by hostile values, or its JSON
/// text cut or with bytes changed.
fn journal(r: &mut SplitMix64, s: &Store, outside: &Path, files: &[(String, String)]) -> Vec<u8> {
    let mut files: Vec<(String, String)> = files.to_vec();
    let mut marker = "summary.json".to_string();
    let mut remove = vec!["summary.json".to_string(), "events.csv".to_string()];
    let mut dirs = vec!["meshes".to_string()];
    for _ in 0..1 + r.below(3) {
        let h = hostile(r, s, outside);
        match r.below(7) {
            0 | 1 => {
                let i = r.below(files.len());
                files[i].0 = h;
            }
            2 => {
                let i = r.below(files.len());
                files[i].1 = h;
            }
            3 => marker = h,
            4 | 5 => remove.push(h),
            _ => dirs.push(h),
        }
    }
    let j = serde_json::json!({ "files": files, "marker": marker, "remove": remove, "dirs": dirs });
    let mut bytes = serde_json::to_vec(&j).unwrap();
    match r.below(8) {
        0 => bytes.truncate(r.below(bytes.len() + 1)),
        1 => {
            for _ in 0..1 + r.below(4) {
                let i = r.below(bytes.len());
                bytes[i] = r.next_u64() as u8;
            }
        }
        _ => {}
    }
    bytes
}

/// Every command that finds a journal recovers it: whatever a journal says, nothing outside
/// DIR changes, no file of the user's in DIR is removed or replaced, every new file in DIR is
/// a unit's file (a hard link into `.talus/units`), and nothing panics.
#[test]
fn hostile_journals_stay_inside_dir() {
    let mut r = SplitMix64::new(44);
    let mut refused = 0;
    for case in 0..400 {
        let (_t, s, outside, files) = scene();
        let before_out = tree(&outside);
        let before_dir = tree(s.dir());
        let bytes = journal(&mut r, &s, &outside, &files);
        std::fs::write(s.journal_path(), &bytes).unwrap();
        let result = if case % 2 == 0 {
            s.recover(&ours).map(|_| ())
        } else {
            s.finish_interrupted_publish("talus status", &ours)
                .map(|_| ())
        };
        let text = String::from_utf8_lossy(&bytes);
        if let Err(e) = &result {
            refused += 1;
            assert!(
                matches!(e, Error::Input { path, .. } if *path == s.journal_path()),
                "case {case}: {e} for {text}"
            );
            assert!(
                s.journal_path().exists(),
                "case {case}: a refused journal stays"
            );
        }
        assert_eq!(
            tree(&outside),
            before_out,
            "case {case}: outside changed by {text}"
        );
        let inodes = unit_inodes(&s);
        let after_dir = tree(s.dir());
        for (name, (content, ino)) in &after_dir {
            let was = before_dir.get(name);
            if was == Some(&(content.clone(), *ino)) {
                continue;
            }
            assert!(
                *ino != 0 && inodes.contains(ino),
                "case {case}: {name} ({content}) is neither as it was nor a unit's file; {text}"
            );
        }
        for user in ["notes.txt", "links"] {
            assert_eq!(
                after_dir.get(user),
                before_dir.get(user),
                "case {case}: the user's {user}; {text}"
            );
        }
        if result.is_err() {
            assert_eq!(
                after_dir, before_dir,
                "case {case}: refused, yet DIR changed"
            );
        }
    }
    assert!(
        refused > 300,
        "only {refused} of 400 hostile journals refused"
    );
}

/// The issue's reproduction, at the store: a journal hard-linking `/etc/hostname`-like files
/// into DIR, creating one outside through `../` and removing one outside by absolute path is
/// refused, naming the journal, and touches nothing.
#[test]
fn the_issues_journal_is_refused() {
    let (_t, s, outside, _files) = scene();
    let plan = s.plan_path();
    std::fs::write(&plan, "{}").unwrap();
    let j = serde_json::json!({
        "files": [[outside.join("secret.txt"), "stolen.txt"], [plan, "../outside/escape.txt"]],
        "marker": "summary.json",
        "remove": [outside.join("keep/events.csv")],
        "dirs": [],
    });
    std::fs::write(s.journal_path(), serde_json::to_vec(&j).unwrap()).unwrap();
    let before = (tree(&outside), tree(s.dir()));
    let e = s
        .finish_interrupted_publish("talus status", &ours)
        .unwrap_err();
    assert_eq!(e.exit_code(), 2, "{e}");
    let text = e.to_string();
    assert!(
        text.contains("publishing") && text.contains("did not write"),
        "{text}"
    );
    assert_eq!((tree(&outside), tree(s.dir())), before);
    assert!(!s.dir().join("stolen.txt").exists());
}

/// A record: the valid one with hostile file names, sizes that fit files elsewhere, or junk.
fn record(r: &mut SplitMix64, s: &Store, outside: &Path, u: &UnitRef) -> Vec<u8> {
    let size = |f: &str| {
        std::fs::metadata(s.unit_dir(u).unwrap().join(f))
            .unwrap()
            .len()
    };
    let mut files = vec![
        serde_json::json!({"name": "a.bin", "size": size("a.bin"), "crc32": 0}),
        serde_json::json!({"name": "sub/b.txt", "size": size("sub/b.txt"), "crc32": 0}),
    ];
    for _ in 0..r.below(3) {
        let name = match r.below(3) {
            0 => "linked.txt".to_string(),
            1 => "linked/secret.txt".to_string(),
            _ => hostile(r, s, outside),
        };
        let size = ["not talus's".len(), 11, 0][r.below(3)];
        files.push(serde_json::json!({"name": name, "size": size, "crc32": 0}));
    }
    let rec = serde_json::json!({
        "unit": {"kind": u.kind, "name": u.name},
        "files": files, "meta": null, "created": 0, "writer": "x:1",
    });
    let mut bytes = serde_json::to_vec(&rec).unwrap();
    if r.below(6) == 0 {
        bytes.truncate(r.below(bytes.len() + 1));
    }
    bytes
}

/// Whatever a record lists, a unit is done only when every listed file is a regular file
/// inside its directory reached without a link; reading it (`verify`, `edited_files`) reads
/// nothing else; nothing panics.
#[test]
fn hostile_records_name_only_files_inside_their_unit() {
    let mut r = SplitMix64::new(4401);
    let (_t, s, outside, _files) = scene();
    let u = unit("m3c2", "pair0-0123456789abcdef");
    write_unit(&s, &u)
        .commit(serde_json::Value::Null, None)
        .unwrap();
    let dir = s.unit_dir(&u).unwrap();
    // Links inside the unit: a file and a folder pointing outside.
    symlink(outside.join("secret.txt"), dir.join("linked.txt")).unwrap();
    symlink(&outside, dir.join("linked")).unwrap();
    let canon = dir.canonicalize().unwrap();
    let mut done = 0;
    for case in 0..300 {
        let bytes = record(&mut r, &s, &outside, &u);
        std::fs::write(dir.join(RECORD_FILE), &bytes).unwrap();
        let Some(rec) = s.done(&u) else {
            continue;
        };
        done += 1;
        for f in &rec.files {
            let p = dir.join(&f.name);
            let m = std::fs::symlink_metadata(&p).unwrap();
            assert!(m.is_file(), "case {case}: {} listed", f.name);
            assert!(
                p.canonicalize().unwrap().starts_with(&canon),
                "case {case}: {} lies outside its unit",
                f.name
            );
        }
        let _ = s.verify(&u, &rec);
        let _ = s.edited_files(&u, &rec);
    }
    assert!(
        done > 0,
        "no generated record was taken: the test tests nothing"
    );
    // The record itself as a link to a record elsewhere is no record.
    let elsewhere = outside.join("record.json");
    std::fs::rename(dir.join(RECORD_FILE), &elsewhere).unwrap();
    symlink(&elsewhere, dir.join(RECORD_FILE)).unwrap();
    assert!(s.done(&u).is_none());
}

/// Links planted in `.talus/` — the work area itself, `tmp/` (which gc empties), a FIFO as the
/// lock — are refused by every command that opens the store, reading or writing; a link as
/// `units/<kind>` is never walked by gc, and one as `claims/<run>` never written through.
#[test]
fn links_planted_in_the_work_area_are_refused() {
    let (_t, s, outside, _files) = scene();
    let old = outside.join("keep");
    let before = tree(&outside);
    let tmp = s.tmp();
    std::fs::rename(&tmp, s.work().join("tmp-aside")).unwrap();
    symlink(&old, &tmp).unwrap();
    for e in [
        Store::open(s.dir(), true).unwrap_err(),
        Store::open(s.dir(), false).unwrap_err(),
        Store::inspect(s.dir()).unwrap_err(),
    ] {
        assert_eq!(e.exit_code(), 2, "{e}");
        assert!(e.to_string().contains("symbolic link"), "{e}");
    }
    std::fs::remove_file(&tmp).unwrap();
    std::fs::rename(s.work().join("tmp-aside"), &tmp).unwrap();
    // A FIFO as the lock: refused at once, not waited on.
    let lock = s.work().join("lock");
    let made = std::ffi::CString::new(lock.to_str().unwrap()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(made.as_ptr(), 0o600) }, 0);
    let e = Store::inspect(s.dir()).unwrap_err();
    assert!(e.to_string().contains("FIFO"), "{e}");
    std::fs::remove_file(&lock).unwrap();
    // `.talus` itself a link.
    let t2 = tempfile::tempdir().unwrap();
    std::fs::create_dir(t2.path().join("dir")).unwrap();
    symlink(s.work(), t2.path().join("dir/.talus")).unwrap();
    assert!(Store::inspect(&t2.path().join("dir")).is_err());
    assert!(Store::open(&t2.path().join("dir"), true).is_err());
    // `units/<kind>` a link to a folder of the user's: gc keeps out of it.
    std::fs::create_dir(outside.join("keep/pair0-1")).unwrap();
    let before_gc = tree(&outside);
    symlink(&old, s.units().join("m3c2")).unwrap();
    s.gc(&std::collections::HashSet::new()).unwrap();
    assert_eq!(tree(&outside), before_gc);
    std::fs::remove_dir(outside.join("keep/pair0-1")).unwrap();
    // `claims/<run>` a link: no claim is written through it.
    symlink(&old, s.work().join("claims/run")).unwrap();
    let e = s.claim("run", &unit("m3c2", "x-1"), "t").unwrap_err();
    assert!(e.to_string().contains("symbolic link"), "{e}");
    assert!(s.claim_holder("run", &unit("m3c2", "x-1")).is_none());
    std::fs::remove_file(s.work().join("claims/run")).unwrap();
    // A claim file planted as a link to a file of the user's (an old one: "stale"): not taken
    // over (that would move it away and delete it), refused as the folder's problem.
    std::fs::create_dir_all(s.work().join("claims/run/m3c2")).unwrap();
    symlink(
        outside.join("secret.txt"),
        s.work().join("claims/run/m3c2/x-1"),
    )
    .unwrap();
    let e = s.claim("run", &unit("m3c2", "x-1"), "t").unwrap_err();
    assert_eq!(e.exit_code(), 2, "{e}");
    assert!(e.to_string().contains("symbolic link"), "{e}");
    assert!(!e.to_string().contains("cannot write"), "{e}");
    assert_eq!(tree(&outside), before);
}
