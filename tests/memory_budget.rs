//! A budget too small for the data is refused with exit 2 and the smallest budget that works:
//! before anything runs when the plan alone proves it, right after tiling (before any M3C2 unit
//! holds anything) when only the tiles' counts show it. Issue "`--memory` as a hard bound".

mod common;

use common::{run_compare, tempdir, write_cloud, Rng, OFFSET};
use std::path::{Path, PathBuf};

use talus::io::Point3;

/// `n` points of a gently sloping plane over [x0, x0 + w) × [y0, y0 + h).
fn plane(rng: &mut Rng, n: usize, x0: f64, y0: f64, w: f64, h: f64) -> Vec<Point3> {
    (0..n)
        .map(|_| {
            let (x, y) = (x0 + w * rng.uniform(), y0 + h * rng.uniform());
            [
                OFFSET[0] + x,
                OFFSET[1] + y,
                OFFSET[2] + 0.01 * x + 0.002 * rng.normal(),
            ]
        })
        .collect()
}

/// The budget the refusal names (`--memory NMiB` at the end of the message).
fn suggested(stderr: &str) -> u64 {
    let tail = stderr
        .trim_end()
        .rsplit("the smallest budget that works is --memory ")
        .next()
        .unwrap();
    tail.trim_end_matches("MiB")
        .parse()
        .unwrap_or_else(|_| panic!("{stderr}"))
}

/// Two planes of `n` points each over [0, w) × [0, h) in `dir`: (before, after).
fn planes(dir: &Path, seed: u64, n: usize, w: f64, h: f64) -> (PathBuf, PathBuf) {
    let mut rng = Rng::new(seed);
    let (b, a) = (dir.join("b.laz"), dir.join("a.laz"));
    write_cloud(&b, &plane(&mut rng, n, 0.0, 0.0, w, h));
    write_cloud(&a, &plane(&mut rng, n, 0.0, 0.0, w, h));
    (b, a)
}

/// The stderr of `talus compare B A --out OUT EXTRA...`, which must be refused with exit 2.
fn refused(b: &Path, a: &Path, out: &Path, extra: &[&str]) -> String {
    let o = run_compare(b, a, out, extra);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(2), "{err}");
    err
}

#[test]
fn one_tile_beyond_the_budget_is_refused_before_anything_runs() {
    // 2 × 700k points where the normal radius (30 m: a halo of 30 m) makes the smallest tile
    // (four halos) wider than the 100 m survey: one tile of 1.4M points, about 140 MiB, beyond
    // the pool of 160 MiB.
    let dir = tempdir();
    let (b, a) = planes(dir.path(), 11, 700_000, 100.0, 100.0);
    let out = dir.path().join("out");
    let err = refused(
        &b,
        &a,
        &out,
        &["--memory", "160MiB", "--normal-radius", "30"],
    );
    assert!(
        err.contains("--memory 160 MiB is too small: the pair's one tile (1400000 points"),
        "{err}"
    );
    // need = 1.4M × 104 B + 4 MiB ≈ 143 MiB; a pool of that within 16 MiB of base and 5 % slack.
    let want = suggested(&err);
    assert!((165..=175).contains(&want), "{err}");
    // Refused while planning: nothing was tiled, and the folder this run made is gone.
    assert!(!err.contains("tiling"), "{err}");
    assert!(!out.exists());
}

#[test]
fn a_dense_tile_in_the_later_survey_is_refused_before_any_m3c2_unit() {
    // C1 is sparse and even, so the plan (sized from C1's footprint and both surveys' counts)
    // cannot see that C2 puts 1.3M points into one corner: the tilings' counts do.
    let dir = tempdir();
    let mut rng = Rng::new(12);
    let (b, a) = (dir.path().join("b.laz"), dir.path().join("a.laz"));
    write_cloud(&b, &plane(&mut rng, 100_000, 0.0, 0.0, 600.0, 100.0));
    let mut after = plane(&mut rng, 100_000, 0.0, 0.0, 600.0, 100.0);
    after.extend(plane(&mut rng, 1_300_000, 540.0, 40.0, 50.0, 50.0));
    write_cloud(&a, &after);
    let out = dir.path().join("out");
    let err = refused(
        &b,
        &a,
        &out,
        &["--memory", "160MiB", "--normal-radius", "10"],
    );
    assert!(err.contains("pass 1: tiling"), "tiled first: {err}");
    assert!(
        err.contains("--memory 160 MiB is too small: tile t_"),
        "{err}"
    );
    assert!(
        err.contains("points with its halo, the pair's densest) needs"),
        "{err}"
    );
    assert!(suggested(&err) > 160, "{err}");
    // No M3C2 unit finished: the refusal came before any of them held a tile.
    let finished = std::fs::read_dir(out.join(".talus/units/m3c2"))
        .map(|d| d.count())
        .unwrap_or(0);
    assert_eq!(finished, 0, "{err}");
}

#[test]
fn a_merge_of_too_many_tiles_is_refused_before_anything_runs() {
    // 100 tiles of 10 × 10: the points unit's merge (m3c2.laz) holds a chunk of each run's
    // results at once, more than a 160 MiB budget's pool beside the LAZ writer.
    let dir = tempdir();
    let (b, a) = planes(dir.path(), 13, 20_000, 100.0, 100.0);
    let out = dir.path().join("out");
    let err = refused(&b, &a, &out, &["--memory", "160MiB", "--tile-size", "10"]);
    assert!(
        err.contains(
            "--memory 160 MiB is too small: writing the pair's m3c2.laz, merging the results of its"
        ),
        "{err}"
    );
    let want = suggested(&err);
    assert!(want > 160, "{err}");
    assert!(!out.exists());
    // The budget it names is enough (the same layout: the tile side is forced).
    let out = dir.path().join("out2");
    let budget = format!("{want}MiB");
    let o = run_compare(&b, &a, &out, &["--memory", &budget, "--tile-size", "10"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn the_stable_sample_is_fixed_and_fits_the_smallest_budget() {
    // 2 × 600k points, more core points than the stable ground samples (500,000); the sample's
    // need (176 bytes each beside the merge) is fixed, and the smallest budget holds it.
    let dir = tempdir();
    let (b, a) = planes(dir.path(), 14, 600_000, 300.0, 300.0);
    let out = dir.path().join("out");
    // Core points at 0.2 m (the points are about 0.39 m apart): nearly every point is one.
    let o = run_compare(
        &b,
        &a,
        &out,
        &["--memory", "160MiB", "--core-spacing", "0.2"],
    );
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let sampled = s["stable"]["sampled_points"]
        .as_u64()
        .unwrap_or_else(|| panic!("{s}"));
    let cores = s["core_points"].as_u64().unwrap();
    assert!(
        sampled <= talus::units::stable::SAMPLES && sampled < cores,
        "{sampled} of {cores}"
    );
}
