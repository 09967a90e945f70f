//! `talus campaign` (issue "Campaigns", SPEC.md §5) on the St Leonards beach campaign (six UAV
//! surveys, ../shared/data/st-leonards) and on bad input:
//! - each pair's results are `talus compare`'s on that pair, given the campaign's parameters and
//!   core points (byte for byte);
//! - appending a survey: a run on five surveys, then on six with `--resume`, computes only what
//!   the sixth adds (every unit of the first run is reused, untouched) and ends with the outputs
//!   of a run on all six at once;
//! - SIGKILL at random moments then `--resume` gives the outputs of an uninterrupted run;
//! - bad input (no date, one date twice, an empty folder, tiles in two CRSs, a survey off the
//!   site): exit 2, one line naming the file and the problem, nothing written.
//!
//! "The outputs" are every file of DIR but the timings a run records of itself (summary.json's
//! stage seconds, the `seconds` column of campaign.csv/json, report.html's run-time column),
//! compared byte for byte.

mod common;
mod pipeline_common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Instant;

use common::Rng;
use pipeline_common::unit_times;

fn surveys() -> Option<Vec<PathBuf>> {
    let dir = common::shared_data("st-leonards")?;
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "laz"))
        .collect();
    v.sort();
    assert_eq!(v.len(), 6);
    Some(v)
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

#[test]
fn each_pair_is_a_compare_of_its_surveys_with_the_campaigns_parameters_and_core_points() {
    let Some(s) = surveys() else { return };
    let tmp = common::tempdir();
    let dir = tmp.path().join("campaign");
    ok(&campaign(&s[..4], &dir, &[]));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    let p = &summary["parameters"];
    let v = |k: &str| p[k]["value"].to_string();
    let params: Vec<String> = [
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
    .flat_map(|k| [format!("--{}", k.replace('_', "-")), v(k)])
    .chain([
        "--orientation".into(),
        p["orientation"]["value"].as_str().unwrap().into(),
    ])
    .collect();
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
        let o = common::run_compare(&s[k], &s[k + 1], &out, &args);
        ok(&o);
        let (mine, theirs) = (outputs(&pair), outputs(&out));
        for name in [
            "m3c2.laz",
            "events.geojson",
            "events.csv",
            "event_regions.geojson",
            "view.json",
            "terrain.bin",
        ] {
            assert!(
                mine[name] == theirs[name],
                "pair {label}: {name} differs from compare's"
            );
        }
        let meshes = |m: &BTreeMap<String, Vec<u8>>| -> Vec<String> {
            m.keys()
                .filter(|n| n.starts_with("meshes/"))
                .cloned()
                .collect()
        };
        assert_eq!(meshes(&mine), meshes(&theirs));
        for n in meshes(&mine) {
            assert!(mine[&n] == theirs[&n], "pair {label}: {n} differs");
        }
    }
}

#[test]
fn appending_a_survey_computes_only_what_it_adds() {
    let Some(s) = surveys() else { return };
    let tmp = common::tempdir();
    let dir = tmp.path().join("appended");
    let t = Instant::now();
    ok(&campaign(&s[..5], &dir, &[]));
    let five = t.elapsed();
    let kinds = [
        "tiling", "cores", "m3c2", "stable", "events", "volumes", "outputs",
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
    let Some(s) = surveys() else { return };
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

/// Write a small cloud of `n` points around (x0, y0) at `path` (LAS, in WGS 84 / UTM zone
/// `zone` N when given).
fn cloud(path: &Path, x0: f64, y0: f64, zone: Option<u32>) {
    let mut rng = Rng::new(5);
    let pts: Vec<[f64; 3]> = (0..2000)
        .map(|_| {
            [
                x0 + 20.0 * rng.uniform(),
                y0 + 20.0 * rng.uniform(),
                100.0 + 0.01 * rng.normal(),
            ]
        })
        .collect();
    let crs = talus::io::Crs {
        wkt: zone.map(|z| {
            talus::synth::UTM33N_WKT
                .replace("zone 33N", &format!("zone {z}N"))
                .replace("32633", &format!("326{z}"))
        }),
        ..Default::default()
    };
    let mut w = talus::io::las_out::ResultWriter::create(path, &crs, &[], common::OFFSET).unwrap();
    for p in &pts {
        w.write(*p, &[]).unwrap();
    }
    w.finish().unwrap();
}

fn refused(o: &std::process::Output, names: &Path, what: &str, out: &Path) {
    let msg = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{msg}");
    assert_eq!(msg.lines().count(), 1, "{msg}");
    assert!(msg.contains(names.to_str().unwrap()), "{msg}");
    assert!(msg.contains(what), "{msg}");
    assert!(!out.exists(), "{} was written", out.display());
}

#[test]
fn bad_campaign_input_is_refused_naming_the_file() {
    let tmp = common::tempdir();
    let d = tmp.path();
    let (x, y) = (common::OFFSET[0], common::OFFSET[1]);
    cloud(&d.join("a_20200101.las"), x, y, None);
    cloud(&d.join("b_20200401.las"), x, y, None);
    cloud(&d.join("c_undated.las"), x, y, None);
    cloud(&d.join("d_2020-04-01.las"), x, y, None);
    cloud(&d.join("far_20200701.las"), x + 5000.0, y, None);
    let out = d.join("out");
    let p = |n: &str| d.join(n);
    // No date, no config entry.
    let o = campaign(&[p("a_20200101.las"), p("c_undated.las")], &out, &[]);
    refused(&o, &p("c_undated.las"), "no date", &out);
    // Two surveys of one date.
    let o = campaign(
        &[
            p("a_20200101.las"),
            p("b_20200401.las"),
            p("d_2020-04-01.las"),
        ],
        &out,
        &[],
    );
    refused(&o, &p("d_2020-04-01.las"), "2020-04-01", &out);
    // A folder with no point cloud.
    let empty = d.join("flight_20200801");
    std::fs::create_dir(&empty).unwrap();
    std::fs::write(empty.join("readme.txt.md"), b"notes").unwrap();
    let o = campaign(&[p("a_20200101.las"), empty.clone()], &out, &[]);
    refused(&o, &empty, "no point cloud", &out);
    // Tiles of one survey in two CRSs.
    let tiles = d.join("tiles_20200901");
    std::fs::create_dir(&tiles).unwrap();
    cloud(&tiles.join("t1.las"), x, y, Some(33));
    cloud(&tiles.join("t2.las"), x + 20.0, y, Some(34));
    let o = campaign(&[p("a_20200101.las"), tiles.clone()], &out, &[]);
    refused(&o, &tiles.join("t2.las"), "CRS", &out);
    // A survey that does not overlap the first.
    let o = campaign(&[p("a_20200101.las"), p("far_20200701.las")], &out, &[]);
    refused(&o, &p("far_20200701.las"), "does not overlap", &out);
    // A config entry dates an undated survey (and the campaign runs).
    let cfg = d.join("campaign.toml");
    std::fs::write(
        &cfg,
        format!(
            "[[epoch]]\npath = \"{}\"\ndate = \"2020-02-15\"\nlabel = \"feb\"\n",
            p("c_undated.las").display()
        ),
    )
    .unwrap();
    let o = campaign(
        &[p("a_20200101.las"), p("c_undated.las"), p("b_20200401.las")],
        &out,
        &["--config", cfg.to_str().unwrap()],
    );
    ok(&o);
    assert!(out.join("pairs/20200101_feb/summary.json").exists());
    assert!(out.join("pairs/feb_20200401/summary.json").exists());
}
