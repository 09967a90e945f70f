//! Real data is the judge: the St Leonards beach campaign (../shared/data/st-leonards, six UAV
//! surveys 2018–2019 on a 1 m grid, water and vegetation edges included), its five consecutive
//! pairs compared with default parameters, every event's volume against a DEM of difference
//! written here (tests/common/dod.rs: both epochs' TINs sampled in z on a 0.25 m grid, only the
//! cells both epochs cover) over the event's own region from event_regions.geojson.
//!
//! Issue "Volumes that add up on real surveys", item 1: per event (DoD over 10 m³) the median of
//! |V − DoD| / |DoD| ≤ 5 % and the 90th percentile ≤ 20 %; per pair the sum of the events within
//! 5 % of the gross change (|gain| + |loss|) over the union of the regions of the DoD there; no
//! location counted twice (the union of the regions is the sum of their areas but for the cells
//! along shared borders). Run with `--nocapture` to see the table.

mod common;

use std::path::Path;

use serde_json::Value;

/// DoD grid cell (m): a quarter of the survey's 1 m grid.
const CELL: f64 = 0.25;

struct PairResult {
    name: String,
    events: usize,
    sum_v: f64,
    sum_dod: f64,
    union_dod: f64,
    gross: f64,
    rel: Vec<f64>,
    overlap_share: f64,
}

fn read_json(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn pair(before: &Path, after: &Path, out: &Path) -> PairResult {
    let o = common::run_compare(before, after, out, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary = read_json(&out.join("summary.json"));
    let spacing = summary["parameters"]["point_spacing"]["value"]
        .as_f64()
        .unwrap();
    let (_, p1) = talus::io::read_all(before).unwrap();
    let (_, p2) = talus::io::read_all(after).unwrap();
    let origin = [p1[0][0], p1[0][1]];
    let e1 = common::dod::Epoch::new(&p1, origin, 2.0 * spacing);
    let e2 = common::dod::Epoch::new(&p2, origin, 2.0 * spacing);
    let events = read_json(&out.join("events.geojson"));
    let volume = |id: u64| {
        events["features"]
            .as_array()
            .unwrap()
            .iter()
            .find(|f| f["properties"]["id"].as_u64() == Some(id))
            .and_then(|f| f["properties"]["volume_m3"].as_f64())
            .unwrap()
    };
    let regions = common::dod::regions(&read_json(&out.join("event_regions.geojson")));
    let mut union = std::collections::HashMap::new();
    let (mut sum_v, mut sum_dod, mut cells_total) = (0.0, 0.0, 0usize);
    let mut rel = Vec::new();
    for (id, polys) in &regions {
        let cells = common::dod::cells(&e1, &e2, polys, CELL);
        let dod: f64 = cells.iter().map(|c| c.1).sum::<f64>() * CELL * CELL;
        let v = volume(*id);
        cells_total += cells.len();
        for (k, dz) in cells {
            union.insert(k, dz);
        }
        sum_v += v;
        sum_dod += dod;
        if dod.abs() > 10.0 {
            rel.push((v - dod).abs() / dod.abs());
        }
    }
    let union_dod = union.values().sum::<f64>() * CELL * CELL;
    let gross = union.values().map(|d| d.abs()).sum::<f64>() * CELL * CELL;
    rel.sort_by(|a, b| a.total_cmp(b));
    PairResult {
        name: format!(
            "{} → {}",
            &before.file_name().unwrap().to_string_lossy()[4..12],
            &after.file_name().unwrap().to_string_lossy()[4..12]
        ),
        events: regions.len(),
        sum_v,
        sum_dod,
        union_dod,
        gross,
        rel,
        overlap_share: 1.0 - union.len() as f64 / cells_total.max(1) as f64,
    }
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn event_volumes_agree_with_a_dem_of_difference_on_the_st_leonards_campaign() {
    let Some(dir) = common::shared_data("st-leonards") else {
        return;
    };
    let mut surveys: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "laz"))
        .collect();
    surveys.sort();
    assert_eq!(surveys.len(), 6, "six surveys in {}", dir.display());
    let tmp = common::tempdir();
    let results: Vec<PairResult> = surveys
        .windows(2)
        .enumerate()
        .map(|(k, w)| pair(&w[0], &w[1], &tmp.path().join(format!("pair{k}"))))
        .collect();
    eprintln!(
        "{:<22} {:>6} {:>12} {:>12} {:>12} {:>10} {:>8} {:>8} {:>8}",
        "pair",
        "events",
        "Σ events m³",
        "DoD union m³",
        "gross m³",
        "Σ−DoD %",
        "median %",
        "p90 %",
        "overlap %"
    );
    let mut all = Vec::new();
    for r in &results {
        let off = 100.0 * (r.sum_v - r.union_dod).abs() / r.gross;
        eprintln!(
            "{:<22} {:>6} {:>12.1} {:>12.1} {:>12.1} {:>10.2} {:>8.2} {:>8.2} {:>8.2}",
            r.name,
            r.events,
            r.sum_v,
            r.union_dod,
            r.gross,
            off,
            100.0 * quantile(&r.rel, 0.5),
            100.0 * quantile(&r.rel, 0.9),
            100.0 * r.overlap_share
        );
        assert!(
            off <= 5.0,
            "{}: Σ events off the DoD by {off:.2} % of the gross change",
            r.name
        );
        // Regions do not overlap but for cells along shared borders.
        assert!(
            r.overlap_share < 0.01,
            "{}: {:.2} % of the cells counted twice",
            r.name,
            100.0 * r.overlap_share
        );
        assert!(
            (r.sum_dod - r.union_dod).abs() <= 0.01 * r.gross,
            "{}",
            r.name
        );
        all.extend_from_slice(&r.rel);
    }
    all.sort_by(|a, b| a.total_cmp(b));
    let (median, p90) = (quantile(&all, 0.5), quantile(&all, 0.9));
    eprintln!(
        "all pairs: {} events over 10 m³, median |V − DoD|/|DoD| {:.2} %, 90th percentile {:.2} %",
        all.len(),
        100.0 * median,
        100.0 * p90
    );
    assert!(median <= 0.05, "median {median}");
    assert!(p90 <= 0.20, "p90 {p90}");
}
