//! Tiling invariance (SPEC.md §3): the same scene as one tile, as many small tiles, and with one
//! or two threads gives the same outputs, byte for byte.
//!
//! The reference is the whole-cloud run (one tile: no halo, no tile border); a tiled run must
//! reproduce it exactly, because every neighbourhood of a core point lies inside its tile's halo
//! and core points, clusters and event ids are defined on global grids and keys. The files are
//! compared as bytes, and m3c2.laz is also read back column by column with
//! `talus::io::result_table::read` so that a failure says which values differ and where.

mod common;
mod pipeline_common;

use std::path::Path;

use pipeline_common::{assert_same_outputs, cliff, compare, unit_dir};

/// summary.json without what legitimately differs: timings, tile count and side, thread count.
fn summary_without_timings(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let o = v.as_object_mut().unwrap();
    for k in ["stages", "tiles", "tile_size"] {
        o.remove(k);
    }
    // The thread count is a parameter of the run, echoed back.
    if let Some(p) = v["parameters"].as_object_mut() {
        p.remove("threads");
    }
    v
}

/// The cliff scene's planted scars are centred at x = 500 012 and 500 040 on the face at
/// y = 5 000 000. With core spacing 0.25 the grid is anchored at (500 000, 4 999 980), so 4 m
/// tiles put a tile corner exactly at both scar centres (and 10 m tiles at the second): each
/// scar is then cut into four tiles, the worst case for halos, core-point selection at borders,
/// orientation and the merged DBSCAN.
#[test]
fn tiled_runs_equal_the_whole_cloud_run() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 120_000);
    let whole = tmp.path().join("whole");
    let base = ["--core-spacing", "0.25"];
    compare(
        &before,
        &after,
        &whole,
        &[&base[..], &["--tile-size", "1000"]].concat(),
    );
    let s = summary_without_timings(&whole);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(whole.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["tiles"], 1, "the reference must be one tile");
    // The scene's three planted events are found, as the significant ones (else the comparison
    // below proves little); at this coarse core spacing the noise gives a few small ones more,
    // which the tiled runs must reproduce as well.
    assert_eq!(s["significant_events"], 3, "{s}");
    for (ts, threads) in [("4", "1"), ("4", "2"), ("10", "2"), ("13", "1")] {
        let tiled = tmp.path().join(format!("tiles{ts}-threads{threads}"));
        compare(
            &before,
            &after,
            &tiled,
            &[&base[..], &["--tile-size", ts, "--threads", threads]].concat(),
        );
        let t: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(tiled.join("summary.json")).unwrap())
                .unwrap();
        assert!(t["tiles"].as_u64().unwrap() > 1, "{t}");
        assert_same_outputs(&whole, &tiled);
        assert_eq!(
            s,
            summary_without_timings(&tiled),
            "summary.json of {ts} m tiles"
        );
    }
}

/// A run that starts anew keeps the points its spacing pass decodes and tiles the before survey
/// from that copy (`io::replay`); a resumed run decodes the file again. Both give the same tile
/// files and the same outputs, byte for byte, and the copy is gone when the run ends.
#[test]
fn tiling_from_the_decoded_copy_equals_decoding_again() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 120_000);
    // The tile files stay after the run (`--keep-units`), to be compared.
    let base = [
        "--core-spacing",
        "0.25",
        "--tile-size",
        "10",
        "--keep-units",
    ];
    let kept = tmp.path().join("kept");
    compare(&before, &after, &kept, &base);
    let scratch: Vec<_> = std::fs::read_dir(kept.join(".talus/tmp"))
        .unwrap()
        .collect();
    assert!(scratch.is_empty(), "left in .talus/tmp: {scratch:?}");
    let decoded = tmp.path().join("decoded");
    compare(
        &before,
        &after,
        &decoded,
        &[&base[..], &["--resume"]].concat(),
    );
    assert_same_outputs(&kept, &decoded);
    // The tilings themselves: every tile file of every tiling unit.
    let tiles = |d: &Path| -> Vec<(String, Vec<u8>)> {
        let mut v = Vec::new();
        for unit in std::fs::read_dir(d.join(".talus/units/tiling")).unwrap() {
            let unit = unit.unwrap().path();
            for f in std::fs::read_dir(&unit).unwrap() {
                let f = f.unwrap().path();
                if f.extension().is_some_and(|e| e == "tile") {
                    let name = format!(
                        "{}/{}",
                        unit.file_name().unwrap().to_string_lossy(),
                        f.file_name().unwrap().to_string_lossy()
                    );
                    v.push((name, std::fs::read(&f).unwrap()));
                }
            }
        }
        v.sort();
        v
    };
    let (a, b) = (tiles(&kept), tiles(&decoded));
    assert!(a.len() > 4, "{} tile files", a.len());
    assert!(a == b, "the tile files differ");
}

/// The sum of `key` over the records of the M3C2 units in `dir`'s store.
fn m3c2_meta_sum(dir: &Path, key: &str) -> u64 {
    let units = dir.join(".talus/units/m3c2");
    std::fs::read_dir(&units)
        .unwrap()
        .map(|e| {
            let r: serde_json::Value = serde_json::from_slice(
                &std::fs::read(e.unwrap().path().join("record.json")).unwrap(),
            )
            .unwrap();
            r["meta"][key].as_u64().unwrap_or(0)
        })
        .sum()
}

/// Issue "Change of any depth", item 5: change deeper than the cylinder, walked along the normal
/// across tile borders. The dense cliff at 600k points per epoch (about 4 cm spacing: the
/// derived half-length is about 1.2 m, so the 3 m deep box, the 2 m deep scar, the 2.5 m cone
/// and the 1.5 m deposit are walked) as one tile and as 3 m tiles: walks leave their tile
/// (`walked_beyond_tile` > 0) and are finished over the points along their axes; the outputs are
/// the same bytes.
#[test]
fn walks_across_tiles_equal_the_whole_cloud_run() {
    let tmp = common::tempdir();
    let scene = tmp.path().join("scene");
    let o = common::run(&[
        "synth",
        "dense",
        "--points",
        "600000",
        "--out",
        scene.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (before, after) = (scene.join("before.laz"), scene.join("after.laz"));
    let whole = tmp.path().join("whole");
    compare(&before, &after, &whole, &["--tile-size", "1000"]);
    let s = summary_without_timings(&whole);
    assert!(
        s["reach"]["extended_points"].as_u64().unwrap() > 1000,
        "{s}"
    );
    assert_eq!(m3c2_meta_sum(&whole, "walked_beyond_tile"), 0, "one tile");
    let tiled = tmp.path().join("tiled");
    compare(&before, &after, &tiled, &["--tile-size", "3"]);
    assert!(
        m3c2_meta_sum(&tiled, "walked_beyond_tile") > 100,
        "walks must leave their tiles for this test to prove anything"
    );
    assert_same_outputs(&whole, &tiled);
    assert_eq!(s, summary_without_timings(&tiled));
}

/// More tiles than one merge may hold (`units::merged::FAN_IN`) at a budget their direct merge
/// would strain (400 MiB): the pair's results are merged in rounds before the stages after M3C2
/// read them. With 1 m tiles the cliff has 1770 tiles — two rounds (56 runs, then 2) — and with
/// 4 m tiles 120 (one round): both give the one-tile run's outputs byte for byte, and no round's
/// temporary run is left in the unit. At the default budget (2 GiB) the 120 tiles' direct merge
/// (122 MiB) is merged directly: no merged unit.
#[test]
fn results_merged_in_rounds_equal_the_whole_cloud_run() {
    let tmp = common::tempdir();
    let (before, after) = cliff(&tmp.path().join("scene"), 120_000);
    let whole = tmp.path().join("whole");
    compare(&before, &after, &whole, &["--tile-size", "1000"]);
    assert!(
        !whole.join(".talus/units/merged").exists(),
        "one tile: no merge"
    );
    let direct = tmp.path().join("direct");
    compare(&before, &after, &direct, &["--tile-size", "4"]);
    assert!(
        !direct.join(".talus/units/merged").exists(),
        "merged directly"
    );
    for (ts, rounds) in [("4", 1), ("1", 2)] {
        let tiled = tmp.path().join(format!("tiles-{ts}"));
        // With 4 m tiles the surveys are also tiled in parts, and m3c2.laz written in segments
        // that seek into the merged runs.
        let parts: &[&str] = match ts {
            "4" => &["--tiling-part", "30001"],
            _ => &[],
        };
        compare(
            &before,
            &after,
            &tiled,
            &[&["--tile-size", ts, "--memory", "400MiB"][..], parts].concat(),
        );
        if ts == "4" {
            let segments = std::fs::read_dir(tiled.join(".talus/units/segments")).unwrap();
            assert!(
                segments.count() >= 3,
                "m3c2.laz in as many segments as parts"
            );
        }
        let unit = unit_dir(&tiled, "merged", "pair-");
        let record: serde_json::Value =
            serde_json::from_slice(&std::fs::read(unit.join("record.json")).unwrap()).unwrap();
        assert_eq!(record["meta"]["rounds"], rounds, "{}", record["meta"]);
        assert!(record["meta"]["runs"].as_array().unwrap().len() <= 32);
        for f in std::fs::read_dir(&unit).unwrap() {
            let name = f.unwrap().file_name().into_string().unwrap();
            assert!(
                name == "record.json" || name.starts_with("m_"),
                "{name} left in the merged unit"
            );
        }
        assert_same_outputs(&whole, &tiled);
        // The budget given is echoed back among the parameters; the rest is the same.
        let without_budget = |d: &Path| {
            let mut v = summary_without_timings(d);
            v["parameters"]
                .as_object_mut()
                .unwrap()
                .remove("memory_bytes");
            v
        };
        assert_eq!(without_budget(&whole), without_budget(&tiled));
    }
}

/// An events unit whose kept core points are more than the budget holds at once smooths and
/// clusters them a piece of space at a time (`events::pieces`), joining the clusters that cross
/// pieces: every output is the bytes of the run that held them at once. `TALUS_EVENTS_HELD`
/// lowers what a unit holds to a few thousand kept points, so that a small scene (a 2M-point
/// `synth large`: 8,443 kept points, 9 events spread over 200 m) takes 2 and then 16 pieces.
#[test]
fn events_in_pieces_equal_the_events_held_at_once() {
    let tmp = common::tempdir();
    let scene = tmp.path().join("scene");
    let synth = common::run(&[
        "synth",
        "large",
        "--points",
        "2000000",
        "--out",
        scene.to_str().unwrap(),
    ]);
    assert!(
        synth.status.success(),
        "{}",
        String::from_utf8_lossy(&synth.stderr)
    );
    let (before, after) = (scene.join("before.laz"), scene.join("after.laz"));
    let meta = |d: &Path| {
        let unit = unit_dir(d, "events", "pair-");
        let record: serde_json::Value =
            serde_json::from_slice(&std::fs::read(unit.join("record.json")).unwrap()).unwrap();
        (
            record["meta"]["kept"].as_u64().unwrap(),
            record["meta"]["pieces"].as_u64().unwrap(),
        )
    };
    let held = tmp.path().join("held");
    compare(&before, &after, &held, &[]);
    let (kept, pieces) = meta(&held);
    assert_eq!(pieces, 0, "held at once");
    assert!(kept > 5000, "{kept} kept core points");
    // Two pieces, and more than the 8 a pass over the scratch rows hands their points.
    for (most, least_pieces) in [(kept - 500, 2), (3000, 9)] {
        let out = tmp.path().join(format!("held-{most}"));
        let o = common::talus()
            .env("TALUS_EVENTS_HELD", most.to_string())
            .args([
                "compare",
                before.to_str().unwrap(),
                after.to_str().unwrap(),
                "--out",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let (k, pieces) = meta(&out);
        assert_eq!(k, kept);
        assert!(pieces >= least_pieces, "{pieces} pieces holding {most}");
        assert_same_outputs(&held, &out);
        // The unit's scratch files are gone with it.
        let unit = unit_dir(&out, "events", "pair-");
        for f in std::fs::read_dir(&unit).unwrap() {
            let name = f.unwrap().file_name().into_string().unwrap();
            assert!(!name.ends_with(".tmp"), "{name} left in the events unit");
        }
    }
}

/// A survey larger than `--tiling-part` is tiled by several units, ranges of its points (a task
/// each on a cluster: issue 47): every output is the whole survey's, byte for byte — through the
/// LAZ decoder of layered point formats (the synthesized cliff, misregistered so that the
/// alignment applies, its sample reads the parts' frames near its windows and the after survey
/// is tiled again in its parts), the las crate's
/// LAZ decoder (St Leonards, point format 0) and uncompressed LAS (autzen, format 7), parts
/// starting inside LAZ chunks; m3c2.laz written in as many segments as the before survey's
/// parts and joined, byte for byte the file one pass writes. A survey that shows too few distinct positions across its parts
/// is refused as a whole one is.
#[test]
fn a_survey_tiled_in_parts_gives_the_whole_surveys_outputs() {
    let tmp = common::tempdir();
    let (before, after) = pipeline_common::synth_cliff(
        &tmp.path().join("scene"),
        120_000,
        &["--shift", "0.08,0,0", "--turn", "0,0,0.1"],
    );
    let leo = common::data("st-leonards");
    let autzen = common::data("autzen-bmx");
    let pairs = [
        // Core points closer than the default: more than four LAZ chunks of them, so that
        // m3c2.laz's segments hold chunks each.
        (
            "cliff",
            before,
            after,
            "25001",
            vec!["--tile-size", "10", "--core-spacing", "0.24"],
        ),
        (
            "leo",
            leo.join("leo_20180606_dsm_resampled_1m.laz"),
            leo.join("leo_20180713_dsm_resampled_1m.laz"),
            "40000",
            vec![],
        ),
        (
            "autzen",
            autzen.join("autzen-bmx-2010.las"),
            autzen.join("autzen-bmx-2023.las"),
            "100",
            vec![],
        ),
    ];
    for (name, b, a, part, extra) in &pairs {
        let whole = tmp.path().join(format!("{name}-whole"));
        let parted = tmp.path().join(format!("{name}-parts"));
        let o = common::run_compare(b, a, &whole, extra);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let line = String::from_utf8_lossy(&o.stderr).to_string();
        compare(
            b,
            a,
            &parted,
            &[&extra[..], &["--tiling-part", part]].concat(),
        );
        let parts = std::fs::read_dir(parted.join(".talus/units/tiling"))
            .unwrap()
            .count();
        assert!(parts >= 6, "{name}: {parts} tiling units");
        // m3c2.laz written in segments, as many as the before survey's parts, and joined.
        let segments: Vec<serde_json::Value> =
            std::fs::read_dir(parted.join(".talus/units/segments"))
                .unwrap()
                .map(|d| {
                    let rec = d.unwrap().path().join("record.json");
                    serde_json::from_str(&std::fs::read_to_string(rec).unwrap()).unwrap()
                })
                .collect();
        let filled = segments
            .iter()
            .filter(|r| r["meta"]["written"]["core_points"].as_u64() > Some(0))
            .count();
        assert!(segments.len() >= 3, "{name}: {} segments", segments.len());
        // The stable ground's pass in as many ranges.
        let ranges = std::fs::read_dir(parted.join(".talus/units/sampled"))
            .unwrap()
            .count();
        assert_eq!(ranges, segments.len(), "{name}: the stable ground's ranges");
        let kept = std::fs::read_dir(parted.join(".talus/units/kept"))
            .unwrap()
            .count();
        assert_eq!(kept, segments.len(), "{name}: the events' filter's ranges");
        if *name == "cliff" {
            assert!(filled >= 3, "{name}: {filled} segments hold core points");
        }
        if *name == "cliff" {
            assert!(line.contains("the after survey aligned on"), "{line}");
            // The after survey tiled again in the first one's frame, a unit per part.
            let aligned = std::fs::read_dir(parted.join(".talus/units/aligned"))
                .unwrap()
                .count();
            assert!(aligned >= 3, "{aligned} aligned units");
            assert_same_outputs(&whole, &parted);
        } else {
            // Real surveys' events may have no solids: every output file compared.
            for f in ["m3c2.laz", "events.csv", "terrain.bin", "view.json"] {
                assert!(
                    std::fs::read(whole.join(f)).unwrap() == std::fs::read(parted.join(f)).unwrap(),
                    "{name}: {f} differs in parts"
                );
            }
        }
        assert_eq!(
            summary_without_timings(&whole),
            summary_without_timings(&parted),
            "{name}: summary.json"
        );
        // The stage table too but for its seconds: a survey's parts count as one unit.
        let units = |d: &Path| -> Vec<(String, u64)> {
            let v: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap())
                    .unwrap();
            v["stages"]
                .as_array()
                .unwrap()
                .iter()
                .map(|s| (s["stage"].to_string(), s["units"].as_u64().unwrap()))
                .collect()
        };
        assert_eq!(units(&whole), units(&parted), "{name}: the stage table");
    }

    // Two distinct positions over 829 points (inside autzen's extent), in parts of 100:
    // refused as one survey is.
    let p = [[194_480.0, 259_230.0, 430.0], [194_481.0, 259_230.5, 430.2]];
    let twice: Vec<talus::geom::Point3> = (0..829).map(|i| p[i % 2]).collect();
    let f = tmp.path().join("two_places.laz");
    let mut w = talus::io::las_out::ResultWriter::create(
        &f,
        &talus::io::Crs::default(),
        &[],
        [194_000.0, 259_000.0, 100.0],
    )
    .unwrap();
    for q in &twice {
        w.write(*q, &[]).unwrap();
    }
    w.finish().unwrap();
    let (_, b, _, _, _) = &pairs[2];
    let out = tmp.path().join("two");
    let o = common::run_compare(b, &f, &out, &["--tiling-part", "100"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("two_places.laz: 829 points at only 2 distinct position(s)"),
        "{err}"
    );
    assert!(!out.exists(), "a refused run left {}", out.display());
}
