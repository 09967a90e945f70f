//! What the store's operations cost on a big file (ignored by default: it needs the file).

use std::time::Instant;

use super::unit_tests::store;
use super::*;

/// Costs on a big file: `TALUS_STORE_BIG=/path cargo test -p talus --lib -- --ignored
/// --nocapture store::timing_tests::timing` (the file must be on the file system of the
/// temporary directory: it is hard-linked into a unit).
#[test]
#[ignore]
fn timing() {
    let big = std::path::PathBuf::from(std::env::var("TALUS_STORE_BIG").unwrap());
    let (_t, s) = store();
    let time = |what: &str, t0: Instant| println!("{what}: {:.6} s", t0.elapsed().as_secs_f64());
    for call in ["content_key first", "content_key cached"] {
        let t0 = Instant::now();
        s.content_key(&big).unwrap();
        time(call, t0);
    }
    let u = UnitRef::new("m3c2", "big").unwrap();
    let mut w = s.begin(&u).unwrap();
    std::fs::hard_link(&big, w.path("big.bin").unwrap()).unwrap();
    let t0 = Instant::now();
    w.add_file("big.bin").unwrap();
    time("add_file (CRC read)", t0);
    let t0 = Instant::now();
    let rec = w.commit(serde_json::Value::Null, None).unwrap();
    time("commit (fsync, rename)", t0);
    let t0 = Instant::now();
    for _ in 0..1000 {
        assert!(s.done(&u).is_some());
    }
    time("done x1000", t0);
    let t0 = Instant::now();
    assert!(s.verify(&u, &rec).unwrap());
    time("verify", t0);
    let t0 = Instant::now();
    for _ in 0..1000 {
        s.claim("r", &u, "t").unwrap().unwrap();
    }
    time("claim + release x1000", t0);
    let src = s.unit_dir(&u).unwrap().join("big.bin");
    let t0 = Instant::now();
    s.publish(&[(src, "m3c2.laz".into())], "m3c2.laz", &|n| {
        n == "m3c2.laz"
    })
    .unwrap();
    time("publish (hard link)", t0);
    let t0 = Instant::now();
    s.gc(&Default::default()).unwrap();
    time("gc of the unit", t0);
}
