//! What a campaign refuses and what it writes: bad input named, forty-one and four hundred
//! surveys, summary.json's stable areas and wall time, timeseries.parquet read by pyarrow.

use super::*;

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

/// Issue "Change of any depth", item 4: the 41-survey campaign of 500k points per survey (0.26 m
/// spacing), defaults only. Every planted event of every consecutive pair is found, complete,
/// and within 5 % of its truth — or, where the event's own 95 % interval is wider than 5 % of its
/// volume (a box scar 2.2 m wide sampled every 0.26 m: where the points fall on its edges moves
/// the volume by ±6 %, see `volume::Region::step_variance`), within that interval. The deposit
/// 2 m in front of the face foot in 2024-09-01 → 2024-12-01 was +39 % before the volume left out
/// the face that both surveys hold (`volume::axis::unchanged_walls`).
#[test]
fn forty_one_surveys_every_planted_event_within_5_percent() {
    let tmp = common::tempdir();
    let data = tmp.path().join("data");
    let truth = synth_campaign(&data, 41, 500_000, &[]);
    let (surveys, labels) = surveys_of(&truth, &data);
    let dir = tmp.path().join("campaign");
    ok(&campaign(&surveys, &dir, &[]));
    let fc = json(&dir.join("events.geojson"));
    let found: Vec<&Value> = fc["features"].as_array().unwrap().iter().collect();
    let (mut fails, mut errors) = (Vec::new(), Vec::new());
    for p in &truth.pairs {
        let label = format!("{}_{}", labels[p.before], labels[p.after]);
        for e in &p.events {
            let t = &e.event;
            let best = found
                .iter()
                .filter(|f| {
                    let q = &f["properties"];
                    q["pair"] == label.as_str() && q["kind"] == t.kind.as_str()
                })
                .map(|f| {
                    let c = &f["geometry"]["coordinates"];
                    (dist([0, 1, 2].map(|k| c[k].as_f64().unwrap()), t.centre), f)
                })
                .filter(|(d, _)| *d <= t.radius_m)
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let Some((_, f)) = best else {
                fails.push(format!("{label}: {} not found", t.description));
                continue;
            };
            let q = &f["properties"];
            let v = q["volume_m3"].as_f64().unwrap();
            let u = q["volume_uncertainty_m3"].as_f64().unwrap();
            let rel = (v - t.volume_m3) / t.volume_m3.abs();
            errors.push(rel.abs());
            let what = format!(
                "{label}: {} {:+.3} m³ found {v:+.3} ± {u:.3} ({:+.1} %)",
                t.description,
                t.volume_m3,
                100.0 * rel
            );
            if q["complete"] != true {
                fails.push(format!("{what}: incomplete ({})", q["volume_note"]));
            }
            let resolved = u <= 0.05 * t.volume_m3.abs();
            if rel.abs() > 0.05 && (resolved || (v - t.volume_m3).abs() > u) {
                fails.push(format!("{what}: beyond 5 % and beyond its interval"));
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let median = errors.get(errors.len() / 2).copied().unwrap_or(f64::NAN);
    eprintln!(
        "41 surveys: {} planted events matched, median |error| {:.2} %, worst {:.1} %",
        errors.len(),
        100.0 * median,
        100.0 * errors.last().copied().unwrap_or(f64::NAN)
    );
    assert!(median <= 0.01, "median |error| {:.2} %", 100.0 * median);
    assert!(fails.is_empty(), "{}", fails.join("\n"));
}

/// Issue 44, item 5: a campaign's refusals say what is wrong — two `[[epoch]]` entries with one
/// label (were "surveyed on one date"), a label that is another survey's date label, the same
/// file given twice (was "two surveys of one date"), an impossible date in a name (was "no date
/// in the name").
#[test]
fn campaign_refusals_say_what_is_wrong() {
    let tmp = common::tempdir();
    let d = tmp.path();
    let (x, y) = (common::OFFSET[0], common::OFFSET[1]);
    for name in [
        "a_20200101.las",
        "b_20200401.las",
        "e_20210230.las",
        "u1.las",
        "u2.las",
    ] {
        cloud(&d.join(name), x, y, None);
    }
    let out = d.join("out");
    let p = |n: &str| d.join(n);
    let o = campaign(&[p("a_20200101.las"), p("e_20210230.las")], &out, &[]);
    refused(
        &o,
        &p("e_20210230.las"),
        "20210230 (2021-02 has 28 days), is not a date",
        &out,
    );
    let o = campaign(
        &[
            p("a_20200101.las"),
            p("b_20200401.las"),
            p("a_20200101.las"),
        ],
        &out,
        &[],
    );
    refused(&o, &p("a_20200101.las"), "given twice", &out);
    let cfg = d.join("campaign.toml");
    let entry = |f: &str, date: &str, label: &str| {
        format!(
            "[[epoch]]\npath = \"{}\"\ndate = \"{date}\"\nlabel = \"{label}\"\n",
            p(f).display()
        )
    };
    std::fs::write(
        &cfg,
        entry("u1.las", "2020-02-01", "x") + &entry("u2.las", "2020-03-01", "x"),
    )
    .unwrap();
    let args = ["--config", cfg.to_str().unwrap()];
    let o = campaign(
        &[p("a_20200101.las"), p("u1.las"), p("u2.las")],
        &out,
        &args,
    );
    refused(&o, &cfg, "label 'x' names two surveys", &out);
    assert!(!String::from_utf8_lossy(&o.stderr).contains("surveyed on"));
    std::fs::write(
        &cfg,
        entry("u1.las", "2020-02-01", "20200101") + &entry("u2.las", "2020-03-01", "y"),
    )
    .unwrap();
    let o = campaign(
        &[p("a_20200101.las"), p("u1.las"), p("u2.las")],
        &out,
        &args,
    );
    refused(&o, &cfg, "label '20200101'", &out);
    assert!(String::from_utf8_lossy(&o.stderr).contains("a_20200101.las's label (its date"));
}

/// Issue 44, item 9: a campaign's summary.json records where its stable ground came from
/// (`--stable` and its file, or the distances), and its `seconds` is the run's wall time — it
/// was the sum of the pairs' stage times, which counts a survey's tiling once per pair it is in
/// (9.3 s for a 4.4 s run of 3 surveys with --baseline).
#[test]
fn campaign_summary_records_stable_areas_and_wall_time() {
    let tmp = common::tempdir();
    let data = tmp.path().join("data");
    synth_campaign(&data, 3, 100_000, &[]);
    let mut surveys: Vec<PathBuf> = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "laz"))
        .collect();
    surveys.sort();
    let out = tmp.path().join("out");
    let t = Instant::now();
    ok(&campaign(&surveys, &out, &["--baseline"]));
    let wall = t.elapsed().as_secs_f64();
    let summary = json(&out.join("summary.json"));
    let seconds = summary["seconds"].as_f64().unwrap();
    assert!(
        seconds <= wall && seconds >= 0.5 * wall,
        "seconds {seconds} for a run of {wall:.3} s"
    );
    assert_eq!(
        summary["stable"]["source"], "automatic",
        "{}",
        summary["stable"]
    );
    // With --stable: the file named.
    let areas = tmp.path().join("stable.geojson");
    std::fs::write(
        &areas,
        r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},
           "geometry":{"type":"Polygon","coordinates":[[[500000,4999974],[500031,4999974],
           [500031,5000010],[500000,5000010],[500000,4999974]]]}}]}"#,
    )
    .unwrap();
    let out2 = tmp.path().join("out2");
    ok(&campaign(
        &surveys,
        &out2,
        &["--stable", areas.to_str().unwrap()],
    ));
    let stable = &json(&out2.join("summary.json"))["stable"];
    assert_eq!(stable["source"], "user", "{stable}");
    assert_eq!(
        stable["file"].as_str().unwrap(),
        areas.canonicalize().unwrap().to_str().unwrap()
    );
    assert_eq!(stable["polygons"], 1);
}

/// The distance columns of a time series: `d_<before>_<after>` per pair of `pairs`, of surveys
/// labelled `labels`.
fn distance_columns(pairs: &[(usize, usize)], labels: &[String]) -> Vec<String> {
    pairs
        .iter()
        .map(|&(b, a)| format!("d_{}_{}", labels[b], labels[a]))
        .collect()
}

/// What tests/py/read_timeseries.py found, checked: every value compared agreed; the Parquet's
/// columns are x, y, z (required, DOUBLE) and `names` (nullable, FLOAT), in as many rows as the
/// campaign's core points; `created_by` and the key-value metadata (version, the CRS of the
/// synthetic surveys, each pair's column, labels and dates).
fn assert_timeseries(r: &Value, dir: &Path, names: &[String], truth: &CampaignTruth) {
    assert_eq!(
        r["mismatches"],
        serde_json::json!([]),
        "{}",
        r["mismatches"]
    );
    let columns: Vec<&str> = r["columns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    let want: Vec<&str> = ["x", "y", "z"]
        .into_iter()
        .chain(names.iter().map(String::as_str))
        .collect();
    assert_eq!(columns, want);
    assert_eq!(r["types"], serde_json::json!(["double", "float"]));
    let nullable: Vec<bool> = (0..columns.len()).map(|c| c >= 3).collect();
    assert_eq!(r["nullable"], serde_json::json!(nullable));
    let summary = json(&dir.join("summary.json"));
    assert_eq!(r["rows"], summary["core_points"]);
    assert_eq!(r["laz"]["points"], summary["core_points"]);
    assert_eq!(r["nulls"]["x"], 0);
    let version = env!("CARGO_PKG_VERSION");
    assert_eq!(r["created_by"], format!("talus version {version}").as_str());
    let meta = &r["metadata"];
    assert_eq!(meta["talus:version"], version);
    assert_eq!(meta["talus:crs_epsg"], truth.crs_epsg.to_string().as_str());
    assert_eq!(meta["talus:crs_wkt"], truth.crs_wkt.as_str());
    let pairs: Value = serde_json::from_str(meta["talus:pairs"].as_str().unwrap()).unwrap();
    let pairs = pairs.as_array().unwrap();
    assert_eq!(pairs.len(), names.len());
    for (p, name) in pairs.iter().zip(names) {
        assert_eq!(p["column"], name.as_str());
        let (b, a) = name[2..].split_once('_').unwrap();
        assert_eq!((&p["before"], &p["after"]), (&b.into(), &a.into()), "{p}");
        let date = |l: &str| format!("{}-{}-{}", &l[..4], &l[4..6], &l[6..]);
        assert_eq!(p["before_date"], date(b).as_str());
        assert_eq!(p["after_date"], date(a).as_str());
    }
}

/// Issue 46, item 3: timeseries.parquet holds timeseries.laz's core points and distances, and
/// each pair's m3c2.laz distances (`--pair-clouds`), read by independent readers (pyarrow,
/// laspy: tests/py/read_timeseries.py) and compared bit for bit, a null exactly where the LAS
/// has NaN (a 0.3 m half-length leaves the deeper changes beyond reach: nulls in every pair).
/// The consecutive and baseline pairs are columns in the campaign's pair order, the LAS's
/// dimensions the same; summary.json says the LAS holds the distances. Without --pair-clouds,
/// each pair's terrain.bin holds the column's values.
#[test]
fn timeseries_parquet_holds_the_laz_values_read_by_pyarrow_and_laspy() {
    let Some(py) = common::laspy::pyarrow_python() else {
        return;
    };
    let tmp = common::tempdir();
    let (truth, surveys, labels, dir) = synth_and_campaign(
        tmp.path(),
        30_000,
        &[],
        &["--cyl-halflen", "0.3", "--pair-clouds"],
    );
    let pairs = all_pairs(&truth);
    // The plan's order: the consecutive pairs, then the baseline ones.
    let names = distance_columns(&pairs, &labels);
    let r = common::laspy::read_timeseries(&py, &dir, true, None);
    assert_timeseries(&r, &dir, &names, &truth);
    assert_eq!(r["laz"]["extra_dims"], serde_json::json!(names));
    let rows = r["rows"].as_u64().unwrap();
    assert_eq!(r["compared"]["laz"], rows * (3 + names.len() as u64));
    assert_eq!(r["compared"]["pairs"], rows * names.len() as u64);
    for n in &names {
        assert!(r["nulls"][n].as_u64().unwrap() > 0, "{n}: no null");
    }
    let summary = json(&dir.join("summary.json"));
    assert_eq!(summary["timeseries"]["laz_distances"], true);
    // The same campaign without --pair-clouds: its pairs' terrain.bin (the time-series columns'
    // files but the first's) hold the same distances, NaN where the Parquet has null.
    let lean = tmp.path().join("lean");
    ok(&campaign(
        &surveys,
        &lean,
        &["--baseline", "--cyl-halflen", "0.3"],
    ));
    let r = common::laspy::read_timeseries(&py, &lean, true, None);
    assert_timeseries(&r, &lean, &names, &truth);
    assert_eq!(r["compared"]["terrain"], rows * names.len() as u64);
    assert_eq!(r["compared"]["pairs"], 0);
}

/// Issue 46, item 3: a campaign of 401 surveys (400 pairs, more than the 341 whose extra-bytes
/// descriptors fit a LAS VLR) writes timeseries.parquet with 400 distance columns, which pyarrow
/// reads, each bit for bit its pair's distances in the viewer's terrain.bin (the pairs hold no
/// m3c2.laz: no `--pair-clouds`; the positions once, in the first pair's) at the same core
/// points, and the
/// first three the dimensions of the timeseries.laz of a campaign of the first four surveys;
/// its timeseries.laz holds the core points only, and laspy reads it; summary.json says so.
/// About 30 s in release (the surveys 5 s, the campaign 20 s).
#[test]
fn four_hundred_pairs_in_parquet_columns_and_a_laz_of_core_points_readers_read() {
    let Some(py) = common::laspy::pyarrow_python() else {
        return;
    };
    let t = Instant::now();
    let tmp = common::tempdir();
    let data = tmp.path().join("data");
    let truth = synth_campaign(&data, 401, 2000, &[]);
    let made = t.elapsed().as_secs_f64();
    let (surveys, labels) = surveys_of(&truth, &data);
    let dir = tmp.path().join("campaign");
    ok(&campaign(&surveys, &dir, &["--align", "off"]));
    let ran = t.elapsed().as_secs_f64() - made;
    let small = tmp.path().join("four");
    ok(&campaign(&surveys[..4], &small, &["--align", "off"]));
    let pairs: Vec<(usize, usize)> = (1..401).map(|k| (k - 1, k)).collect();
    let names = distance_columns(&pairs, &labels);
    let r = common::laspy::read_timeseries(&py, &dir, true, Some(&small));
    assert_timeseries(&r, &dir, &names, &truth);
    let rows = r["rows"].as_u64().unwrap();
    assert!(rows > 100, "{rows} core points");
    assert_eq!(r["compared"]["terrain"], rows * 400);
    assert!(!dir
        .join("pairs")
        .join(&names[1][2..])
        .join("m3c2.laz")
        .exists());
    assert_eq!(r["compared"]["against"], rows * 3);
    // The LAS: the core points alone (compared with the Parquet's x, y, z).
    assert_eq!(r["laz"]["extra_dims"], serde_json::json!([]));
    assert_eq!(r["compared"]["laz"], rows * 3);
    let summary = json(&dir.join("summary.json"));
    assert_eq!(summary["timeseries"]["laz_distances"], false);
    let note = summary["timeseries"]["laz"].as_str().unwrap();
    assert!(
        note.contains("core points only") && note.contains("341"),
        "{note}"
    );
    eprintln!(
        "400 pairs: {rows} core points; surveys {made:.1} s, campaign {ran:.1} s, all {:.1} s",
        t.elapsed().as_secs_f64()
    );
}
