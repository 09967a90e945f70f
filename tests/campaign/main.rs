//! `talus campaign` (issue "Campaigns", SPEC.md §5) on a synthetic campaign (`talus synth
//! campaign`, exact truth), on the St Leonards beach campaign (six UAV surveys,
//! tests/data/st-leonards) and on bad input:
//! - synthetic: every planted change of truth.json (consecutive and baseline pairs) found in its
//!   own pair with its volume within 2 %, and the changes of one place (the scar that grows
//!   again, truth track 1) on one `track_id` of the campaign's events.csv / events.geojson, other
//!   places on other tracks;
//! - synthetic: each pair's results are `talus compare`'s on its two surveys given the pair's
//!   parameters (summary.json) and the campaign's core points (timeseries.laz), with the campaign
//!   cut into tiles on its own grid and compare left to its own (`--pair-clouds`); without it,
//!   the same pairs but m3c2.laz, and terrain.bin's positions once, in the first pair's;
//! - each pair's results are `talus compare`'s on that pair, given the campaign's parameters and
//!   core points (byte for byte);
//! - appending a survey: a run on five surveys, then on six with `--resume`, computes only what
//!   the sixth adds (every unit of the first run is reused, untouched) and ends with the outputs
//!   of a run on all six at once;
//! - SIGKILL at random moments then `--resume` gives the outputs of an uninterrupted run;
//! - bad input (no date, one date twice, an empty folder, tiles in two CRSs, a survey off the
//!   site): exit 2, one line naming the file and the problem, nothing written;
//! - the time series: timeseries.parquet read by pyarrow holds timeseries.laz's values (laspy)
//!   and each pair's m3c2.laz distances (`--pair-clouds`), bit for bit, nulls where they have
//!   NaN; at 400 pairs (past what a LAS VLR describes) the Parquet holds them all (each its
//!   pair's terrain.bin distances) and timeseries.laz the core points only, which laspy reads.
//!
//! "The outputs" are every file of DIR but the timings a run records of itself (summary.json's
//! stage seconds, the `seconds` column of campaign.csv/json and the run-time column of
//! report.html's table), compared byte for byte.

#[path = "../common/mod.rs"]
mod common;
#[path = "../pipeline_common/mod.rs"]
mod pipeline_common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Instant;

use common::Rng;
use pipeline_common::unit_times;
use serde_json::Value;
use talus::synth::campaign::{CampaignTruth, RECURRING_TRACK};

mod files;

fn surveys() -> Vec<PathBuf> {
    let dir = common::data("st-leonards");
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "laz"))
        .collect();
    v.sort();
    assert_eq!(v.len(), 6);
    v
}

fn campaign(epochs: &[PathBuf], out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args: Vec<String> = vec!["campaign".into()];
    args.extend(epochs.iter().map(|p| p.to_string_lossy().into_owned()));
    args.extend(["--out".into(), out.to_string_lossy().into_owned()]);
    args.extend(extra.iter().map(|s| s.to_string()));
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    common::run(&refs)
}

fn ok(o: &std::process::Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Every file under `dir` (not .talus) by relative name, with the run's own timings blanked.
fn outputs(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(base: &Path, here: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for e in std::fs::read_dir(here).unwrap() {
            let p = e.unwrap().path();
            let name = p.strip_prefix(base).unwrap().to_string_lossy().into_owned();
            if name.starts_with(".talus") {
                continue;
            }
            if p.is_dir() {
                walk(base, &p, out);
                continue;
            }
            let bytes = std::fs::read(&p).unwrap();
            let bytes = if name.ends_with("summary.json") || name == "campaign.json" {
                let mut v: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
                blank_seconds(&mut v);
                v.to_string().into_bytes()
            } else if name == "report.html" {
                blank_run_times(&String::from_utf8(bytes).unwrap()).into_bytes()
            } else if name == "campaign.csv" {
                // The seconds column (15th).
                String::from_utf8(bytes)
                    .unwrap()
                    .lines()
                    .map(|l| {
                        let mut c: Vec<&str> = l.split(',').collect();
                        if c.len() > 14 {
                            c[14] = "-";
                        }
                        c.join(",")
                    })
                    .collect::<Vec<_>>()
                    .join("\n")
                    .into_bytes()
            } else {
                bytes
            };
            out.insert(name, bytes);
        }
    }
    /// report.html's table with its run-time column (the last cell of each row) blanked.
    fn blank_run_times(html: &str) -> String {
        let mut out = String::new();
        let mut rest = html;
        while let Some(end) = rest.find("</td></tr>") {
            let (head, tail) = rest.split_at(end);
            match head.rfind("<td>") {
                Some(start)
                    if head[start + 4..]
                        .chars()
                        .all(|c| c.is_ascii_digit() || " .,\u{2009}\u{202f}".contains(c)) =>
                {
                    out.push_str(&head[..start + 4]);
                    out.push('-');
                }
                _ => out.push_str(head),
            }
            out.push_str("</td></tr>");
            rest = &tail["</td></tr>".len()..];
        }
        out.push_str(rest);
        out
    }
    fn blank_seconds(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, x) in m.iter_mut() {
                    if k == "seconds" {
                        *x = serde_json::Value::Null;
                    } else {
                        blank_seconds(x);
                    }
                }
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(blank_seconds),
            _ => {}
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn assert_same(a: &Path, b: &Path) {
    let (x, y) = (outputs(a), outputs(b));
    assert_eq!(
        x.keys().collect::<Vec<_>>(),
        y.keys().collect::<Vec<_>>(),
        "{} and {} hold other files",
        a.display(),
        b.display()
    );
    for (name, bytes) in &x {
        assert!(
            &y[name] == bytes,
            "{name} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}

/// The flags that give `talus compare` the parameters of `p` (summary.json's "parameters"), but
/// the registration error and the threshold: those compare measures on the pair's stable ground.
fn parameter_flags(p: &Value) -> Vec<String> {
    [
        "point_spacing",
        "core_spacing",
        "normal_radius",
        "cyl_radius",
        "cyl_halflen",
        "min_points",
        "smooth_k",
        "smooth_sigma",
        "eps",
        "cluster_min_points",
    ]
    .iter()
    .flat_map(|k| {
        [
            format!("--{}", k.replace('_', "-")),
            p[k]["value"].to_string(),
        ]
    })
    .chain([
        "--orientation".into(),
        p["orientation"]["value"].as_str().unwrap().into(),
    ])
    .collect()
}

/// The lean campaign's pair `label` (in `lean`) holds the `--pair-clouds` one's outputs (in
/// `full`) but m3c2.laz; where its terrain positions are in the first pair (`shared`: its
/// label), its terrain.bin is the full one's distances (its time-series column's file, the same
/// bytes) and its view.json the full one's with `positions` naming the first pair's terrain.bin
/// (and format version 2).
fn assert_lean_pair(label: &str, full: &Path, lean: &Path, shared: Option<&str>) {
    let (mut mine, mut theirs) = (outputs(lean), outputs(full));
    assert!(
        theirs.remove("m3c2.laz").is_some(),
        "pair {label}: no m3c2.laz with --pair-clouds"
    );
    let (terrain, view) = (
        mine.remove("terrain.bin").unwrap(),
        mine.remove("view.json").unwrap(),
    );
    let (t, v) = (
        theirs.remove("terrain.bin").unwrap(),
        theirs.remove("view.json").unwrap(),
    );
    assert_eq!(
        mine.keys().collect::<Vec<_>>(),
        theirs.keys().collect::<Vec<_>>(),
        "pair {label}"
    );
    for (n, bytes) in &mine {
        assert!(
            bytes == &theirs[n],
            "pair {label}: {n} differs from --pair-clouds'"
        );
    }
    let mut view: Value = serde_json::from_slice(&view).unwrap();
    let v: Value = serde_json::from_slice(&v).unwrap();
    match shared {
        None => {
            assert!(terrain == t, "pair {label}: terrain.bin differs");
            assert_eq!(view, v, "pair {label}: view.json");
        }
        Some(first) => {
            let n = v["points"].as_u64().unwrap() as usize;
            assert!(n > 0 && t.len() == 16 * n, "pair {label}: {n} points");
            assert!(
                terrain == t[12 * n..],
                "pair {label}: terrain.bin is not the distances"
            );
            let at = view.as_object_mut().unwrap().remove("positions");
            assert_eq!(
                at,
                Some(format!("../{first}/terrain.bin").into()),
                "pair {label}"
            );
            // A view.json naming its positions elsewhere is format version 2.
            assert_eq!(view["version"], 2, "pair {label}");
            view["version"] = v["version"].clone();
            assert_eq!(view, v, "pair {label}: view.json");
            // Published from the pair's time-series column (up to 2M core points): that very
            // file, not a copy.
            use std::os::unix::fs::MetadataExt;
            let ino = std::fs::metadata(lean.join("terrain.bin")).unwrap().ino();
            let store = lean
                .parent()
                .unwrap()
                .parent()
                .unwrap()
                .join(".talus/units/series");
            let linked = std::fs::read_dir(&store).unwrap().any(|d| {
                let f = d.unwrap().path().join("series.bin");
                std::fs::metadata(f).is_ok_and(|m| m.ino() == ino)
            });
            assert!(
                linked,
                "pair {label}: terrain.bin is not its series unit's file"
            );
        }
    }
}

/// The campaign's pair `label` (its outputs in `pair`) is compare's run in `out`: every output
/// but summary.json byte for byte (m3c2.laz, events, regions, viewer files), every mesh.
fn assert_pair_is_compare(label: &str, pair: &Path, out: &Path) {
    let (mine, theirs) = (outputs(pair), outputs(out));
    for name in pipeline_common::COMPARED {
        assert!(
            mine[*name] == theirs[*name],
            "pair {label}: {name} differs from compare's"
        );
    }
    let meshes = |m: &BTreeMap<String, Vec<u8>>| -> Vec<String> {
        m.keys()
            .filter(|n| n.starts_with("meshes/"))
            .cloned()
            .collect()
    };
    assert_eq!(meshes(&mine), meshes(&theirs), "pair {label}: other meshes");
    for n in meshes(&mine) {
        assert!(mine[&n] == theirs[&n], "pair {label}: {n} differs");
    }
}

#[test]
fn each_pair_is_a_compare_of_its_surveys_with_the_campaigns_parameters_and_core_points() {
    let s = surveys();
    let tmp = common::tempdir();
    let dir = tmp.path().join("campaign");
    ok(&campaign(&s[..4], &dir, &["--pair-clouds"]));
    let summary = json(&dir.join("summary.json"));
    let params = parameter_flags(&summary["parameters"]);
    for k in 0..3 {
        let label = format!(
            "{}_{}",
            summary["epochs"][k]["label"].as_str().unwrap(),
            summary["epochs"][k + 1]["label"].as_str().unwrap()
        );
        let pair = dir.join("pairs").join(&label);
        let out = tmp.path().join(format!("compare{k}"));
        let mut args: Vec<&str> = params.iter().map(String::as_str).collect();
        let cores = pair.join("m3c2.laz");
        args.extend(["--core-points", cores.to_str().unwrap()]);
        ok(&common::run_compare(&s[k], &s[k + 1], &out, &args));
        assert_pair_is_compare(&label, &pair, &out);
    }
}

#[test]
fn appending_a_survey_computes_only_what_it_adds() {
    let s = surveys();
    let tmp = common::tempdir();
    let dir = tmp.path().join("appended");
    let t = Instant::now();
    ok(&campaign(&s[..5], &dir, &[]));
    let five = t.elapsed();
    // The intermediate units (tiles, M3C2 results) were released after the first run (their
    // records stay): the appended survey computes none of the old pairs' again — it reads the
    // first and the last survey's tiles, which a campaign keeps, and every old pair's column of
    // the time series (`series`).
    let kinds = [
        "tiling", "cores", "m3c2", "series", "stable", "events", "points", "volumes", "outputs",
    ];
    let before: BTreeMap<&str, _> = kinds.iter().map(|k| (*k, unit_times(&dir, k))).collect();
    let t = Instant::now();
    ok(&campaign(&s, &dir, &["--resume"]));
    let appended = t.elapsed();
    // Every unit of the first run is still there, not computed again.
    for k in kinds {
        let now = unit_times(&dir, k);
        for (name, time) in &before[k] {
            assert_eq!(
                now.get(name),
                Some(time),
                "{k} unit {name} was computed again"
            );
        }
    }
    // What the sixth survey adds: its tiling, and one more pair's units.
    let added = |k: &str| unit_times(&dir, k).len() - before[k].len();
    assert_eq!(added("tiling"), 1);
    assert_eq!(added("cores"), 0);
    assert_eq!(added("outputs"), 1);
    assert_eq!(added("points"), 1);
    assert_eq!(added("series"), 1);
    assert_eq!(added("m3c2"), before["m3c2"].len() / 4);
    eprintln!(
        "five surveys {:.1} s; the sixth appended {:.1} s",
        five.as_secs_f64(),
        appended.as_secs_f64()
    );
    let whole = tmp.path().join("whole");
    ok(&campaign(&s, &whole, &[]));
    assert_same(&whole, &dir);
}

#[test]
fn sigkill_at_random_moments_then_resume_gives_the_uninterrupted_result() {
    let s = surveys();
    let tmp = common::tempdir();
    let reference = tmp.path().join("reference");
    let t = Instant::now();
    ok(&campaign(&s[..4], &reference, &[]));
    let full = t.elapsed();
    let dir = tmp.path().join("killed");
    let mut rng = Rng::new(11);
    let mut landed = 0;
    for attempt in 0..5 {
        let mut args: Vec<String> = vec!["campaign".into()];
        args.extend(s[..4].iter().map(|p| p.to_string_lossy().into_owned()));
        args.extend(["--out".into(), dir.to_string_lossy().into_owned()]);
        if attempt > 0 {
            args.push("--resume".into());
        }
        let mut child = common::talus()
            .args(&args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(full.mul_f64(0.05 + 0.8 * rng.uniform()));
        if child.try_wait().unwrap().is_none() {
            child.kill().unwrap();
            landed += 1;
        }
        child.wait().unwrap();
    }
    assert!(landed > 0, "no kill landed while the campaign ran");
    ok(&campaign(&s[..4], &dir, &["--resume"]));
    assert_same(&reference, &dir);
}

// ---------------------------------------------------------------- the synthetic campaign

/// Relative volume tolerance: 2 % of the true volume.
const REL_TOL: f64 = 0.02;
/// Largest |volume| (m³) a found event may have without matching a planted change (the stable
/// scene's false-positive bound, tests/accuracy.rs).
const STRAY_MAX: f64 = 0.2;

/// `talus synth campaign --epochs N --points P` into `dir`; its truth.
fn synth_campaign(dir: &Path, epochs: usize, points: u64, extra: &[&str]) -> CampaignTruth {
    let (e, p) = (epochs.to_string(), points.to_string());
    let mut args = vec![
        "synth",
        "campaign",
        "--out",
        dir.to_str().unwrap(),
        "--epochs",
        &e,
        "--points",
        &p,
    ];
    args.extend_from_slice(extra);
    let o = common::run(&args);
    ok(&o);
    serde_json::from_slice(&std::fs::read(dir.join("truth.json")).unwrap()).unwrap()
}

/// A synthetic campaign's pairs as (before, after): the consecutive ones, then the baseline
/// ones (the campaign's order).
fn all_pairs(truth: &CampaignTruth) -> Vec<(usize, usize)> {
    truth
        .pairs
        .iter()
        .chain(&truth.baseline_pairs)
        .map(|p| (p.before, p.after))
        .collect()
}

/// The surveys of a synthetic campaign written into `data`, and their labels in a campaign
/// (YYYYMMDD).
fn surveys_of(truth: &CampaignTruth, data: &Path) -> (Vec<PathBuf>, Vec<String>) {
    truth
        .epochs
        .iter()
        .map(|e| (data.join(&e.file), e.date.replace('-', "")))
        .unzip()
}

/// A synthetic campaign of 4 surveys of `points` points in `tmp`/data (`synth` more arguments
/// of `synth campaign`), then `talus campaign` of them with `--baseline` and `extra` into
/// `tmp`/campaign: the truth, the surveys, their labels in the campaign (YYYYMMDD) and the
/// campaign's DIR.
fn synth_and_campaign(
    tmp: &Path,
    points: u64,
    synth: &[&str],
    extra: &[&str],
) -> (CampaignTruth, Vec<PathBuf>, Vec<String>, PathBuf) {
    let data = tmp.join("data");
    let truth = synth_campaign(&data, 4, points, synth);
    let (surveys, labels) = surveys_of(&truth, &data);
    let dir = tmp.join("campaign");
    let mut args = vec!["--baseline"];
    args.extend_from_slice(extra);
    ok(&campaign(&surveys, &dir, &args));
    (truth, surveys, labels, dir)
}

fn json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// An event of the campaign's events.geojson.
#[derive(Debug)]
struct Found {
    pair: String,
    id: u64,
    kind: String,
    volume: f64,
    significant: bool,
    track: u64,
    centroid: [f64; 3],
}

fn campaign_events(dir: &Path) -> Vec<Found> {
    let fc = json(&dir.join("events.geojson"));
    let found: Vec<Found> = fc["features"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let p = &f["properties"];
            let c = &f["geometry"]["coordinates"];
            Found {
                pair: p["pair"].as_str().unwrap().into(),
                id: p["id"].as_u64().unwrap(),
                kind: p["kind"].as_str().unwrap().into(),
                volume: p["volume_m3"].as_f64().unwrap(),
                significant: p["significant"].as_bool().unwrap(),
                // No track is null (vegetation): 0 here.
                track: p["track_id"].as_u64().unwrap_or(0),
                centroid: [0, 1, 2].map(|k| c[k].as_f64().unwrap()),
            }
        })
        .collect();
    // events.csv holds the same events with the same tracks.
    let csv = std::fs::read_to_string(dir.join("events.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let (pair, id, track) = (col("pair"), col("id"), col("track_id"));
    let rows: BTreeSet<(String, u64, u64)> = lines
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            (
                c[pair].into(),
                c[id].parse().unwrap(),
                c[track].parse().unwrap_or(0),
            )
        })
        .collect();
    let features: BTreeSet<(String, u64, u64)> = found
        .iter()
        .map(|f| (f.pair.clone(), f.id, f.track))
        .collect();
    assert_eq!(rows, features, "events.csv and events.geojson disagree");
    assert_eq!(rows.len(), found.len(), "an event twice");
    found
}

/// Every planted change of truth.json — each consecutive pair's and each baseline pair's — is
/// found in its own pair (`pairs/<before>_<after>`, the events with that `pair` in the campaign's
/// events.geojson) with |V − V_true| ≤ 2 % |V_true|, significant; no other event of the pair
/// above 0.2 m³; and the events of one planted place share one `track_id`, different places
/// different ones: the scar of interval 1 that grows again in interval 3 (truth track 1) is one
/// track over pairs (0, 1), (2, 3) and the baselines (0, 2), (0, 3).
///
/// Matching rule: a planted change matches the nearest found event of its pair of the same kind
/// whose centroid lies within the change's `radius_m` (the circle about its centre that holds
/// its footprint) of its centre, each found event matched at most once (pairs taken by
/// increasing distance). Planted changes are at least 5 m apart and their radii at most 3.2 m,
/// so a centroid can lie in one change's circle only; the centroids found lie within 0.25 m.
///
/// 4 surveys of 300k points (about the synth's default density, 0.1 m spacing: at a third of it
/// the smallest change, a 2 m³ box scar, is measured 6 % off by sampling alone) with
/// `--baseline`: 5 pairs, 20 events.
#[test]
fn synthetic_campaign_finds_every_planted_change_in_its_pair_and_tracks_the_recurring_scar() {
    let tmp = common::tempdir();
    let (truth, _, labels, dir) = synth_and_campaign(tmp.path(), 300_000, &[], &[]);
    judge_campaign(&truth, &labels, &dir);
}

/// The same campaign with every survey after the first misregistered (`synth campaign
/// --misregister`: shifts of 1 to 8 cm, turns of 0.02 to 0.3°, about every axis): each survey is
/// aligned onto the first — the second directly, the later ones chained through their
/// predecessors, with whom they share more stable ground (campaign.json lists the transforms and
/// their routes, every one applied, each turn the planted one) — and every pair passes the same
/// judge: every planted change within 2 %, no stray event, one track a place.
#[test]
fn misregistered_campaign_is_aligned_and_every_pair_is_within_2_percent() {
    let tmp = common::tempdir();
    let (truth, _, labels, dir) = synth_and_campaign(tmp.path(), 300_000, &["--misregister"], &[]);
    let table = json(&dir.join("campaign.json"));
    let epochs = table["epochs"].as_array().unwrap();
    assert_eq!(epochs.len(), truth.epochs.len());
    assert!(epochs[0]["alignment"].is_null(), "{}", epochs[0]);
    for (k, (e, planted)) in epochs.iter().zip(&truth.epochs).enumerate().skip(1) {
        let a = &e["alignment"];
        assert_eq!(a["applied"], true, "{}: {a}", e["label"]);
        // Changes accumulate: survey k shares with the first the ground none of intervals 1..k
        // changed, with its predecessor all but interval k's. So from the third survey on, the
        // route through the predecessors shares more stable ground at its weakest link (the
        // second survey's fit onto the first) and is taken: k → k − 1 → … → 0.
        let route: Vec<u64> = a["route"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .collect();
        let expect: Vec<u64> = if k == 1 {
            vec![1, 0]
        } else {
            (0..=k as u64).rev().collect()
        };
        assert_eq!(route, expect, "{}: {a}", e["label"]);
        // The turn's angle: the fit leaves what the stable ground does not see (the shift along
        // the coast), never a turn, so every turn component is fitted.
        let planted_deg = planted.turn_deg.iter().map(|d| d * d).sum::<f64>().sqrt();
        let fitted = a["rotation_deg"].as_f64().unwrap();
        eprintln!(
            "{}: turn planted {planted_deg:.4}°, fitted {fitted:.4}°, route {}, {} stable core \
             points",
            e["label"], a["route"], a["stable_points"]
        );
        assert!(
            (fitted - planted_deg).abs() < 0.01 * planted_deg + 0.002,
            "{}: turn {fitted}° vs planted {planted_deg}°",
            e["label"]
        );
    }
    judge_campaign(&truth, &labels, &dir);
}

/// Every planted change of `truth` found in its pair of the campaign in `dir`, as the first test
/// above says.
fn judge_campaign(truth: &CampaignTruth, labels: &[String], dir: &Path) {
    let found = campaign_events(dir);
    let mut fails = Vec::new();
    let mut table = String::new();
    // Found track ids per truth track.
    let mut tracks: BTreeMap<u32, BTreeSet<u64>> = BTreeMap::new();
    let mut recurring = Vec::new();
    let mut matched = BTreeSet::new();
    for p in truth.pairs.iter().chain(&truth.baseline_pairs) {
        let label = format!("{}_{}", labels[p.before], labels[p.after]);
        assert!(
            dir.join("pairs").join(&label).join("summary.json").exists(),
            "no pair {label}"
        );
        let mine: Vec<(usize, &Found)> = found
            .iter()
            .enumerate()
            .filter(|(_, f)| f.pair == label)
            .collect();
        let mut cands: Vec<(f64, usize, usize)> = Vec::new();
        for (t, e) in p.events.iter().enumerate() {
            for &(i, f) in &mine {
                let d = dist(f.centroid, e.event.centre);
                if f.kind == e.event.kind && d <= e.event.radius_m {
                    cands.push((d, t, i));
                }
            }
        }
        cands.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut of_truth = vec![None; p.events.len()];
        for (d, t, i) in cands {
            if of_truth[t].is_none() && !matched.contains(&i) {
                of_truth[t] = Some((i, d));
                matched.insert(i);
            }
        }
        for (e, m) in p.events.iter().zip(&of_truth) {
            let (v, what) = (e.event.volume_m3, &e.event.description);
            let Some((i, d)) = *m else {
                fails.push(format!(
                    "{label}: planted {} {what} ({v:+.3} m³ at {:?}, track {}) has no found {} \
                     event within {:.2} m",
                    e.event.kind, e.event.centre, e.track, e.event.kind, e.event.radius_m
                ));
                continue;
            };
            let f = &found[i];
            let rel = (f.volume - v) / v.abs();
            table.push_str(&format!(
                "{label} track {:>2} {v:+8.3} m³ found {:+8.3} m³ ({:+.2} %) {d:.2} m off, \
                 track_id {}: {what}\n",
                e.track,
                f.volume,
                100.0 * rel,
                f.track
            ));
            if rel.abs() > REL_TOL || !f.significant {
                fails.push(format!(
                    "{label}: {what} (true {v:+.4} m³) ↔ event {} ({:+.4} m³, {:+.2} %, \
                     significant {})",
                    f.id,
                    f.volume,
                    100.0 * rel,
                    f.significant
                ));
            }
            tracks.entry(e.track).or_default().insert(f.track);
            if e.track == RECURRING_TRACK {
                recurring.push((label.clone(), f.track));
            }
        }
        for &(i, f) in &mine {
            if !matched.contains(&i) && f.volume.abs() > STRAY_MAX {
                fails.push(format!(
                    "{label}: found {} event {} ({:+.4} m³) at {:?} matches no planted change",
                    f.kind, f.id, f.volume, f.centroid
                ));
            }
        }
    }
    eprint!("{table}");
    assert!(fails.is_empty(), "{}", fails.join("\n"));
    // One place, one track; different places, different tracks.
    for (t, ids) in &tracks {
        assert_eq!(
            ids.len(),
            1,
            "truth track {t} is split over track_ids {ids:?}"
        );
    }
    let ids: Vec<u64> = tracks.values().flatten().copied().collect();
    let distinct: BTreeSet<u64> = ids.iter().copied().collect();
    assert_eq!(
        ids.len(),
        distinct.len(),
        "places share a track: {tracks:?}"
    );
    // The recurring scar: in interval 1's pair, interval 3's and both baselines holding them.
    let pairs: Vec<&str> = recurring.iter().map(|(l, _)| l.as_str()).collect();
    assert_eq!(
        pairs,
        [
            format!("{}_{}", labels[0], labels[1]),
            format!("{}_{}", labels[2], labels[3]),
            format!("{}_{}", labels[0], labels[2]),
            format!("{}_{}", labels[0], labels[3]),
        ],
        "the recurring scar's events"
    );
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Each pair of a synthetic campaign is `talus compare` of its two surveys given the pair's
/// parameters (the values in its summary.json, as flags) and the campaign's core points: the
/// first survey thinned, a core-point unit in the store (`.talus/units/cores/thinned-*`, tiles
/// of the internal format) published with every pair's distances as timeseries.laz, which is
/// the file given to `--core-points`. The campaign is cut into 3 × 4 tiles of its own grid over
/// the four surveys (`--tile-size 12`), compare plans its own (one tile). The registration error
/// and the threshold are left to compare to measure on the pair's stable ground.
///
/// Byte for byte: m3c2.laz, events.geojson, events.csv, event_regions.geojson, view.json,
/// terrain.bin and every mesh. Field by field in summary.json: every parameter's value, the
/// stable ground's measurement and the counts and totals (not: the paths, the core-point file,
/// the spacing measured on compare's own before survey, the tiles, the parameters' sources, the
/// timings).
///
/// Without `--pair-clouds` (the default, issue 46), the same campaign's pairs hold the same files
/// but m3c2.laz, the same bytes but terrain.bin and view.json: terrain.bin is the distances of
/// the full one alone (its last 4 bytes a point) but in the first pair, and view.json names the
/// first pair's for the positions ([`assert_lean_pair`]).
#[test]
fn synthetic_campaign_pairs_are_compares_with_its_parameters_and_core_points() {
    let tmp = common::tempdir();
    let (truth, surveys, labels, dir) = synth_and_campaign(
        tmp.path(),
        60_000,
        &[],
        &["--tile-size", "12", "--pair-clouds"],
    );
    let lean = tmp.path().join("lean");
    ok(&campaign(
        &surveys,
        &lean,
        &["--baseline", "--tile-size", "12"],
    ));
    let first = format!("{}_{}", labels[0], labels[1]);
    for (k, (b, a)) in all_pairs(&truth).into_iter().enumerate() {
        let label = format!("{}_{}", labels[b], labels[a]);
        let shared = (k > 0).then_some(first.as_str());
        assert_lean_pair(
            &label,
            &dir.join("pairs").join(&label),
            &lean.join("pairs").join(&label),
            shared,
        );
    }
    let summary = json(&dir.join("summary.json"));
    assert!(summary["tiles"].as_u64().unwrap() > 1, "one tile");
    let cores = dir.join("timeseries.laz");
    let pairs = all_pairs(&truth);
    assert_eq!(pairs.len(), 5);
    for (b, a) in pairs {
        let label = format!("{}_{}", labels[b], labels[a]);
        let pair = dir.join("pairs").join(&label);
        let mine = json(&pair.join("summary.json"));
        let mut args = parameter_flags(&mine["parameters"]);
        args.extend(["--core-points".into(), cores.to_string_lossy().into_owned()]);
        let out = tmp.path().join(format!("compare-{label}"));
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        ok(&common::run_compare(&surveys[b], &surveys[a], &out, &refs));
        assert_pair_is_compare(&label, &pair, &out);
        assert!(
            pair.join("meshes").read_dir().unwrap().next().is_some(),
            "pair {label}: no mesh"
        );
        let theirs = json(&out.join("summary.json"));
        let values = |s: &Value| -> BTreeMap<String, Value> {
            s["parameters"]
                .as_object()
                .unwrap()
                .iter()
                .map(|(k, v)| (k.clone(), v["value"].clone()))
                .collect()
        };
        assert_eq!(values(&mine), values(&theirs), "pair {label}: parameters");
        for k in [
            "stable",
            "core_points",
            "computed_points",
            "significant_points",
            "kept_points",
            "events",
            "gain_events",
            "loss_events",
            "significant_events",
            "total_gain_m3",
            "total_loss_m3",
        ] {
            assert_eq!(mine[k], theirs[k], "pair {label}: summary.json {k}");
        }
        assert_eq!(
            mine["core_points"], summary["core_points"],
            "pair {label}: not the campaign's core points"
        );
    }
}
