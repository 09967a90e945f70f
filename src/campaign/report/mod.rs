//! The campaign's `report.html` (SPEC.md §5): one self-contained page a geomorphologist can hand
//! on — nothing is fetched (inline CSS and SVG, no script, no fonts but the reader's own), and
//! the same inputs give the same bytes (no time stamp; every number printed at a fixed
//! precision).
//!
//! It shows, in this order:
//! 1. the campaign table (the paper's Table 1 completed): one row per pair as given, totals over
//!    the consecutive pairs (this module, with the page's header and style);
//! 2. cumulative significant gain, loss and net volume over time, along the chain of consecutive
//!    pairs (baseline pairs, `--baseline`, would count the same change twice and are left out)
//!    (`cumulative.rs`);
//! 3. the magnitude–frequency plot: the exceedance N(≥ |V|) of the significant events' volumes,
//!    per gain and loss, on log–log axes, with the fitted power laws
//!    ([`super::powerlaw`]) over their tails (`magnitude.rs`);
//! 4. a plan-view map per pair (x/y of the event regions, one extent and scale for all pairs),
//!    gains and losses in two colours, events below their uncertainty hatched, the other pairs'
//!    events as faint outlines, track ids where they do not overlap, a scale bar and north arrow
//!    (`map.rs`).
//!
//! The charts share `chart.rs` (their colours, axes, ticks); every number and escaped string is
//! written by `text.rs`, and dates are `crate::campaign::date::Date`.
//!
//! Colours: the viewer's convention (its distance ramp, ColorBrewer RdBu): gain red (#b2182b),
//! loss blue (#2166ac), a diverging pair readers with any common colour-vision deficiency tell
//! apart; the marks differ in shape too (circles for gains, squares for losses), and the legend
//! says which is which.

use std::fmt::Write;

use super::powerlaw::PowerLawFit;
use cumulative::cumulative_section;
use magnitude::magnitude_section;
use map::maps_section;
use text::{esc, fixed, grouped, grouped_u, plural, signed};

/// `write!` into a String, which cannot fail. Defined before the chart modules so that they
/// see it too.
macro_rules! w {
    ($($t:tt)*) => {{
        let _ = write!($($t)*);
    }};
}

mod chart;
mod cumulative;
mod magnitude;
mod map;
mod text;

/// One compared pair: a row of `campaign.csv`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct PairRow {
    pub label: String,
    pub before: String,
    pub after: String,
    /// ISO date, `YYYY-MM-DD`.
    pub before_date: String,
    pub after_date: String,
    pub days: i64,
    pub core_points: u64,
    pub significant_points: u64,
    pub events: usize,
    pub gain_events: usize,
    pub loss_events: usize,
    /// Totals of the pair's significant events, m³ (loss ≤ 0).
    pub gain_m3: f64,
    pub loss_m3: f64,
    pub net_m3: f64,
    /// The mean 95 % half-width of the pair's event volumes, m³.
    pub mean_volume_uncertainty_m3: f64,
    pub seconds: f64,
}

/// One event of one pair.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct EventRow {
    /// Index into [`Report::pairs`].
    pub pair: usize,
    pub id: u32,
    /// `"gain"` or `"loss"`.
    pub kind: String,
    /// Signed (loss < 0); `None` where no volume could be measured.
    pub volume_m3: Option<f64>,
    pub uncertainty_m3: Option<f64>,
    pub significant: bool,
    /// The volume covers the whole change (events.geojson `complete`); an incomplete event's
    /// interval is not a 95 % bound and the map draws its outline dashed.
    #[serde(default = "whole")]
    pub complete: bool,
    /// A vegetation event kept apart (`--vegetation flag|remove`): drawn in its own colour, in
    /// no track, no sum and no fit.
    #[serde(default)]
    pub vegetation: bool,
    /// 0: none.
    pub track_id: u32,
    pub centroid: [f64; 3],
    /// Region outline: polygons → rings → [x, y, z] (closed rings), as event_regions.geojson
    /// holds them; empty where the event has no region.
    pub region: Vec<Vec<Vec<[f64; 3]>>>,
}

fn whole() -> bool {
    true
}

/// Everything the page shows.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Report {
    pub title: String,
    pub crs: String,
    /// In date order.
    pub pairs: Vec<PairRow>,
    pub events: Vec<EventRow>,
    /// Fitted to [`magnitudes`]`(events, "gain")`, and the same for losses.
    pub gain_fit: Option<PowerLawFit>,
    pub loss_fit: Option<PowerLawFit>,
    /// e.g. "talus 0.1.0".
    pub generated_by: String,
}

/// The values the magnitude–frequency plot shows for `kind` ("gain" or "loss"): |volume| of the
/// significant events of that kind that have a volume. Fit these, so the plotted points and
/// the fitted lines speak of the same events.
pub fn magnitudes(events: &[EventRow], kind: &str) -> Vec<f64> {
    events
        .iter()
        .filter(|e| e.significant && !e.vegetation && e.kind == kind)
        .filter_map(|e| e.volume_m3)
        .map(f64::abs)
        .collect()
}

/// The page.
pub fn html(report: &Report) -> String {
    let chain = chain(&report.pairs);
    let mut s = String::with_capacity(64 * 1024);
    w!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{} — campaign report</title>\n<style>\n{}</style>\n</head>\n<body>\n<main>\n",
        esc(&report.title),
        CSS
    );
    header(&mut s, report, &chain);
    table_section(&mut s, report, &chain);
    cumulative_section(&mut s, report, &chain);
    magnitude_section(&mut s, report);
    maps_section(&mut s, report);
    w!(
        s,
        "<footer>Generated by {}. Power-law fits: maximum likelihood with x<sub>min</sub> chosen by \
         the Kolmogorov–Smirnov distance (Clauset, Shalizi &amp; Newman 2009, SIAM Review \
         51:661).</footer>\n</main>\n</body>\n</html>\n",
        esc(&report.generated_by)
    );
    s
}

const CSS: &str = "\
:root{--gain:#b2182b;--loss:#2166ac;--ink:#1a1a1a;--muted:#5f6368;--rule:#d0d0d0}
*{box-sizing:border-box}
body{margin:0;background:#fff;color:var(--ink);font:14px/1.45 system-ui,-apple-system,\"Segoe UI\",Roboto,\"Helvetica Neue\",Arial,sans-serif}
main{max-width:1180px;margin:0 auto;padding:28px 30px 40px}
h1{font-size:25px;font-weight:600;margin:0 0 2px;letter-spacing:-.01em}
h2{font-size:17px;font-weight:600;margin:34px 0 10px;padding-bottom:5px;border-bottom:1px solid var(--rule)}
.sub{color:var(--muted);margin:0 0 16px}
.figures{display:flex;flex-wrap:wrap;gap:10px 36px;margin:14px 0 0;padding:12px 16px;background:#f6f7f8;border-radius:4px}
.figures div{display:flex;flex-direction:column}
.figures span{font-size:12px;color:var(--muted)}
.figures b{font-size:20px;font-weight:600;font-variant-numeric:tabular-nums}
.note{color:var(--muted);font-size:12.5px;margin:6px 0 0;max-width:900px}
.scroll{overflow-x:auto}
table{border-collapse:collapse;width:100%;font-size:12.5px;font-variant-numeric:tabular-nums}
th,td{padding:4px 8px;text-align:right;white-space:nowrap}
td{vertical-align:top}
thead th{font-weight:600;vertical-align:bottom}
thead tr:first-child th{border-bottom:1px solid var(--rule)}
thead tr:last-child th{border-bottom:1.5px solid var(--ink)}
thead th.group{text-align:center}
tbody tr:nth-child(even){background:#f7f8f9}
tbody tr.baseline td{color:var(--muted);font-style:italic}
tfoot td,tfoot th{border-top:1.5px solid var(--ink);font-weight:600}
tbody th,tfoot th{vertical-align:top}
.l{text-align:left}
.u{font-weight:400;color:var(--muted)}
.d{display:block;font-weight:400;font-size:11.5px;color:var(--muted)}
.gain{color:var(--gain)}.loss{color:var(--loss)}
svg{display:block;max-width:100%;height:auto}
svg text{font-family:inherit}
.legend{display:flex;flex-wrap:wrap;gap:6px 22px;font-size:12.5px;margin:0 0 12px;color:var(--ink)}
.legend span{display:inline-flex;align-items:center;gap:6px}
.sw{display:inline-block;width:16px;height:11px;border:1.2px solid}
.sw.g{background:var(--gain);border-color:var(--gain);opacity:.8}
.sw.l{background:var(--loss);border-color:var(--loss);opacity:.8}
.sw.v{background:#4d9221;border-color:#4d9221;opacity:.55}
.sw.hg{border-color:var(--gain);background:repeating-linear-gradient(45deg,var(--gain) 0 1.5px,#fff 1.5px 4px)}
.sw.hl{border-color:var(--loss);background:repeating-linear-gradient(45deg,var(--loss) 0 1.5px,#fff 1.5px 4px)}
.sw.o{border-color:#b8b8b8;background:none}
.sw.inc{border:1.2px dashed #555;background:none}
.maps{display:grid;grid-template-columns:repeat(3,360px);justify-content:space-between;gap:20px 0}
figure{margin:0}
figcaption{font-size:12.5px;margin-top:4px;line-height:1.35}
figcaption .u{display:block}
footer{margin-top:36px;padding-top:8px;border-top:1px solid var(--rule);color:var(--muted);font-size:12px}
@media (max-width:1180px){.maps{grid-template-columns:repeat(auto-fill,minmax(300px,360px));gap:20px}}
@media print{main{padding:0;max-width:none}section{break-inside:avoid}}
";

fn header(s: &mut String, report: &Report, chain: &[usize]) {
    w!(
        s,
        "<header>\n<h1>{}</h1>\n<p class=\"sub\">",
        esc(&report.title)
    );
    let total = totals(&report.pairs, chain);
    let mut parts = Vec::new();
    if let Some(t) = &total {
        parts.push(format!(
            "{} surveys, {} to {}",
            surveys(&report.pairs),
            esc(&t.before_date),
            esc(&t.after_date)
        ));
    }
    parts.push(format!(
        "{} pair{}",
        report.pairs.len(),
        plural(report.pairs.len())
    ));
    if !report.crs.is_empty() {
        parts.push(format!(
            "<span title=\"{}\">{}</span>",
            esc(&report.crs),
            esc(&crs_name(&report.crs))
        ));
    }
    s.push_str(&parts.join(" · "));
    s.push_str("</p>\n");
    if let Some(t) = total {
        w!(
            s,
            "<div class=\"figures\" role=\"group\" aria-label=\"Campaign totals\">\
             <div><span>Period</span><b>{} d</b></div>\
             <div><span>Events</span><b>{}</b></div>\
             <div><span>Gain</span><b class=\"gain\">{} m³</b></div>\
             <div><span>Loss</span><b class=\"loss\">{} m³</b></div>\
             <div><span>Net change</span><b>{} m³</b></div></div>\n",
            grouped(t.days),
            grouped(t.events as i64),
            signed(t.gain_m3, 1),
            signed(t.loss_m3, 1),
            signed(t.net_m3, 1)
        );
    }
    s.push_str("</header>\n");
}

/// The consecutive pairs summed, as a row from the first survey to the last (the point counts
/// are not summed: every pair has the same core points); `None` without pairs.
fn totals(pairs: &[PairRow], chain: &[usize]) -> Option<PairRow> {
    let (first, last) = (&pairs[*chain.first()?], &pairs[*chain.last()?]);
    let rows = chain.iter().map(|&i| &pairs[i]);
    let events: usize = rows.clone().map(|p| p.events).sum();
    let weighted: f64 = rows
        .clone()
        .map(|p| p.mean_volume_uncertainty_m3 * p.events as f64)
        .sum();
    Some(PairRow {
        label: "Total".into(),
        before: first.before.clone(),
        after: last.after.clone(),
        before_date: first.before_date.clone(),
        after_date: last.after_date.clone(),
        days: rows.clone().map(|p| p.days).sum(),
        core_points: 0,
        significant_points: 0,
        events,
        gain_events: rows.clone().map(|p| p.gain_events).sum(),
        loss_events: rows.clone().map(|p| p.loss_events).sum(),
        gain_m3: rows.clone().map(|p| p.gain_m3).sum(),
        loss_m3: rows.clone().map(|p| p.loss_m3).sum(),
        net_m3: rows.clone().map(|p| p.net_m3).sum(),
        mean_volume_uncertainty_m3: if events > 0 {
            weighted / events as f64
        } else {
            f64::NAN
        },
        seconds: rows.map(|p| p.seconds).sum(),
    })
}

fn table_section(s: &mut String, report: &Report, chain: &[usize]) {
    s.push_str(
        "<section id=\"campaign-table\" aria-labelledby=\"h-table\">\n\
         <h2 id=\"h-table\">1. Campaign</h2>\n<div class=\"scroll\">\n<table>\n\
         <caption class=\"note\" style=\"caption-side:bottom;text-align:left\">",
    );
    s.push_str(
        "Volumes are totals over the significant events (|V| above its 95 % uncertainty); \
         losses are negative. Mean ±: the mean 95 % half-width of the pair's event volumes.",
    );
    let baseline = report.pairs.len() - chain.len();
    if baseline > 0 {
        w!(
            s,
            " Rows in italics ({baseline}) are baseline pairs, not consecutive ones: they are \
             left out of the totals and the cumulative chart."
        );
    }
    s.push_str(
        "</caption>\n<thead>\n<tr><th rowspan=\"2\" class=\"l\" scope=\"col\">Pair</th>\
         <th rowspan=\"2\" class=\"l\" scope=\"col\">Before<span class=\"d\">survey, date</span></th>\
         <th rowspan=\"2\" class=\"l\" scope=\"col\">After<span class=\"d\">survey, date</span></th>\
         <th rowspan=\"2\" scope=\"col\">Days</th>\
         <th colspan=\"2\" class=\"group\" scope=\"colgroup\">Core points</th>\
         <th colspan=\"3\" class=\"group\" scope=\"colgroup\">Events</th>\
         <th colspan=\"4\" class=\"group\" scope=\"colgroup\">Volume <span class=\"u\">(m³)</span></th>\
         <th rowspan=\"2\" scope=\"col\">Run time<span class=\"d\">(s)</span></th></tr>\n\
         <tr><th scope=\"col\">Total</th><th scope=\"col\">Significant</th>\
         <th scope=\"col\">All</th><th scope=\"col\">Gain</th><th scope=\"col\">Loss</th>\
         <th scope=\"col\">Gain</th><th scope=\"col\">Loss</th><th scope=\"col\">Net</th>\
         <th scope=\"col\">Mean ±</th></tr>\n</thead>\n<tbody>\n",
    );
    for (i, p) in report.pairs.iter().enumerate() {
        let class = if chain.contains(&i) {
            ""
        } else {
            " class=\"baseline\""
        };
        table_row(s, class, p, true);
    }
    s.push_str("</tbody>\n");
    if let Some(t) = totals(&report.pairs, chain) {
        s.push_str("<tfoot>");
        table_row(s, "", &t, false);
        s.push_str("</tfoot>\n");
    }
    s.push_str("</table>\n</div>\n</section>\n");
}

/// A row of the table: the pair's label as its header cell, then every field; `points`: with
/// the core-point counts (a dash for each without).
fn table_row(s: &mut String, attrs: &str, p: &PairRow, points: bool) {
    let (core, significant) = if points {
        let share = if p.core_points > 0 {
            format!(
                "<span class=\"d\">{} %</span>",
                fixed(
                    100.0 * p.significant_points as f64 / p.core_points as f64,
                    1
                )
            )
        } else {
            String::new()
        };
        (
            grouped_u(p.core_points),
            format!("{}{share}", grouped_u(p.significant_points)),
        )
    } else {
        ("—".to_string(), "—".to_string())
    };
    let cells = [
        ("l", survey_cell(&p.before, &p.before_date)),
        ("l", survey_cell(&p.after, &p.after_date)),
        ("", grouped(p.days)),
        ("", core),
        ("", significant),
        ("", grouped(p.events as i64)),
        ("", grouped(p.gain_events as i64)),
        ("", grouped(p.loss_events as i64)),
        ("gain", signed(p.gain_m3, 1)),
        ("loss", signed(p.loss_m3, 1)),
        ("", signed(p.net_m3, 1)),
        ("", fixed(p.mean_volume_uncertainty_m3, 1)),
        ("", fixed(p.seconds, 1)),
    ];
    w!(
        s,
        "<tr{attrs}><th class=\"l\" scope=\"row\">{}</th>",
        esc(&p.label)
    );
    for (class, content) in cells {
        if class.is_empty() {
            w!(s, "<td>{content}</td>");
        } else {
            w!(s, "<td class=\"{class}\">{content}</td>");
        }
    }
    s.push_str("</tr>\n");
}

/// A survey's label over its date.
fn survey_cell(label: &str, date: &str) -> String {
    format!("{}<span class=\"d\">{}</span>", esc(label), esc(date))
}

/// The consecutive pairs, in order: from the pair with the earliest dates, each next one the
/// pair that starts where the last one ended (same survey or same date) and ends soonest. With
/// `--baseline` the pairs first → k (k > 2) are not in it.
fn chain(pairs: &[PairRow]) -> Vec<usize> {
    let key = |i: usize| (&pairs[i].before_date, &pairs[i].after_date, i);
    let Some(first) = (0..pairs.len()).min_by_key(|&i| key(i)) else {
        return Vec::new();
    };
    let mut out = vec![first];
    while out.len() < pairs.len() {
        let last = &pairs[out[out.len() - 1]];
        let next = (0..pairs.len())
            .filter(|i| !out.contains(i))
            .filter(|&i| {
                let p = &pairs[i];
                (p.before == last.after || p.before_date == last.after_date)
                    && p.after_date > last.after_date
            })
            .min_by_key(|&i| (&pairs[i].after_date, i));
        match next {
            Some(i) => out.push(i),
            None => break,
        }
    }
    out
}

/// Distinct surveys named by the pairs.
fn surveys(pairs: &[PairRow]) -> usize {
    let mut names: Vec<&str> = pairs
        .iter()
        .flat_map(|p| [p.before.as_str(), p.after.as_str()])
        .collect();
    names.sort_unstable();
    names.dedup();
    names.len()
}

/// A CRS for a header: a WKT's name (its first quoted string), else the text, shortened.
fn crs_name(crs: &str) -> String {
    if crs.contains('[') {
        if let Some(name) = crs.split('"').nth(1) {
            return name.to_string();
        }
    }
    if crs.chars().count() > 80 {
        let short: String = crs.chars().take(77).collect();
        format!("{short}…")
    } else {
        crs.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::date::Date;
    use crate::campaign::powerlaw;

    fn pair(label: &str, before: &str, after: &str, b: &str, a: &str) -> PairRow {
        PairRow {
            label: label.into(),
            before: before.into(),
            after: after.into(),
            before_date: b.into(),
            after_date: a.into(),
            days: Date::parse(a).unwrap().days() - Date::parse(b).unwrap().days(),
            core_points: 1_234_567,
            significant_points: 45_678,
            events: 2,
            gain_events: 1,
            loss_events: 1,
            gain_m3: 12.25,
            loss_m3: -30.5,
            net_m3: -18.25,
            mean_volume_uncertainty_m3: 1.5,
            seconds: 321.25,
        }
    }

    fn square(x: f64, y: f64, r: f64) -> Vec<Vec<Vec<[f64; 3]>>> {
        vec![vec![vec![
            [x - r, y - r, 100.0],
            [x + r, y - r, 100.0],
            [x + r, y + r, 100.0],
            [x - r, y + r, 100.0],
            [x - r, y - r, 100.0],
        ]]]
    }

    fn event(
        pair: usize,
        id: u32,
        v: f64,
        significant: bool,
        track: u32,
        x: f64,
        y: f64,
    ) -> EventRow {
        EventRow {
            pair,
            id,
            kind: if v > 0.0 { "gain" } else { "loss" }.into(),
            volume_m3: Some(v),
            uncertainty_m3: Some(0.3 + 0.05 * v.abs()),
            significant,
            complete: true,
            vegetation: false,
            track_id: track,
            centroid: [x, y, 100.0],
            region: square(x, y, 1.0 + v.abs().sqrt()),
        }
    }

    /// Three consecutive pairs, 40 events, both fits.
    fn sample() -> Report {
        let pairs = vec![
            pair("A<&>B", "s1", "s2", "2023-03-14", "2023-06-20"),
            pair("s2_s3", "s2", "s3", "2023-06-20", "2023-09-12"),
            pair("s3_s4", "s3", "s4", "2023-09-12", "2024-01-05"),
        ];
        let mut events = Vec::new();
        for i in 0..40u32 {
            let v = 0.3 * (1.0 - (i as f64 + 0.5) / 40.0).powf(-1.4);
            let v = if i % 3 == 0 { v } else { -v };
            let x = 512_000.0 + 9.0 * i as f64;
            let y = 5_400_000.0 + 40.0 * ((i * 7) % 5) as f64;
            events.push(event(
                (i % 3) as usize,
                i + 1,
                v,
                i % 7 != 0,
                1 + i % 4,
                x,
                y,
            ));
        }
        let gain_fit = powerlaw::fit(&magnitudes(&events, "gain"));
        let loss_fit = powerlaw::fit(&magnitudes(&events, "loss"));
        Report {
            title: "Cliff \"North\" & <b>bay</b>".into(),
            crs: "PROJCS[\"WGS 84 / UTM zone 33N\",GEOGCS[\"WGS 84\"]]".into(),
            pairs,
            events,
            gain_fit,
            loss_fit: loss_fit.or(Some(PowerLawFit {
                alpha: 1.7,
                alpha_se: 0.2,
                x_min: 0.5,
                n_tail: 12,
                n: 20,
                ks: 0.1,
            })),
            generated_by: "talus 0.1.0".into(),
        }
    }

    fn count(h: &str, pat: &str) -> usize {
        h.matches(pat).count()
    }

    /// The text between `<tag` … `</tag>` of the element with `id`.
    fn section<'a>(h: &'a str, id: &str) -> &'a str {
        let start = h.find(&format!("<section id=\"{id}\"")).unwrap();
        let end = start + h[start..].find("</section>").unwrap();
        &h[start..end]
    }

    #[test]
    fn table_rows_and_totals() {
        let r = sample();
        let h = html(&r);
        let table = section(&h, "campaign-table");
        let body = &table[table.find("<tbody>").unwrap()..table.find("</tbody>").unwrap()];
        assert_eq!(count(body, "<tr><th class=\"l\" scope=\"row\">"), 3);
        assert_eq!(count(table, "<tfoot>"), 1);
        for p in &r.pairs {
            assert!(table.contains(&esc(&p.label)));
            assert!(table.contains(&p.after_date));
        }
        // Every field, rounded: 1 234 567 core points, 45 678 significant (3.7 %), volumes.
        assert!(table.contains("1\u{202f}234\u{202f}567"));
        assert!(table.contains("45\u{202f}678<span class=\"d\">3.7 %</span>"));
        assert!(table.contains(">+12.3<") || table.contains(">+12.2<"));
        assert!(table.contains(">−30.5<"));
        assert!(table.contains(">321.3<") || table.contains(">321.2<"));
        // Totals: 3 × the per-pair values; days from the first to the last survey.
        assert!(table.contains(">+36.8<"), "gain total");
        assert!(table.contains(">−91.5<"));
        assert!(table.contains(">−54.8<"));
        assert!(table.contains(&format!(">{}<", 98 + 84 + 115)));
        assert!(table.contains(">963.8<"));
    }

    #[test]
    fn four_sections_with_their_svgs() {
        let r = sample();
        let h = html(&r);
        assert_eq!(count(&h, "<section "), 4);
        assert_eq!(count(&h, "<svg "), 2 + r.pairs.len());
        assert_eq!(count(section(&h, "cumulative"), "<svg "), 1);
        assert_eq!(count(section(&h, "magnitude-frequency"), "<svg "), 1);
        assert_eq!(count(section(&h, "maps"), "<svg "), r.pairs.len());
        assert_eq!(count(&h, "</svg>"), 2 + r.pairs.len());
        // Every SVG is labelled.
        assert_eq!(
            count(&h, "role=\"img\" aria-labelledby="),
            2 + r.pairs.len()
        );
        let cum = section(&h, "cumulative");
        assert_eq!(count(cum, "class=\"series\""), 3);
        assert!(cum.contains("Cumulative volume (m³)") && cum.contains("Survey date"));
        let mf = section(&h, "magnitude-frequency");
        assert_eq!(count(mf, "class=\"fit\""), 2);
        assert!(mf.contains("Event volume |V| (m³)"));
        assert_eq!(count(mf, "α = "), 2);
        let maps = section(&h, "maps");
        assert_eq!(count(maps, "<path class=\"event "), r.events.len());
        assert_eq!(count(maps, "class=\"scale-bar\""), r.pairs.len());
        assert_eq!(count(maps, "class=\"north\""), r.pairs.len());
        // Non-significant events hatched.
        let hatched = r.events.iter().filter(|e| !e.significant).count();
        let hatched_paths = maps
            .lines()
            .filter(|l| l.starts_with("<path class=\"event ") && l.contains("fill=\"url(#hatch-"))
            .count();
        assert_eq!(hatched_paths, hatched);
        assert!(h.starts_with("<!DOCTYPE html>") && h.ends_with("</html>\n"));
        assert!(h.contains(
            "<title>Cliff &quot;North&quot; &amp; &lt;b&gt;bay&lt;/b&gt; — campaign report</title>"
        ));
        assert!(h.contains("<h1>") && h.contains("<h2 id=\"h-maps\">"));
        assert!(h.contains(">WGS 84 / UTM zone 33N</span>"));
    }

    #[test]
    fn an_incomplete_event_is_dashed_without_an_interval() {
        let mut r = sample();
        let before = html(&r);
        assert!(!before.contains("stroke-dasharray=\"3 2\""));
        let e = &mut r.events[0];
        e.complete = false;
        let id = e.id;
        let h = html(&r);
        assert_eq!(
            h.matches("stroke-dasharray=\"3 2\"").count(),
            1,
            "one dashed outline"
        );
        let tip = h
            .split("<title>")
            .find(|t| t.starts_with(&format!("Event {id} (")))
            .expect("the event's tooltip");
        assert!(tip.contains("incomplete: measured in part only"), "{tip}");
        assert!(
            !tip.split("</title>").next().unwrap().contains('±'),
            "{tip}"
        );
        assert!(
            h.contains("Dashed: incomplete"),
            "the legend says what dashed means"
        );
    }

    /// One gain/loss convention in the viewer and the report (issue "Trust, second round"): the
    /// viewer's (gain red, loss blue: its markers and distance ramp, viewer/src/events.js and
    /// colormap.js), with the legend saying it.
    #[test]
    fn gains_are_red_and_losses_blue_as_in_the_viewer_and_the_legend_says_so() {
        let viewer = include_str!("../../../viewer/src/colormap.js");
        assert!(viewer.contains("blue = loss") && viewer.contains("red = gain"));
        let h = html(&sample());
        assert!(h.contains("--gain:#b2182b;--loss:#2166ac"));
        assert!(h.contains("Gain (red: material added)"));
        assert!(h.contains("Loss (blue: material removed)"));
    }

    #[test]
    fn strings_are_escaped() {
        let h = html(&sample());
        assert!(!h.contains("<&>"));
        assert!(!h.contains("<b>bay"));
        assert!(h.contains("A&lt;&amp;&gt;B"));
        // Every '&' starts an entity.
        for (i, _) in h.match_indices('&') {
            let rest = &h[i..(i + 8).min(h.len())];
            assert!(
                ["&amp;", "&lt;", "&gt;", "&quot;", "&#39;"]
                    .iter()
                    .any(|e| rest.starts_with(e)),
                "bare & at {i}: {rest}"
            );
        }
    }

    #[test]
    fn nothing_is_fetched() {
        let h = html(&sample());
        assert!(!h.contains("http://") && !h.contains("https://"));
        assert!(!h.contains("<script") && !h.contains("<link") && !h.contains("@import"));
        assert!(!h.contains("src=") && !h.contains("href="));
        // url() only for the page's own fragments.
        for (i, _) in h.match_indices("url(") {
            assert_eq!(&h[i + 4..i + 5], "#", "{}", &h[i..i + 20]);
        }
    }

    #[test]
    fn identical_input_identical_bytes() {
        let r = sample();
        let a = html(&r);
        let back: Report = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
        assert_eq!(a, html(&back));
        assert_eq!(a, html(&r.clone()));
    }

    #[test]
    fn empty_cases_still_render() {
        let mut r = sample();
        r.events.clear();
        r.gain_fit = None;
        r.loss_fit = None;
        let h = html(&r);
        assert_eq!(count(&h, "<svg "), 2 + r.pairs.len());
        assert!(h.contains("No significant events with a volume"));
        assert!(h.contains("No events"));
        assert_eq!(count(&h, "class=\"fit\""), 0);

        // One pair, events but no fit.
        let mut r = sample();
        r.pairs.truncate(1);
        r.events.retain(|e| e.pair == 0);
        r.gain_fit = None;
        r.loss_fit = None;
        let h = html(&r);
        assert_eq!(count(&h, "<svg "), 3);
        assert_eq!(count(&h, "no power-law fit"), 2);
        assert_eq!(count(&h, "<tfoot>"), 1);

        // Nothing at all.
        let r = Report {
            title: String::new(),
            crs: String::new(),
            pairs: Vec::new(),
            events: Vec::new(),
            gain_fit: None,
            loss_fit: None,
            generated_by: String::new(),
        };
        let h = html(&r);
        assert_eq!(count(&h, "<section "), 4);
        assert!(h.contains("No pairs"));
        assert!(h.ends_with("</html>\n"));

        // An event without a region, one with a volume missing, one of a pair out of range.
        let mut r = sample();
        r.events[0].region.clear();
        r.events[1].volume_m3 = None;
        r.events[2].pair = 99;
        let h = html(&r);
        assert!(h.contains("class=\"event-mark\""));
        assert!(h.contains("no volume"));
    }

    #[test]
    fn baseline_pairs_stay_out_of_totals() {
        let mut r = sample();
        r.pairs
            .push(pair("s1_s3", "s1", "s3", "2023-03-14", "2023-09-12"));
        assert_eq!(chain(&r.pairs), vec![0, 1, 2]);
        let h = html(&r);
        assert_eq!(count(&h, "<tr class=\"baseline\">"), 1);
        assert!(h.contains(">+36.8<"));
        // Pairs given out of order still chain by date.
        let p = sample().pairs;
        assert_eq!(
            chain(&[p[2].clone(), p[0].clone(), p[1].clone()]),
            vec![1, 2, 0]
        );
    }

    #[test]
    fn track_labels_do_not_overlap() {
        let mut r = sample();
        // Twenty events on top of one another, each with its own track.
        r.events = (0..20)
            .map(|i| {
                event(
                    0,
                    i + 1,
                    -1.0 - i as f64,
                    true,
                    i + 1,
                    512_100.0,
                    5_400_100.0 + 0.2 * i as f64,
                )
            })
            .collect();
        r.events
            .push(event(1, 50, 4.0, true, 3, 512_000.0, 5_400_000.0));
        let h = html(&r);
        let labels = count(section(&h, "maps"), "class=\"track\"");
        assert!((2..20).contains(&labels), "{labels} labels");
        // The largest event's track is the one kept.
        assert!(h.contains(">T20</text>"));
    }
}
