//! `talus synth campaign`: its truths, layout, files and dates, and its command line.

use super::*;

/// The pair (before, after) of campaign `m`.
fn pair(m: &CampaignModel, before: usize, after: usize) -> PairModel {
    m.pair(before, after).unwrap()
}

/// Survey j's surfaces: epoch 1 of the pair (j − 1, j), or epoch 0 of (0, 1) for j = 0.
fn survey(m: &CampaignModel, j: usize) -> (SceneModel, usize) {
    if j == 0 {
        (pair(m, 0, 1).model, 0)
    } else {
        (pair(m, j - 1, j).model, 1)
    }
}

/// Whether (x, y) lies in the rectangle [min − e, max + e].
fn in_rect(min: [f64; 2], max: [f64; 2], e: f64, x: f64, y: f64) -> bool {
    x >= min[0] - e && x <= max[0] + e && y >= min[1] - e && y <= max[1] + e
}

/// Every campaign pair's truth, consecutive (one interval's changes, the recurring scar's growth
/// among them as the difference of two half-ellipsoids) and baseline (0, k) (the accumulated
/// changes), matches the numerical integral of the difference of the pair's two analytic surfaces
/// within 0.5 %, for 5 surveys (the scar grows again in interval 3) and 3 (in interval 2);
/// outside the events' footprints the two surfaces are identical (beach, plateau and face on a
/// 5 cm grid); a baseline event's volume is the sum of its place's interval volumes.
#[test]
fn campaign_truths_match_numerical_integration() {
    for n in [5, 3] {
        let m = CampaignModel::new(n).unwrap();
        let ([x0, x1], beach, [z0, z1]) = m.site();
        let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
        pairs.extend((2..n).map(|k| (0, k)));
        let mut checked = 0;
        for (before, after) in pairs {
            let p = pair(&m, before, after);
            let name = format!("campaign {n}: pair ({before}, {after})");
            checked += check_volumes(&name, &p.model, 1500);
            let (ground, face): (Vec<_>, Vec<_>) = p
                .model
                .events()
                .iter()
                .map(|e| e.footprint)
                .partition(|f| matches!(f, Footprint::Ground { .. }));
            let outside = |fs: &[Footprint], x: f64, y: f64| {
                fs.iter().all(|f| match *f {
                    Footprint::Ground { min, max }
                    | Footprint::Face { min, max }
                    | Footprint::Frame { min, max } => !in_rect(min, max, 1e-9, x, y),
                })
            };
            let h = 0.05;
            for i in 0..=((x1 - x0) / h) as usize {
                let x = x0 + i as f64 * h;
                for j in 0..=((beach + 10.0) / h) as usize {
                    let y = -beach + j as f64 * h;
                    if outside(&ground, x, y) {
                        assert_eq!(p.model.height(0, x, y), p.model.height(1, x, y), "{name}");
                    }
                }
                for j in 0..=((z1 - z0) / h) as usize {
                    let z = z0 + j as f64 * h;
                    if outside(&face, x, z) {
                        let d = p.model.face_depth(1, x, z).unwrap();
                        assert_eq!(p.model.face_depth(0, x, z), Some(d), "{name}");
                    }
                }
            }
            if before == 0 && after >= 2 {
                for (e, t) in p.model.events().iter().zip(&p.tracks) {
                    let sum: f64 = (1..=after)
                        .flat_map(|k| {
                            let q = pair(&m, k - 1, k);
                            q.tracks
                                .iter()
                                .zip(q.model.events())
                                .filter(|(u, _)| *u == t)
                                .map(|(_, f)| f.volume_m3)
                                .collect::<Vec<_>>()
                        })
                        .sum();
                    assert!((e.volume_m3 - sum).abs() < 1e-9, "{name}: track {t}");
                }
            }
        }
        // 5 surveys: 2 + 3 + 3 + 3 interval events, baselines 5 + 7 + 10; 3 surveys: 2 + 3, and
        // 4 places in the baseline (0, 2) (the scar opened and grew: one event).
        assert_eq!(checked, if n == 5 { 11 + 22 } else { 5 + 4 });
    }
}

/// The campaign's layout for every number of surveys from 3 to 41, and for 100 and 401 (the
/// most): two or three events per interval of 1–20 m³; one recurring place (its track in
/// intervals 1 and min(3, N − 1), the later shape containing the earlier, their footprints and
/// truth circles overlapping, the second volume the difference); every other place changes in
/// one interval only; in the last survey all places are ≥ 5 m apart on the beach and on the
/// face, ≥ 5 m from the site's ends, the beach's seaward border, the face's foot and its top;
/// deposits (gains on the beach) stay ≥ 1.5 m in front of the foot; a place's change stays in
/// every later survey.
#[test]
fn campaign_layout_for_every_size() {
    for n in (campaign::MIN_EPOCHS..=41).chain([100, campaign::MAX_EPOCHS]) {
        let m = CampaignModel::new(n).unwrap();
        assert_eq!(m.epochs(), n);
        let recur = 3.min(n - 1);
        assert_eq!(m.recurring_interval(), recur);
        let mut seen: Vec<(u32, usize, ModelEvent)> = Vec::new();
        for k in 1..n {
            let p = pair(&m, k - 1, k);
            let ev = p.model.events();
            assert!((2..=3).contains(&ev.len()), "{n}: interval {k}");
            assert_eq!(p.tracks.len(), ev.len());
            for (e, &t) in ev.iter().zip(&p.tracks) {
                assert!(
                    (1.0..=20.0).contains(&e.volume_m3.abs()),
                    "{n}: {}",
                    e.volume_m3
                );
                seen.push((t, k, e.clone()));
            }
        }
        let recurring: Vec<&(u32, usize, ModelEvent)> = seen
            .iter()
            .filter(|(t, _, _)| seen.iter().filter(|(u, _, _)| u == t).count() > 1)
            .collect();
        assert_eq!(recurring.len(), 2, "{n}");
        let [(t1, k1, e1), (t2, k2, e2)] = [recurring[0], recurring[1]];
        assert_eq!(
            (*t1, *t2),
            (campaign::RECURRING_TRACK, campaign::RECURRING_TRACK)
        );
        assert_eq!((*k1, *k2), (1, recur));
        let (Footprint::Face { min: a0, max: a1 }, Footprint::Face { min: b0, max: b1 }) =
            (e1.footprint, e2.footprint)
        else {
            panic!("the recurring change is a scar")
        };
        // The later footprint contains the earlier: they overlap.
        assert!(in_rect(b0, b1, 0.0, a0[0], a0[1]) && in_rect(b0, b1, 0.0, a1[0], a1[1]));
        let d = (0..3)
            .map(|i| (e1.centre[i] - e2.centre[i]).powi(2))
            .sum::<f64>();
        assert!(d.sqrt() < e1.radius_m + e2.radius_m);
        assert!(e1.volume_m3 < 0.0 && e2.volume_m3 < 0.0);
        // The last survey against the first: one event per place, each place once.
        let all = pair(&m, 0, n - 1);
        let mut tracks = all.tracks.clone();
        tracks.sort_unstable();
        tracks.dedup();
        assert_eq!(tracks.len(), all.tracks.len());
        assert_eq!(tracks.len(), seen.len() - 1);
        let ([x0, x1], beach, [z0, z1]) = m.site();
        let ev = all.model.events();
        for (i, e) in ev.iter().enumerate() {
            let (min, max, lo, hi) = match e.footprint {
                Footprint::Ground { min, max } => (min, max, -beach, 0.0),
                Footprint::Face { min, max } => (min, max, z0, z1),
                Footprint::Frame { .. } => panic!("a campaign has no scanned face"),
            };
            assert!(
                min[0] >= x0 + 5.0 - 1e-9 && max[0] <= x1 - 5.0 + 1e-9,
                "{n}"
            );
            assert!(min[1] >= lo + 5.0 - 1e-9, "{n}: {}", e.description);
            if let Footprint::Face { .. } = e.footprint {
                assert!(max[1] <= hi - 5.0 + 1e-9, "{n}: {}", e.description);
            } else if e.volume_m3 > 0.0 {
                assert!(max[1] <= -1.5, "{n}: {} touches the face", e.description);
            }
            for f in &ev[i + 1..] {
                let (b0, b1) = match (e.footprint, f.footprint) {
                    (Footprint::Ground { .. }, Footprint::Ground { min, max })
                    | (Footprint::Face { .. }, Footprint::Face { min, max }) => (min, max),
                    _ => continue,
                };
                let gap = (0..2)
                    .map(|k| (b0[k] - max[k]).max(min[k] - b1[k]))
                    .fold(f64::NEG_INFINITY, f64::max);
                assert!(gap >= 5.0 - 1e-9, "{n}: gap {gap}");
            }
        }
        // Accumulation on the surfaces: at each event's centre survey j (j ≥ its interval k)
        // differs from survey k − 1 as survey k does, but for the recurring scar after it grew.
        if n <= 6 {
            for (t, k, e) in &seen {
                let change = |j: usize| {
                    let (s, ep) = survey(&m, j);
                    let (b, bp) = survey(&m, k - 1);
                    let c = e.centre;
                    match e.footprint {
                        Footprint::Ground { .. } => {
                            s.height(ep, c[0], c[1]).unwrap() - b.height(bp, c[0], c[1]).unwrap()
                        }
                        Footprint::Frame { .. } => unreachable!("a campaign has no scanned face"),
                        Footprint::Face { .. } => {
                            b.face_depth(bp, c[0], c[2]).unwrap()
                                - s.face_depth(ep, c[0], c[2]).unwrap()
                        }
                    }
                };
                let first = change(*k);
                assert!(first.abs() > 0.3, "{n}: {}", e.description);
                for j in *k..n {
                    let grown = *t == campaign::RECURRING_TRACK && *k == 1 && j >= recur;
                    if !grown {
                        assert_eq!(change(j), first, "{n}: {} in survey {j}", e.description);
                    }
                }
            }
        }
    }
}

/// The written campaign: `survey_YYYYMMDD.laz` every three months from 2021-03-01 (dates in
/// order, each name holding its date), LAS 1.4 point format 6 LAZ, 1 mm scale, the WKT CRS, the
/// advertised point count (100 per m² of plan: ≈ 0.1 m spacing) and point source id k + 1;
/// truth.json holds the returned truth, consecutive pairs and baseline pairs (0, k), ids from 1,
/// kinds by sign. Through the points: near every event's centre each survey's points lie on that
/// survey's analytic surface, and every survey from the event's interval on holds its change
/// (deposits raise, pits lower the beach, scars take the face back), the recurring scar 0.8 m
/// deep until it grows and 1.3 m after.
#[test]
fn campaign_files_dates_and_accumulation() {
    let dir = tempfile::tempdir().unwrap();
    let o = CampaignOptions::default();
    let truth = campaign::write(dir.path(), &o).unwrap();
    let m = campaign::model(&o).unwrap();
    let n = campaign::DEFAULT_EPOCHS;
    let dates = [
        "2021-03-01",
        "2021-06-01",
        "2021-09-01",
        "2021-12-01",
        "2022-03-01",
    ];
    assert_eq!(truth.epochs.len(), n);
    assert_eq!(campaign::date(40), "2031-03-01");
    let ([x0, x1], beach, _) = m.site();
    assert_eq!(
        m.default_points(),
        (100.0 * (x1 - x0) * (beach + 40.0)).round() as u64
    );
    let back: CampaignTruth =
        serde_json::from_slice(&std::fs::read(dir.path().join("truth.json")).unwrap()).unwrap();
    assert_eq!(
        (
            &back.scene,
            back.seed,
            &back.epochs,
            back.crs_epsg,
            &back.crs_wkt
        ),
        (
            &truth.scene,
            truth.seed,
            &truth.epochs,
            CRS_EPSG,
            &truth.crs_wkt
        )
    );
    assert_eq!(back.crs_wkt, UTM33N_WKT);
    let pairs = |t: &CampaignTruth| -> Vec<(usize, usize)> {
        t.pairs
            .iter()
            .chain(&t.baseline_pairs)
            .map(|p| (p.before, p.after))
            .collect()
    };
    let mut expect: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
    expect.extend((2..n).map(|k| (0, k)));
    assert_eq!(pairs(&truth), expect);
    assert_eq!(pairs(&back), expect);
    for (p, q) in truth
        .pairs
        .iter()
        .chain(&truth.baseline_pairs)
        .zip(back.pairs.iter().chain(&back.baseline_pairs))
    {
        assert_eq!(p.events.len(), q.events.len());
        for (i, (e, f)) in p.events.iter().zip(&q.events).enumerate() {
            assert_eq!(e.event.id as usize, i + 1);
            assert_eq!(
                (e.track, &e.event.description),
                (f.track, &f.event.description)
            );
            assert_eq!(e.event.kind == "gain", e.event.volume_m3 > 0.0);
            assert!((e.event.volume_m3 - f.event.volume_m3).abs() < 1e-9);
            assert!((0..3).all(|k| (e.event.centre[k] - f.event.centre[k]).abs() < 1e-6));
        }
    }
    let mut points = Vec::new();
    for (k, ep) in truth.epochs.iter().enumerate() {
        assert_eq!(ep.date, dates[k]);
        assert_eq!(
            ep.file.to_str().unwrap(),
            format!("survey_{}.laz", dates[k].replace('-', ""))
        );
        assert_eq!(ep.points, m.default_points());
        let path = dir.path().join(&ep.file);
        let mut reader = las::Reader::from_path(&path).unwrap();
        let h = reader.header().clone();
        assert_eq!(h.version(), las::Version::new(1, 4));
        assert_eq!(h.point_format().to_u8().unwrap(), 6);
        assert!(h.point_format().is_compressed);
        assert_eq!(h.number_of_points(), ep.points);
        assert_eq!(
            (h.transforms().x.scale, h.transforms().z.scale),
            (0.001, 0.001)
        );
        let wkt = h.get_wkt_crs_bytes().expect("WKT CRS VLR");
        assert_eq!(
            std::str::from_utf8(wkt).unwrap().trim_end_matches('\0'),
            UTM33N_WKT
        );
        let data = reader.read_all().unwrap();
        assert!(data.point_source_id().all(|id| id as usize == k + 1));
        let local: Vec<[f64; 3]> = data
            .x()
            .zip(data.y())
            .zip(data.z())
            .map(|((x, y), z)| [x - ORIGIN[0], y - ORIGIN[1], z])
            .collect();
        assert_eq!(local.len() as u64, ep.points);
        points.push(local);
    }
    for f in std::fs::read_dir(dir.path()).unwrap() {
        let name = f.unwrap().file_name();
        assert!(!name.to_string_lossy().ends_with(".tmp"), "{name:?}");
    }
    let recur = m.recurring_interval();
    // Each place's first interval: the recurring scar's is 1.
    let first_interval = |t: u32| {
        (1..n)
            .find(|&k| pair(&m, k - 1, k).tracks.contains(&t))
            .unwrap()
    };
    for k in 1..n {
        let p = pair(&m, k - 1, k);
        for (e, &t) in p.model.events().iter().zip(&p.tracks) {
            let since = first_interval(t);
            // Scars go into the rock (+y), deposits raise the beach, pits lower it.
            let up = matches!(e.footprint, Footprint::Face { .. }) || e.volume_m3 > 0.0;
            let c = e.centre;
            for (j, pts) in points.iter().enumerate() {
                let (s, ep) = survey(&m, j);
                let (s0, _) = survey(&m, 0);
                // Points within 0.3 m of the centre across the surface: their mean offset from
                // survey j's surface (noise only, ≤ 1.2 × 5 mm along z on the slopes:
                // 6 mm / √(≈ 28) per mean, bound at 5σ) and from the intact site's (the change
                // held by survey j).
                let (mut on, mut off, mut count) = (0.0, 0.0, 0.0);
                for q in pts {
                    match e.footprint {
                        Footprint::Ground { .. } if (q[0] - c[0]).hypot(q[1] - c[1]) < 0.3 => {
                            on += q[2] - s.height(ep, q[0], q[1]).unwrap();
                            off += q[2] - s0.height(0, q[0], q[1]).unwrap();
                        }
                        Footprint::Face { .. }
                            if (q[0] - c[0]).hypot(q[2] - c[2]) < 0.3 && q[1].abs() < 3.0 =>
                        {
                            on += q[1] - s.face_depth(ep, q[0], q[2]).unwrap();
                            off += q[1];
                        }
                        _ => continue,
                    }
                    count += 1.0;
                }
                assert!(count > 10.0, "{}: {count} points", e.description);
                let (on, off) = (on / count, off / count);
                assert!(
                    on.abs() < 0.006,
                    "{} survey {j}: {on} off its surface",
                    e.description
                );
                if j < since {
                    assert!(off.abs() < 0.006, "{} survey {j}: {off}", e.description);
                } else {
                    assert!(
                        off.abs() > 0.3,
                        "{} survey {j}: change {off}",
                        e.description
                    );
                    assert_eq!(off > 0.0, up, "{}", e.description);
                }
                if t == campaign::RECURRING_TRACK && j >= 1 {
                    let deep = if j >= recur { 1.3 } else { 0.8 };
                    assert!(
                        (off - deep).abs() < 0.01,
                        "recurring scar survey {j}: {off}"
                    );
                }
            }
        }
    }
}

/// Same options → identical bytes of every survey and truth.json (also on one thread); another
/// seed → other points in every survey and the same planted changes (the layout does not depend
/// on the seed); the surveys of one campaign come from different random streams.
#[test]
fn campaign_same_seed_same_bytes() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    let o = CampaignOptions {
        epochs: 4,
        ..CampaignOptions::default()
    };
    let ta = campaign::write(a.path(), &o).unwrap();
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| campaign::write(b.path(), &o))
        .unwrap();
    let tc = campaign::write(
        c.path(),
        &CampaignOptions {
            seed: 2,
            ..o.clone()
        },
    )
    .unwrap();
    for ep in &ta.epochs {
        let x = std::fs::read(a.path().join(&ep.file)).unwrap();
        assert_eq!(
            x,
            std::fs::read(b.path().join(&ep.file)).unwrap(),
            "{:?}",
            ep.file
        );
        assert_ne!(
            x,
            std::fs::read(c.path().join(&ep.file)).unwrap(),
            "{:?}",
            ep.file
        );
    }
    let json = std::fs::read(a.path().join("truth.json")).unwrap();
    assert_eq!(json, std::fs::read(b.path().join("truth.json")).unwrap());
    assert_eq!((ta.pairs.clone(), tc.seed), (tc.pairs.clone(), 2));
    let first: Vec<Vec<[f64; 3]>> = (0..4)
        .map(|k| {
            campaign::survey_chunks(&o, k)
                .unwrap()
                .flatten()
                .take(100)
                .collect()
        })
        .collect();
    for k in 1..4 {
        assert_ne!(first[k], first[k - 1]);
    }
}

/// Out-of-range options are usage errors: 2 or 402 surveys, too few points, bad noise, a pair not
/// in order, a survey past the last.
#[test]
fn campaign_bad_options_are_usage_errors() {
    let dir = tempfile::tempdir().unwrap();
    let o = CampaignOptions::default();
    for bad in [
        CampaignOptions {
            epochs: 2,
            ..o.clone()
        },
        CampaignOptions {
            epochs: campaign::MAX_EPOCHS + 1,
            ..o.clone()
        },
        CampaignOptions {
            points: Some(10),
            ..o.clone()
        },
        CampaignOptions {
            noise: Some(-0.1),
            ..o.clone()
        },
    ] {
        let e = campaign::write(dir.path(), &bad).unwrap_err();
        assert_eq!(e.exit_code(), 2, "{e}");
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    let m = campaign::model(&o).unwrap();
    for (i, j) in [(1, 1), (2, 1), (0, 5)] {
        assert_eq!(m.pair(i, j).unwrap_err().exit_code(), 2, "({i}, {j})");
    }
    let e = campaign::survey_chunks(&o, 5).err().expect("no survey 5");
    assert_eq!(e.exit_code(), 2);
}

/// The command line: `talus synth campaign --out DIR --epochs 3 --points P --seed S --noise M
/// --las` writes three LAS surveys and truth.json with those settings; `--rotate` with a campaign
/// and `--epochs` with a pair scene are usage errors (exit 2).
#[test]
fn campaign_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_talus"))
            .args(args)
            .output()
            .unwrap()
    };
    let o = out.to_str().unwrap();
    let r = run(&[
        "synth", "campaign", "--out", o, "--epochs", "3", "--points", "20000", "--seed", "7",
        "--noise", "0.01", "--las",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let t: CampaignTruth =
        serde_json::from_slice(&std::fs::read(out.join("truth.json")).unwrap()).unwrap();
    assert_eq!((t.seed, t.noise_m, t.epochs.len()), (7, 0.01, 3));
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|f| f.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            ".talus-synth.json",
            "survey_20210301.las",
            "survey_20210601.las",
            "survey_20210901.las",
            "truth.json"
        ]
    );
    for e in &t.epochs {
        assert_eq!(e.points, 20000);
        let r = las::Reader::from_path(out.join(&e.file)).unwrap();
        assert!(!r.header().point_format().is_compressed);
    }
    for args in [
        &["synth", "campaign", "--out", o, "--rotate", "10"][..],
        &["synth", "campaign", "--out", o, "--epochs", "2"],
        &["synth", "hill", "--out", o, "--epochs", "3"],
    ] {
        let r = run(args);
        assert_eq!(r.status.code(), Some(2), "{args:?}");
    }
}
