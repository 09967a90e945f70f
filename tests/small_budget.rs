//! A small budget serves a large event (issue 24): the 5.2M-point cliff, whose debris fan gathers
//! 418 k points into one volume, completes at `--memory 164MiB` (the smallest budget that works,
//! the same as for the 40M- and 120M-point pairs of `benches/smallest_budget.sh`) within 1.1 × the
//! budget (the kernel's high-water mark of the run) and writes the same bytes as at 2 GiB, where
//! the layout has 6 tiles instead of 153. In a test binary of its own: the peak is read with
//! `getrusage(RUSAGE_CHILDREN)`, the largest of this process's finished children, so nothing
//! else may run beside it.

mod common;

use common::{run_compare, synth_cliff, tempdir};

/// The largest resident set of any finished child of this process, in bytes.
fn children_peak() -> u64 {
    // SAFETY: getrusage only writes the struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    let r = unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut u) };
    assert_eq!(r, 0, "getrusage");
    u.ru_maxrss as u64 * 1024
}

#[test]
fn the_cliff_at_164_mib_stays_within_the_budget_and_gives_the_same_bytes() {
    let dir = tempdir();
    let (b, a) = synth_cliff(dir.path(), 5_200_000);
    let small = dir.path().join("small");
    let o = run_compare(&b, &a, &small, &["--memory", "164MiB"]);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    // The synth child's peak is far below (≈ 100 MiB): the largest is the compare's.
    let peak = children_peak();
    let budget = 164u64 << 20;
    assert!(
        peak as f64 <= 1.1 * budget as f64,
        "peak {} MiB at a budget of 164 MiB\n{err}",
        peak >> 20
    );
    // The largest event is measured here, not refused: one event's volume gathers 418 k points.
    assert!(err.contains("6 event(s)"), "{err}");
    let large = dir.path().join("large");
    let o = run_compare(&b, &a, &large, &["--memory", "2GiB"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let tiles = |d: &std::path::Path| -> u64 {
        let s: serde_json::Value =
            serde_json::from_slice(&std::fs::read(d.join("summary.json")).unwrap()).unwrap();
        s["tiles"].as_u64().unwrap()
    };
    assert!(
        tiles(&small) > 10 * tiles(&large),
        "{} vs {}",
        tiles(&small),
        tiles(&large)
    );
    for f in [
        "events.geojson",
        "events.csv",
        "event_regions.geojson",
        "m3c2.laz",
        "terrain.bin",
    ] {
        assert!(
            std::fs::read(small.join(f)).unwrap() == std::fs::read(large.join(f)).unwrap(),
            "{f} differs between 164 MiB and 2 GiB"
        );
    }
    for e in std::fs::read_dir(large.join("meshes")).unwrap() {
        let name = e.unwrap().file_name();
        assert!(
            std::fs::read(small.join("meshes").join(&name)).unwrap()
                == std::fs::read(large.join("meshes").join(&name)).unwrap(),
            "{name:?} differs"
        );
    }
}
