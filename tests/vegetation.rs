//! Vegetation (SPEC.md §4): on `talus synth vegetation` — a cliff with shrubs on its face and
//! beach, grass on its plateau and a tree at its top that grow or are cut between the surveys,
//! beside a boulder beach, a scree cone, one rockfall and one rubble deposit — the real events are
//! measured within 2 %, are never taken for vegetation, and every other event over 0.2 m³ is
//! flagged; vegetation events are listed but left out of the totals (`flag`, the default) or
//! counted (`keep`); the same surveys delivered classified give no vegetation event at all; a
//! campaign keeps vegetation out of its tracks and its magnitude–frequency fit.

mod common;

use std::path::{Path, PathBuf};

use serde_json::Value;

fn json_file(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// `talus synth vegetation --out DIR EXTRA...`: DIR.
fn synth(dir: &Path, extra: &[&str]) -> PathBuf {
    let mut args = vec!["synth", "vegetation", "--out", dir.to_str().unwrap()];
    args.extend_from_slice(extra);
    let o = common::run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    dir.to_path_buf()
}

/// Compare the scene in `data` into `out` with `extra` flags; the events' properties and
/// centroids, and summary.json.
fn compare(data: &Path, out: &Path, extra: &[&str]) -> (Vec<(Value, [f64; 3])>, Value) {
    let o = common::run_compare(
        &data.join("before.laz"),
        &data.join("after.laz"),
        out,
        extra,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fc = json_file(&out.join("events.geojson"));
    let events = fc["features"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let c = f["geometry"]["coordinates"].as_array().unwrap();
            (
                f["properties"].clone(),
                [0, 1, 2].map(|k| c[k].as_f64().unwrap()),
            )
        })
        .collect();
    (events, json_file(&out.join("summary.json")))
}

fn volume(p: &Value) -> f64 {
    p["volume_m3"].as_f64().unwrap_or(0.0)
}

/// For each planted event of `truth`, the index of the found event that measures it: the one
/// with the largest |volume| of the planted sign whose centroid lies within the planted radius
/// plus 1.5 m of the planted centre.
fn matched(truth: &Value, events: &[(Value, [f64; 3])]) -> Vec<usize> {
    truth["events"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            let c: Vec<f64> = t["centre"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            let (v, r) = (
                t["volume_m3"].as_f64().unwrap(),
                t["radius_m"].as_f64().unwrap(),
            );
            (0..events.len())
                .filter(|&i| {
                    let e = &events[i].1;
                    let d = ((e[0] - c[0]).powi(2) + (e[1] - c[1]).powi(2) + (e[2] - c[2]).powi(2))
                        .sqrt();
                    d < r + 1.5 && volume(&events[i].0) * v > 0.0
                })
                .max_by(|&a, &b| {
                    volume(&events[a].0)
                        .abs()
                        .total_cmp(&volume(&events[b].0).abs())
                })
                .unwrap_or_else(|| panic!("planted event {} not found", t["description"]))
        })
        .collect()
}

/// What every run must show: each planted event within 2 % and not vegetation (its fraction
/// under a half: a rubble deposit and a fresh scar are surfaces); `kind` the sign of the volume;
/// returns the planted events' indices.
fn real_events_right(label: &str, truth: &Value, events: &[(Value, [f64; 3])]) -> Vec<usize> {
    let m = matched(truth, events);
    for (t, &i) in truth["events"].as_array().unwrap().iter().zip(&m) {
        let (want, p) = (t["volume_m3"].as_f64().unwrap(), &events[i].0);
        let got = volume(p);
        let err = (got - want) / want.abs();
        println!(
            "{label}: {}: {got:+.3} m³ for {want:+.3} ({:+.2} %), vegetation_fraction {}",
            t["description"],
            100.0 * err,
            p["vegetation_fraction"]
        );
        assert!(
            err.abs() < 0.02,
            "{label}: {} off by {err}",
            t["description"]
        );
        assert_eq!(p["vegetation"], Value::Bool(false), "{label}: {p}");
        assert!(p["vegetation_fraction"].as_f64().unwrap() < 0.5, "{p}");
    }
    for (p, _) in events {
        if let Some(v) = p["volume_m3"].as_f64().filter(|v| *v != 0.0) {
            assert_eq!(
                p["kind"] == "gain",
                v > 0.0,
                "{label}: kind against volume: {p}"
            );
        }
    }
    m
}

/// Every event but the real ones (`real`, their indices) is flagged as vegetation or under
/// 0.2 m³.
fn no_unflagged_event_over_0_2_m3(events: &[(Value, [f64; 3])], real: &[usize]) {
    for (i, (p, _)) in events.iter().enumerate() {
        if !real.contains(&i) && p["vegetation"] == Value::Bool(false) {
            assert!(
                volume(p).abs() <= 0.2,
                "an unflagged event over 0.2 m³: {p}"
            );
        }
    }
}

/// summary.json's totals (gain, loss), asserted within 2 % of the planted ones.
fn totals_right(label: &str, truth: &Value, summary: &Value) -> (f64, f64) {
    let (gain, loss) = (
        truth["total_gain_m3"].as_f64().unwrap(),
        truth["total_loss_m3"].as_f64().unwrap(),
    );
    let (g, l) = (
        summary["total_gain_m3"].as_f64().unwrap(),
        summary["total_loss_m3"].as_f64().unwrap(),
    );
    println!("{label}: totals {g:+.3} / {l:+.3} m³ for {gain:+.3} / {loss:+.3}");
    assert!(((g - gain) / gain).abs() < 0.02 && ((l - loss) / loss).abs() < 0.02);
    (g, l)
}

/// Unclassified surveys: vegetation recognised from its geometry. `flag` (the default) lists
/// the shrubs', grass's and tree's events, flagged, and leaves them out of the totals, which are
/// then the real change's within 2 %; no unflagged event other than the real ones exceeds
/// 0.2 m³. `keep` gives the same events and counts the vegetation's significant volumes too.
#[test]
fn unclassified_vegetation_is_flagged_and_left_out_of_the_totals() {
    let tmp = common::tempdir();
    let data = synth(&tmp.path().join("data"), &[]);
    let truth = json_file(&data.join("truth.json"));
    let (events, summary) = compare(&data, &tmp.path().join("flag"), &[]);
    let real = real_events_right("flag", &truth, &events);
    let flagged: Vec<&Value> = events
        .iter()
        .map(|e| &e.0)
        .filter(|p| p["vegetation"] == Value::Bool(true))
        .collect();
    println!(
        "flag: {} events, {} flagged as vegetation ({:.3} m³ of |V|)",
        events.len(),
        flagged.len(),
        flagged.iter().map(|p| volume(p).abs()).sum::<f64>()
    );
    assert!(flagged.len() >= 5, "the plants' events are flagged");
    no_unflagged_event_over_0_2_m3(&events, &real);
    assert_eq!(summary["vegetation_events"], flagged.len());
    assert_eq!(summary["parameters"]["vegetation"]["value"], "flag");
    let (g, l) = totals_right("flag", &truth, &summary);
    let csv = std::fs::read_to_string(tmp.path().join("flag/events.csv")).unwrap();
    assert!(csv
        .lines()
        .next()
        .unwrap()
        .ends_with("volume_note,vegetation_fraction,vegetation,sign_known"));
    // `vegetation` is the last column but `sign_known`.
    assert_eq!(
        csv.lines()
            .filter(|l| l.ends_with(",true,true") || l.ends_with(",true,false"))
            .count(),
        flagged.len()
    );

    // keep: the same events, and the totals count the vegetation's significant ones.
    let (kept, ks) = compare(&data, &tmp.path().join("keep"), &["--vegetation", "keep"]);
    assert_eq!(kept, events);
    let sig = |sign: f64| -> f64 {
        flagged
            .iter()
            // What the totals count: significant, complete (of known sign) events.
            .filter(|p| {
                p["significant"] == Value::Bool(true)
                    && p["complete"] == Value::Bool(true)
                    && volume(p) * sign > 0.0
            })
            .map(|p| volume(p))
            .sum()
    };
    let kg = ks["total_gain_m3"].as_f64().unwrap();
    let kl = ks["total_loss_m3"].as_f64().unwrap();
    println!("keep: totals {kg:+.3} / {kl:+.3} m³");
    assert!((kg - (g + sig(1.0))).abs() < 1e-9 && (kl - (l + sig(-1.0))).abs() < 1e-9);
    assert!(
        sig(1.0) > 0.5 && sig(-1.0) < -0.5,
        "vegetation moves the totals when kept"
    );
}

/// The same scene delivered classified (ground 2, grass 3, shrubs 4, tree 5): the plants are
/// left out by class, so no event is vegetation, the real ones are right and nothing else is
/// significant.
#[test]
fn classified_delivery_gives_no_vegetation_event() {
    let tmp = common::tempdir();
    let data = synth(&tmp.path().join("data"), &["--classified"]);
    let truth = json_file(&data.join("truth.json"));
    let (events, summary) = compare(&data, &tmp.path().join("res"), &[]);
    let real = real_events_right("classified", &truth, &events);
    assert!(
        events
            .iter()
            .all(|e| e.0["vegetation"] == Value::Bool(false)),
        "{events:?}"
    );
    assert_eq!(summary["vegetation_events"], 0);
    // Nothing but the real change is significant.
    for (i, (p, _)) in events.iter().enumerate() {
        assert!(
            real.contains(&i) || p["significant"] == Value::Bool(false),
            "{p}"
        );
    }
}

/// A campaign of three surveys — the scene's two, then the second again sampled afresh (its
/// leaves resampled, nothing moved): vegetation events keep no track, the fit and its
/// magnitude_frequency.csv hold only the events that count, and the report draws the
/// vegetation apart.
#[test]
fn a_campaign_keeps_vegetation_out_of_tracks_and_the_fit() {
    let tmp = common::tempdir();
    let a = synth(&tmp.path().join("a"), &[]);
    let b = synth(&tmp.path().join("b"), &["--seed", "2"]);
    let surveys = tmp.path().join("surveys");
    std::fs::create_dir_all(&surveys).unwrap();
    for (from, name) in [
        (a.join("before.laz"), "2021-03-01.laz"),
        (a.join("after.laz"), "2021-09-01.laz"),
        (b.join("after.laz"), "2022-03-01.laz"),
    ] {
        std::fs::copy(from, surveys.join(name)).unwrap();
    }
    let out = tmp.path().join("campaign");
    let mut args = vec!["campaign".to_string()];
    for n in ["2021-03-01.laz", "2021-09-01.laz", "2022-03-01.laz"] {
        args.push(surveys.join(n).to_str().unwrap().to_string());
    }
    args.extend(["--out".into(), out.to_str().unwrap().to_string()]);
    let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let o = common::run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fc = json_file(&out.join("events.geojson"));
    let events: Vec<&Value> = fc["features"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| &f["properties"])
        .collect();
    let veg: Vec<&&Value> = events
        .iter()
        .filter(|p| p["vegetation"] == Value::Bool(true))
        .collect();
    let mut per_pair = std::collections::BTreeMap::<String, usize>::new();
    for p in &veg {
        *per_pair
            .entry(p["pair"].as_str().unwrap().into())
            .or_default() += 1;
    }
    println!(
        "campaign: {} events, {} vegetation (per pair: {per_pair:?})",
        events.len(),
        veg.len()
    );
    assert!(veg.len() >= 10, "both pairs' plants flagged");
    // In no track: null (it was 0, which the viewer counted as one more track than the
    // command line's): the tracks the files hold are summary.json's.
    assert!(
        veg.iter().all(|p| p["track_id"].is_null()),
        "vegetation in a track"
    );
    let tracks: std::collections::BTreeSet<u64> = events
        .iter()
        .filter_map(|p| p["track_id"].as_u64())
        .collect();
    let summary = json_file(&out.join("summary.json"));
    assert_eq!(tracks.len() as u64, summary["tracks"].as_u64().unwrap());
    assert!(!tracks.contains(&0));
    // events.csv likewise: an empty track_id (the 4th column, before any quoted text).
    let csv = std::fs::read_to_string(out.join("events.csv")).unwrap();
    assert_eq!(
        csv.lines().next().unwrap().split(',').nth(3),
        Some("track_id")
    );
    let untracked = csv
        .lines()
        .skip(1)
        .filter(|r| r.split(',').nth(3) == Some(""))
        .count();
    assert_eq!(untracked, veg.len());
    // The fit's values: significant events that count, of both consecutive pairs.
    let counted = events
        .iter()
        .filter(|p| {
            p["vegetation"] == Value::Bool(false)
                && p["significant"] == Value::Bool(true)
                && p["volume_m3"].is_number()
        })
        .count();
    let mf = std::fs::read_to_string(out.join("magnitude_frequency.csv")).unwrap();
    assert_eq!(mf.lines().count() - 1, counted, "{mf}");
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains("class=\"event vegetation\""));
    assert!(report.contains("Vegetation (green"));
}

/// `--vegetation remove`: the vegetation-like points are dropped before M3C2, so the plants'
/// events are gone (what is left of them stays under 0.2 m³ unflagged), the real events are
/// right and the totals are the real change's within 2 %. summary.json counts the points
/// removed from each survey. The cleared surveys do not depend on the tiling: 12 m tiles give
/// the one-tile run's events and m3c2.laz byte for byte.
#[test]
fn removed_vegetation_leaves_the_real_change() {
    let tmp = common::tempdir();
    let data = synth(&tmp.path().join("data"), &[]);
    let truth = json_file(&data.join("truth.json"));
    let whole = tmp.path().join("whole");
    let (events, summary) = compare(&data, &whole, &["--vegetation", "remove"]);
    let real = real_events_right("remove", &truth, &events);
    no_unflagged_event_over_0_2_m3(&events, &real);
    let removed: Vec<u64> = summary["vegetation_removed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    println!(
        "remove: {} events ({} flagged), points removed {removed:?}",
        events.len(),
        events
            .iter()
            .filter(|e| e.0["vegetation"] == Value::Bool(true))
            .count()
    );
    // The plants hold about 25,000 points per survey; the cut shrub's are only in the first.
    assert!(
        removed.iter().all(|&n| (15_000..40_000).contains(&n)),
        "{removed:?}"
    );
    totals_right("remove", &truth, &summary);

    let tiled = tmp.path().join("tiled");
    let (again, s2) = compare(
        &data,
        &tiled,
        &["--vegetation", "remove", "--tile-size", "12"],
    );
    assert!(s2["tiles"].as_u64().unwrap() > 4, "{}", s2["tiles"]);
    assert_eq!(again, events);
    for f in ["m3c2.laz", "events.csv", "event_regions.geojson"] {
        assert!(
            std::fs::read(whole.join(f)).unwrap() == std::fs::read(tiled.join(f)).unwrap(),
            "{f} differs with 12 m tiles"
        );
    }
}

/// Issue 44, item 6: `--vegetation remove` on a cliff without plants drops points (edges and
/// creases of the rock look scattered too) and so shifts the totals; the run says how many of
/// each survey and by what rule, the counts those of summary.json.
#[test]
fn removing_vegetation_says_what_it_removed_and_why() {
    let tmp = common::tempdir();
    let (before, after) = common::synth_cliff(tmp.path(), 20_000);
    let out = tmp.path().join("out");
    let o = common::run_compare(&before, &after, &out, &["--vegetation", "remove"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let summary = json_file(&out.join("summary.json"));
    let removed = &summary["vegetation_removed"];
    let (b, a) = (removed[0].as_u64().unwrap(), removed[1].as_u64().unwrap());
    assert!(b > 0 && a > 0, "{removed}");
    let note = err
        .lines()
        .find(|l| l.starts_with("talus: --vegetation remove left out"))
        .unwrap_or_else(|| panic!("no note: {err}"));
    for needle in [
        format!("{b} of 20000 points"),
        format!("{a} of 20000 points"),
        "not planar in balls of 4 and 8 point spacings".into(),
        "edges and creases of the terrain".into(),
    ] {
        assert!(note.contains(&needle), "'{needle}' not in: {note}");
    }
}
