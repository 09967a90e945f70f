//! Write a campaign report (`report.html`) from built-in sample data: six surveys of a
//! 300 m × 200 m rock slope over 15 months (five pairs), 43 events of 0.2–460 m³ with a heavy
//! tail (five below their uncertainty), four tracks (scars that fail again, fans that keep
//! building), regions as small polygons in UTM 33N coordinates.
//!
//! `cargo run --example campaign_report -- OUT.html` (the browser test runs it).

use talus::campaign::powerlaw;
use talus::campaign::report::{self, EventRow, PairRow, Report};

/// Survey dates, one label each (`YYYYMMDD`, as `talus campaign` names them).
const DATES: [&str; 6] = [
    "2023-03-14",
    "2023-06-20",
    "2023-09-12",
    "2023-12-05",
    "2024-03-19",
    "2024-06-11",
];
const DAYS: [i64; 5] = [98, 84, 84, 105, 84];
/// The site's south-west corner (UTM 33N).
const ORIGIN: [f64; 2] = [512_300.0, 5_403_500.0];

/// Recurring places: (pair, x along the slope in m, signed volume m³, track).
const TRACKED: [(usize, f64, f64, u32); 11] = [
    (0, 92.0, -182.0, 1),
    (2, 96.0, -34.5, 1),
    (4, 90.0, -461.0, 1),
    (0, 101.0, 96.0, 2),
    (2, 99.0, 21.4, 2),
    (3, 104.0, 12.8, 2),
    (1, 212.0, -63.0, 3),
    (3, 208.0, -8.2, 3),
    (1, 216.0, 27.5, 4),
    (4, 219.0, 41.0, 4),
    (4, 221.0, -15.6, 5),
];

/// Events on poorly covered ground (occlusion, a gap in one survey): an uncertainty larger
/// than the volume, so below it. (pair, x, signed volume m³, track.)
const POOR: [(usize, f64, f64, u32); 3] = [
    (1, 150.0, -38.0, 40),
    (3, 64.0, 17.5, 41),
    (4, 262.0, -9.5, 42),
];

/// A well-spread number in [0, 1) for event `i`, draw `k` (an additive recurrence: the sample
/// needs spread, not randomness).
fn u(i: usize, k: usize) -> f64 {
    let v = 0.5 + i as f64 * 0.618_033_988_75 + k as f64 * 0.414_213_562_37 + (i * k) as f64 * 0.1;
    v - v.floor()
}

/// The slope's crest line: y (m, from the site's south edge) at x.
fn crest(x: f64) -> f64 {
    128.0 + 18.0 * (x / 47.0).sin()
}

/// A closed lobed ring around (x, y) of an area that holds `volume` at a plausible depth, grown
/// by the volume margin (1.5 m), elongated along the slope.
fn ring(x: f64, y: f64, volume: f64, phase: f64) -> Vec<[f64; 3]> {
    let depth = 0.5 + 0.3 * (1.0 + volume.abs()).ln();
    let r = (volume.abs() / depth / std::f64::consts::PI).sqrt() + 1.5;
    let mut pts: Vec<[f64; 3]> = (0..14)
        .map(|j| {
            let t = std::f64::consts::TAU * j as f64 / 14.0;
            let lobe = 1.0 + 0.18 * (3.0 * t + phase).sin();
            [
                ORIGIN[0] + x + 1.35 * r * lobe * t.cos(),
                ORIGIN[1] + y + r / 1.35 * lobe * t.sin(),
                640.0 + 0.4 * y,
            ]
        })
        .collect();
    pts.push(pts[0]);
    pts
}

fn event(
    pair: usize,
    id: u32,
    x: f64,
    volume: f64,
    track: u32,
    phase: f64,
    poor: bool,
) -> EventRow {
    // Losses on the face just below the crest, gains on the talus below it.
    let y = if volume < 0.0 {
        crest(x) - 4.0 - 6.0 * phase.sin().abs()
    } else {
        crest(x) - 45.0 - 40.0 * phase.cos().abs()
    };
    let uncertainty = if poor {
        0.5 + 1.3 * volume.abs()
    } else {
        0.22 + 0.04 * volume.abs()
    };
    let mut region = vec![vec![ring(x, y, volume, phase)]];
    if track == 1 && pair == 4 {
        // The largest scar's region is cut in two by a neighbour's cells.
        region.push(vec![ring(x + 17.0, y - 3.0, 6.0, phase + 1.0)]);
    }
    EventRow {
        pair,
        id,
        kind: if volume > 0.0 { "gain" } else { "loss" }.into(),
        volume_m3: Some(volume),
        uncertainty_m3: Some(uncertainty),
        significant: volume.abs() > uncertainty,
        // One event measured in part, as a dense survey with a short --cyl-halflen gives.
        complete: !(track == 2 && pair == 3),
        vegetation: false,
        track_id: track,
        centroid: [ORIGIN[0] + x, ORIGIN[1] + y, 640.0 + 0.4 * y],
        region,
    }
}

fn sample() -> Report {
    let mut events: Vec<EventRow> = Vec::new();
    let mut next_id = [1u32; 5];
    let mut push = |events: &mut Vec<EventRow>, pair: usize, x, v, track, phase, poor| {
        events.push(event(pair, next_id[pair], x, v, track, phase, poor));
        next_id[pair] += 1;
    };
    for (i, &(pair, x, v, track)) in TRACKED.iter().enumerate() {
        push(&mut events, pair, x, v, track, i as f64, false);
    }
    for (i, &(pair, x, v, track)) in POOR.iter().enumerate() {
        push(&mut events, pair, x, v, track, 2.0 + i as f64, true);
    }
    // 29 more events, each at its own place: a heavy-tailed spread of volumes (a power law of
    // exponent 1.8 above 0.2 m³), two losses for every gain.
    for i in 0..29 {
        let pair = (i * 3 + 1) % 5;
        let x = 12.0 + 276.0 * u(i, 1);
        let v = 0.2 * (1.0 - 0.97 * u(i, 2)).powf(-1.25);
        let v = if i % 3 == 2 { v } else { -v };
        push(&mut events, pair, x, v, 6 + i as u32, 0.7 * i as f64, false);
    }
    events.sort_by_key(|e| (e.pair, e.id));

    let pairs = (0..5)
        .map(|k| {
            let mine: Vec<&EventRow> = events.iter().filter(|e| e.pair == k).collect();
            let sig = |sign: f64| -> f64 {
                mine.iter()
                    .filter(|e| e.significant)
                    .filter_map(|e| e.volume_m3)
                    .filter(|v| v * sign > 0.0)
                    .sum()
            };
            let (gain, loss) = (sig(1.0), sig(-1.0));
            let area: f64 = mine
                .iter()
                .map(|e| (e.volume_m3.unwrap().abs() / 0.8).max(4.0))
                .sum();
            let label = |d: &str| d.replace('-', "");
            PairRow {
                label: format!("{}_{}", label(DATES[k]), label(DATES[k + 1])),
                before: label(DATES[k]),
                after: label(DATES[k + 1]),
                before_date: DATES[k].into(),
                after_date: DATES[k + 1].into(),
                days: DAYS[k],
                core_points: 1_482_913,
                significant_points: 2_140 + (area * 16.0) as u64,
                events: mine.len(),
                gain_events: mine.iter().filter(|e| e.kind == "gain").count(),
                loss_events: mine.iter().filter(|e| e.kind == "loss").count(),
                gain_m3: gain,
                loss_m3: loss,
                net_m3: gain + loss,
                mean_volume_uncertainty_m3: mine
                    .iter()
                    .filter_map(|e| e.uncertainty_m3)
                    .sum::<f64>()
                    / mine.len().max(1) as f64,
                seconds: 512.0 + 41.5 * k as f64 + 6.25 * mine.len() as f64,
            }
        })
        .collect();
    Report {
        title: "Val Ferret rock slope — monitoring campaign 2023–2024".into(),
        crs: "PROJCS[\"WGS 84 / UTM zone 33N\",GEOGCS[\"WGS 84\",DATUM[\"WGS_1984\",\
              SPHEROID[\"WGS 84\",6378137,298.257223563]],PRIMEM[\"Greenwich\",0],\
              UNIT[\"degree\",0.0174532925199433]],PROJECTION[\"Transverse_Mercator\"],\
              PARAMETER[\"central_meridian\",15],PARAMETER[\"scale_factor\",0.9996],\
              PARAMETER[\"false_easting\",500000],UNIT[\"metre\",1],AUTHORITY[\"EPSG\",\"32633\"]]"
            .into(),
        gain_fit: powerlaw::fit(&report::magnitudes(&events, "gain")),
        loss_fit: powerlaw::fit(&report::magnitudes(&events, "loss")),
        pairs,
        events,
        generated_by: format!("talus {}", env!("CARGO_PKG_VERSION")),
    }
}

fn main() {
    let Some(out) = std::env::args_os().nth(1) else {
        eprintln!("usage: campaign_report OUT.html");
        std::process::exit(2);
    };
    let report = sample();
    if let Err(e) = std::fs::write(&out, report::html(&report)) {
        eprintln!("campaign_report: {}: {e}", out.to_string_lossy());
        std::process::exit(1);
    }
    println!(
        "campaign_report: {} ({} pairs, {} events)",
        out.to_string_lossy(),
        report.pairs.len(),
        report.events.len()
    );
}
