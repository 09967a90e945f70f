use super::*;
use crate::atomic::tmp_path;

fn sample() -> Manifest {
    let mut m = Manifest::new("0123456789abcdef");
    m.record(
        "split/c1",
        UnitEntry {
            file: "tiles/c1".into(),
            checksum: "crc32:00000000".into(),
            inputs_hash: "aa".into(),
        },
    );
    m.record(
        "m3c2/t_0001_0002",
        UnitEntry {
            file: "m3c2/t_0001_0002.tile".into(),
            checksum: "crc32:deadbeef".into(),
            inputs_hash: "bb".into(),
        },
    );
    m
}

#[test]
fn save_load_round_trip_and_readable_json() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("manifest.json");
    let m = sample();
    m.save(&path).unwrap();
    assert_eq!(Manifest::load(&path).unwrap(), m);
    // A person (and any JSON parser) can read it: check the structure with serde_json::Value.
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(v["version"], 1);
    assert_eq!(v["key_hash"], "0123456789abcdef");
    assert_eq!(v["units"]["m3c2/t_0001_0002"]["checksum"], "crc32:deadbeef");
    assert!(!tmp_path(&path).exists());
}

#[test]
fn is_done_needs_matching_inputs() {
    let m = sample();
    assert!(m.is_done("split/c1", "aa"));
    assert!(!m.is_done("split/c1", "ab"));
    assert!(!m.is_done("split/c2", "aa"));
}

#[test]
fn crash_leftover_tmp_does_not_corrupt_previous_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("manifest.json");
    let m = sample();
    m.save(&path).unwrap();
    // Simulate a SIGKILL during the next save: a half-written temporary is left behind.
    let mut next = m.clone();
    next.record(
        "event/7",
        UnitEntry {
            file: "e7".into(),
            checksum: "x".into(),
            inputs_hash: "y".into(),
        },
    );
    let full = serde_json::to_vec_pretty(&next).unwrap();
    std::fs::write(tmp_path(&path), &full[..full.len() / 2]).unwrap();
    // The final name still holds the previous complete manifest.
    assert_eq!(Manifest::load(&path).unwrap(), m);
    assert_eq!(Manifest::open(&path, &m.key_hash).unwrap(), m);
    // The next save overwrites the leftover and replaces the manifest.
    next.save(&path).unwrap();
    assert_eq!(Manifest::load(&path).unwrap(), next);
    assert!(!tmp_path(&path).exists());
}

#[test]
fn open_starts_over_on_new_key_garbage_or_missing_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("manifest.json");
    assert_eq!(Manifest::open(&path, "k").unwrap(), Manifest::new("k"));
    assert!(matches!(Manifest::load(&path), Err(Error::Io { .. })));
    sample().save(&path).unwrap();
    assert_eq!(
        Manifest::open(&path, "other").unwrap(),
        Manifest::new("other")
    );
    std::fs::write(&path, b"{\"version\": 1, \"key_ha").unwrap();
    assert!(matches!(Manifest::load(&path), Err(Error::Corrupt { .. })));
    assert_eq!(Manifest::open(&path, "k").unwrap(), Manifest::new("k"));
}

#[test]
fn file_checksum_is_crc32_of_content() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f");
    std::fs::write(&path, b"123456789").unwrap();
    // CRC-32/IEEE check value of "123456789" (Rocksoft model catalogue): 0xcbf43926.
    assert_eq!(file_checksum(&path).unwrap(), "crc32:cbf43926");
}
