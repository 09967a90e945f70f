//! Uncertainties are claims (issue "Volumes that add up on real surveys", items 3 and 4): tested
//! as statistics over many events with known truth. The `events` scene plants a dozen changes of
//! 0.2–6 m³ (boxes raised and dug, spherical caps and dents, cos² bumps and dents) on undulating
//! ground with 1 cm noise; its seed draws the shapes, sizes and places, so seeds 1–8 give 96
//! different events. For each: is the truth inside V ± U (U = volume_uncertainty_m3, a 95 %
//! half-width), and z = (V − V_true) / (U / 1.96). Asked: ≥ 85 % inside, and RMS(z) ≥ 0.3
//! (intervals not grossly wider than the errors). The same with a registration error in epoch 2
//! (2 cm vertical, 1 cm horizontal). And the registration error measured on the stable scene.
//! Run with `--nocapture` for the figures.

mod common;

use std::path::Path;

use serde_json::Value;
use talus::synth::Truth;

fn read_json(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// Synthesize `scene` (with `extra` synth options) into `dir` and compare it with defaults.
fn run(scene: &str, extra: &[&str], dir: &Path) -> (Truth, Value, Value) {
    run_with(scene, extra, dir, &[])
}

/// [`run`], the comparison given `args`.
fn run_with(scene: &str, extra: &[&str], dir: &Path, compare: &[&str]) -> (Truth, Value, Value) {
    let data = dir.join("data");
    let mut args = vec!["synth", scene, "--out", data.to_str().unwrap()];
    args.extend_from_slice(extra);
    let o = common::run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let res = dir.join("res");
    let o = common::run_compare(
        &data.join("before.laz"),
        &data.join("after.laz"),
        &res,
        compare,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let truth: Truth =
        serde_json::from_str(&std::fs::read_to_string(data.join("truth.json")).unwrap()).unwrap();
    (
        truth,
        read_json(&res.join("events.geojson")),
        read_json(&res.join("summary.json")),
    )
}

/// (V_true, V, U) of every planted event, matched to the found event of its kind nearest to its
/// centre (within its radius, at least 3 m); panics on a planted event not found.
fn matched(truth: &Truth, events: &Value, label: &str) -> Vec<(f64, f64, f64)> {
    let found = events["features"].as_array().unwrap();
    truth
        .events
        .iter()
        .map(|t| {
            let best = found
                .iter()
                .filter(|f| f["properties"]["kind"] == t.kind.as_str())
                .map(|f| {
                    let c = &f["geometry"]["coordinates"];
                    let d = (c[0].as_f64().unwrap() - t.centre[0])
                        .hypot(c[1].as_f64().unwrap() - t.centre[1]);
                    (d, f)
                })
                .filter(|(d, _)| *d <= t.radius_m.max(3.0))
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap_or_else(|| {
                    panic!(
                        "{label}: planted {} ({:+.3} m³) not found",
                        t.description, t.volume_m3
                    )
                });
            let p = &best.1["properties"];
            (
                t.volume_m3,
                p["volume_m3"].as_f64().unwrap(),
                p["volume_uncertainty_m3"].as_f64().unwrap(),
            )
        })
        .collect()
}

/// Seeds 1–8 of the `events` scene with `extra` synth options, two at a time.
fn campaign_of_seeds(extra: &[&str]) -> Vec<(f64, f64, f64)> {
    let tmp = common::tempdir();
    let seeds: Vec<u64> = (1..=8).collect();
    let mut all = Vec::new();
    for pair in seeds.chunks(2) {
        let runs: Vec<Vec<(f64, f64, f64)>> = std::thread::scope(|s| {
            let handles: Vec<_> = pair
                .iter()
                .map(|&seed| {
                    let dir = tmp.path().join(format!("seed{seed}"));
                    s.spawn(move || {
                        let seed_s = seed.to_string();
                        let mut args = vec!["--seed", seed_s.as_str()];
                        args.extend_from_slice(extra);
                        let (truth, events, _) = run("events", &args, &dir);
                        matched(&truth, &events, &format!("seed {seed}"))
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        all.extend(runs.into_iter().flatten());
    }
    all
}

fn judge(label: &str, rows: &[(f64, f64, f64)]) {
    let inside = rows.iter().filter(|(t, v, u)| (v - t).abs() <= *u).count();
    let z: Vec<f64> = rows.iter().map(|(t, v, u)| (v - t) / (u / 1.96)).collect();
    let rms = (z.iter().map(|x| x * x).sum::<f64>() / z.len() as f64).sqrt();
    let share = inside as f64 / rows.len() as f64;
    let worst = rows
        .iter()
        .map(|(t, v, _)| ((v - t) / t).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "{label}: {} events, truth inside V ± U for {inside} ({:.1} %), RMS of (V − V_true)/(U/1.96) {rms:.3}, largest relative error {:.2} %",
        rows.len(),
        100.0 * share,
        100.0 * worst
    );
    for (t, v, u) in rows {
        if (v - t).abs() > *u {
            eprintln!("  outside: true {t:+.4} m³, measured {v:+.4} ± {u:.4}");
        }
    }
    assert!(rows.len() >= 90, "{label}: {} events", rows.len());
    assert!(
        share >= 0.85,
        "{label}: truth inside for {:.1} %",
        100.0 * share
    );
    assert!(rms >= 0.3, "{label}: RMS z {rms} (intervals too wide)");
}

#[test]
fn uncertainties_cover_the_truth_over_96_events() {
    judge("events, seeds 1-8", &campaign_of_seeds(&[]));
}

#[test]
fn uncertainties_cover_the_truth_with_a_registration_error() {
    judge(
        "events, seeds 1-8, epoch 2 shifted 1 cm in x and 2 cm in z",
        &campaign_of_seeds(&["--shift", "0.01,0,0.02"]),
    );
}

/// Item 4: the stable scene (independent resampling, 1 cm noise; its epoch 2 is 5 mm higher)
/// gives no event above 0.2 m³ and measures its 5 mm shift; shifted 2.5 cm more (3 cm in all),
/// the registration error is measured within ±30 %, still without an event above 0.2 m³ (the
/// measurement itself: `--align off`; aligned, see the next test).
#[test]
fn the_registration_error_is_measured_on_the_stable_scene() {
    let tmp = common::tempdir();
    for (extra, want) in [(vec![], 0.005), (vec!["--shift", "0,0,0.025"], 0.03)] {
        let (_, events, summary) = run_with(
            "stable",
            &extra,
            &tmp.path().join(format!("{want}")),
            &["--align", "off"],
        );
        let reg = &summary["parameters"]["reg_error"];
        let got = reg["value"].as_f64().unwrap();
        eprintln!(
            "stable scene, true shift {want} m: reg_error {got:.4} m ({})",
            reg["source"].as_str().unwrap()
        );
        assert!(reg["source"].as_str().unwrap().starts_with("measured"));
        assert!((got - want).abs() <= 0.3 * want, "{got} vs {want}");
        for f in events["features"].as_array().unwrap() {
            let v = f["properties"]["volume_m3"].as_f64().unwrap_or(0.0);
            assert!(v.abs() <= 0.2, "event of {v} m³ on the stable scene");
        }
    }
}

/// The same shifts with the alignment (the default): removed, not only measured. The fitted
/// vertical shift is the planted one within 4 of its standard errors (+1 mm, the coordinate
/// quantum), `reg_error` is then the residual (below a fifth of the shift), and still no event
/// above 0.2 m³.
#[test]
fn the_registration_error_is_removed_on_the_stable_scene() {
    let tmp = common::tempdir();
    for (extra, want) in [(vec![], 0.005), (vec!["--shift", "0,0,0.025"], 0.03)] {
        let (_, events, summary) = run("stable", &extra, &tmp.path().join(format!("{want}")));
        let a = &summary["alignment"];
        eprintln!("stable scene, true shift {want} m: {a}");
        assert_eq!(a["applied"], true, "{a}");
        let tz = a["translation"][2].as_f64().unwrap();
        let sd = a["translation_sd"][2].as_f64().unwrap();
        assert!(
            (tz - want).abs() <= 4.0 * sd + 0.001,
            "{tz} ± {sd} vs {want}"
        );
        let reg = summary["parameters"]["reg_error"]["value"]
            .as_f64()
            .unwrap();
        assert!(
            reg <= 0.2 * want,
            "reg_error {reg} after alignment, shift {want}"
        );
        for f in events["features"].as_array().unwrap() {
            let v = f["properties"]["volume_m3"].as_f64().unwrap_or(0.0);
            assert!(v.abs() <= 0.2, "event of {v} m³ on the stable scene");
        }
    }
}
