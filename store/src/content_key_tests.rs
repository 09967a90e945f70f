//! Tests of content keys and their cache.

use std::time::{Duration, Instant, SystemTime};

use talus_tiling::Fnv64;

use super::unit_tests::{set_mtime, store};
use super::*;

/// The store with the "racy" window off, so a file just written is cached at once.
fn eager() -> (tempfile::TempDir, Store) {
    let (t, mut s) = store();
    s.racy = Duration::ZERO;
    (t, s)
}

/// A file `name` holding `bytes` in `t`.
fn input(t: &tempfile::TempDir, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = t.path().join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn cache_json(s: &Store) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(s.work().join("cache/inputs.json")).unwrap()).unwrap()
}

#[test]
fn the_key_is_fnv_over_the_size_and_the_block_crcs() {
    let (t, s) = eager();
    let bytes: Vec<u8> = (0..(5u32 << 19)).map(|i| (i * 7 % 251) as u8).collect(); // 2.5 MiB
    let a = input(&t, "a.laz", &bytes);
    let mut h = Fnv64::new();
    h.write_u64(bytes.len() as u64);
    for block in bytes.chunks(1 << 20) {
        h.write(&crc32fast::hash(block).to_le_bytes());
    }
    let key = s.content_key(&a).unwrap();
    assert_eq!(key, h.hex());
    assert_eq!(key.len(), 16);
    // Same bytes elsewhere, same key; an empty file has a key too.
    let b = input(&t, "b.laz", &bytes);
    assert_eq!(s.content_key(&b).unwrap(), key);
    let e = input(&t, "empty", b"");
    assert_eq!(s.content_key(&e).unwrap(), Fnv64::new().write_u64(0).hex());
}

#[test]
fn same_size_and_mtime_with_other_content_is_noticed() {
    let (t, s) = eager();
    let a = input(&t, "a.las", b"first content");
    let mtime = std::fs::metadata(&a).unwrap().modified().unwrap();
    let k1 = s.content_key(&a).unwrap();
    // Past the file system's timestamp granularity, so the rewrite gets another ctime.
    std::thread::sleep(Duration::from_millis(20));
    std::fs::write(&a, b"other content").unwrap();
    set_mtime(&a, mtime);
    assert_eq!(std::fs::metadata(&a).unwrap().modified().unwrap(), mtime);
    let k2 = s.content_key(&a).unwrap();
    assert_ne!(k1, k2);
}

#[test]
fn an_unchanged_file_is_not_read_again() {
    let (t, s) = eager();
    let a = input(&t, "a.las", b"content");
    let k = s.content_key(&a).unwrap();
    let canon = std::fs::canonicalize(&a).unwrap();
    let canon = canon.to_str().unwrap();
    let entry = &cache_json(&s)["files"][canon];
    assert_eq!(entry["key"], k.as_str());
    // Plant another key in the cache: returned as long as the identity holds, so the file
    // was not read.
    let text = std::fs::read_to_string(s.work().join("cache/inputs.json")).unwrap();
    std::fs::write(
        s.work().join("cache/inputs.json"),
        text.replace(&k, "0123456789abcdef"),
    )
    .unwrap();
    let t0 = Instant::now();
    assert_eq!(s.content_key(&a).unwrap(), "0123456789abcdef");
    assert!(t0.elapsed() < Duration::from_secs(1));
    // Through another spelling of the path, too.
    let other = t.path().join(".").join("a.las");
    assert_eq!(s.content_key(&other).unwrap(), "0123456789abcdef");
    // A touch changes the identity: read again, the real key.
    set_mtime(&a, SystemTime::now());
    assert_eq!(s.content_key(&a).unwrap(), k);
    // A damaged cache is an empty one.
    std::fs::write(s.work().join("cache/inputs.json"), b"{not json").unwrap();
    assert_eq!(s.content_key(&a).unwrap(), k);
    assert_eq!(cache_json(&s)["files"][canon]["key"], k.as_str());
}

#[test]
fn a_file_changed_just_now_is_hashed_but_not_cached() {
    let (t, s) = store();
    let a = input(&t, "fresh.las", b"content");
    let k = s.content_key(&a).unwrap();
    assert!(!s.work().join("cache/inputs.json").exists());
    assert_eq!(s.content_key(&a).unwrap(), k);
}

#[test]
fn an_unreadable_input_is_an_input_error_naming_it() {
    let (t, s) = eager();
    let missing = t.path().join("missing.laz");
    let e = s.content_key(&missing).unwrap_err();
    assert!(
        matches!(&e, Error::Input { path, .. } if path == &missing),
        "{e}"
    );
    assert!(e.to_string().contains("missing.laz"));
    let e = s.content_key(t.path()).unwrap_err();
    assert!(
        matches!(&e, Error::Input { path, .. } if path == t.path()),
        "{e}"
    );
}
