//! The campaign's `report.html` (SPEC.md §5): one self-contained page a geomorphologist can hand
//! on — nothing is fetched (inline CSS and SVG, no script, no fonts but the reader's own), and
//! the same inputs give the same bytes (no time stamp; every number printed at a fixed
//! precision).
//!
//! It shows, in this order:
//! 1. the campaign table (the paper's Table 1 completed): one row per pair as given, totals over
//!    the consecutive pairs;
//! 2. cumulative significant gain, loss and net volume over time, along the chain of consecutive
//!    pairs (baseline pairs, `--baseline`, would count the same change twice and are left out);
//! 3. the magnitude–frequency plot: the exceedance N(≥ |V|) of the significant events' volumes,
//!    per gain and loss, on log–log axes, with the fitted power laws
//!    ([`super::powerlaw`]) over their tails;
//! 4. a plan-view map per pair (x/y of the event regions, one extent and scale for all pairs),
//!    gains and losses in two colours, events below their uncertainty hatched, the other pairs'
//!    events as faint outlines, track ids where they do not overlap, a scale bar and north arrow.
//!
//! Colours: the viewer's convention (its distance ramp, ColorBrewer RdBu): gain red (#b2182b),
//! loss blue (#2166ac), a diverging pair readers with any common colour-vision deficiency tell
//! apart; the marks differ in shape too (circles for gains, squares for losses), and the legend
//! says which is which.

use super::powerlaw::{self, PowerLawFit};
use std::fmt::Write;

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
        .filter(|e| e.significant && e.kind == kind)
        .filter_map(|e| e.volume_m3)
        .map(f64::abs)
        .collect()
}

const GAIN: &str = "#b2182b";
const LOSS: &str = "#2166ac";
const NET: &str = "#2b2b2b";
const INK: &str = "#1a1a1a";
const MUTED: &str = "#5f6368";
const GRID: &str = "#e4e4e4";
const AXIS: &str = "#8a8a8a";
/// Chart widths in CSS pixels (the page's content is 1120 px wide).
const WIDTH: f64 = 1120.0;

/// `write!` into a String, which cannot fail.
macro_rules! w {
    ($($t:tt)*) => {{
        let _ = write!($($t)*);
    }};
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

// ---------------------------------------------------------------------------------------------
// Header and table

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

// ---------------------------------------------------------------------------------------------
// Cumulative change over time

fn cumulative_section(s: &mut String, report: &Report, chain: &[usize]) {
    s.push_str(
        "<section id=\"cumulative\" aria-labelledby=\"h-cumulative\">\n\
         <h2 id=\"h-cumulative\">2. Cumulative change</h2>\n",
    );
    s.push_str(&cumulative_svg(report, chain));
    s.push_str(
        "<p class=\"note\">Running totals of the significant events' volumes, from the first \
         survey; one mark per survey. Change is known only at survey dates: the lines join \
         them.</p>\n</section>\n",
    );
}

fn cumulative_svg(report: &Report, chain: &[usize]) -> String {
    let (w, h) = (WIDTH, 380.0);
    let (l, r, t, b) = (84.0, 150.0, 40.0, 58.0);
    let mut s = svg_open(
        w,
        h,
        "cumulative-title",
        "Cumulative significant gain, loss and net volume over time",
    );
    if chain.is_empty() {
        empty_note(&mut s, w, h, "No pairs");
        s.push_str("</svg>\n");
        return s;
    }
    let pairs: Vec<&PairRow> = chain.iter().map(|&i| &report.pairs[i]).collect();
    // x: the first survey's date, then each pair's after date (days); the survey index when a
    // date does not parse.
    let mut labels = vec![pairs[0].before_date.clone()];
    labels.extend(pairs.iter().map(|p| p.after_date.clone()));
    let parsed: Option<Vec<i64>> = labels.iter().map(|d| parse_date(d)).collect();
    let xs: Vec<f64> = match &parsed {
        Some(d) => d.iter().map(|&v| v as f64).collect(),
        None => (0..labels.len()).map(|i| i as f64).collect(),
    };
    let mut gain = vec![0.0];
    let mut loss = vec![0.0];
    let mut net = vec![0.0];
    for p in &pairs {
        gain.push(gain[gain.len() - 1] + finite(p.gain_m3).abs());
        loss.push(loss[loss.len() - 1] - finite(p.loss_m3).abs());
        net.push(net[net.len() - 1] + finite(p.net_m3));
    }
    let (mut x0, mut x1) = (xs[0], xs[xs.len() - 1]);
    if x1 <= x0 {
        x0 -= 1.0;
        x1 += 1.0;
    }
    let all = gain.iter().chain(&loss).chain(&net);
    let lo = all.clone().fold(0.0f64, |a, &v| a.min(v));
    let hi = all.fold(0.0f64, |a, &v| a.max(v));
    let (ylo, yhi, ystep) = nice_range(lo, hi, 8);
    let (pw, ph) = (w - l - r, h - t - b);
    let px = |x: f64| l + (x - x0) / (x1 - x0) * pw;
    let py = |y: f64| t + (yhi - y) / (yhi - ylo) * ph;

    // y grid, ticks and labels.
    let mut y = ylo;
    let decimals = step_decimals(ystep);
    while y <= yhi + ystep * 1e-9 {
        let yy = py(y);
        let colour = if y.abs() < ystep * 1e-9 { AXIS } else { GRID };
        y_grid(&mut s, (l, l + pw), yy, colour, &signed_tick(y, decimals));
        y += ystep;
    }
    // x axis and ticks.
    let base = t + ph;
    w!(
        s,
        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{AXIS}\"/>\n",
        c(l),
        c(base),
        c(l + pw),
        c(base)
    );
    match &parsed {
        Some(_) => {
            for (x, month, year) in month_ticks(x0, x1, pw) {
                let xx = px(x);
                x_tick(&mut s, xx, base, &month);
                if let Some(year) = year {
                    w!(
                        s,
                        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12\" fill=\"{MUTED}\">{year}</text>\n",
                        c(xx),
                        c(base + 32.0)
                    );
                }
            }
        }
        None => {
            for (x, label) in xs.iter().zip(&labels) {
                x_tick(&mut s, px(*x), base, &esc(label));
            }
        }
    }
    // Axis titles.
    w!(
        s,
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12.5\" fill=\"{INK}\">Survey date</text>\n\
         <text transform=\"translate(18 {}) rotate(-90)\" text-anchor=\"middle\" font-size=\"12.5\" fill=\"{INK}\">Cumulative volume (m³)</text>\n",
        c(l + pw / 2.0),
        c(h - 6.0),
        c(t + ph / 2.0)
    );
    // Areas under gain and loss, then the three lines with a mark per survey.
    let zero = py(0.0);
    for (vals, colour) in [(&gain, GAIN), (&loss, LOSS)] {
        let mut d = format!("M{} {}", c(px(xs[0])), c(zero));
        for (x, v) in xs.iter().zip(vals.iter()) {
            w!(d, "L{} {}", c(px(*x)), c(py(*v)));
        }
        w!(d, "L{} {}Z", c(px(xs[xs.len() - 1])), c(zero));
        w!(
            s,
            "<path d=\"{d}\" fill=\"{colour}\" fill-opacity=\"0.09\" stroke=\"none\"/>\n"
        );
    }
    let series: [(&str, &[f64], &str, &str); 3] = [
        ("Gain", &gain, GAIN, ""),
        ("Loss", &loss, LOSS, ""),
        ("Net", &net, NET, " stroke-dasharray=\"6 4\""),
    ];
    for (name, vals, colour, dash) in series {
        let pts: Vec<String> = xs
            .iter()
            .zip(vals.iter())
            .map(|(x, v)| format!("{},{}", c(px(*x)), c(py(*v))))
            .collect();
        w!(
            s,
            "<polyline class=\"series\" data-series=\"{}\" points=\"{}\" fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\"{dash} stroke-linejoin=\"round\"/>\n",
            name.to_lowercase(),
            pts.join(" ")
        );
        for (i, (x, v)) in xs.iter().zip(vals.iter()).enumerate() {
            w!(
                s,
                "<circle cx=\"{}\" cy=\"{}\" r=\"3.2\" fill=\"#fff\" stroke=\"{colour}\" stroke-width=\"1.6\"><title>{}: {} m³ ({})</title></circle>\n",
                c(px(*x)),
                c(py(*v)),
                name,
                signed(*v, 1),
                esc(&labels[i])
            );
        }
    }
    // End labels, pushed apart so they never overlap.
    let last = xs.len() - 1;
    let mut ends: Vec<(f64, &str, f64, &str)> = series
        .iter()
        .map(|(name, vals, colour, _)| (py(vals[last]), *name, vals[last], *colour))
        .collect();
    ends.sort_by(|a, b| a.0.total_cmp(&b.0));
    let ys = spread(
        &ends.iter().map(|e| e.0).collect::<Vec<_>>(),
        15.0,
        t,
        t + ph,
    );
    for ((_, name, v, colour), y) in ends.iter().zip(ys) {
        w!(
            s,
            "<text x=\"{}\" y=\"{}\" font-size=\"12.5\" fill=\"{colour}\" font-weight=\"600\">{name} {} m³</text>\n",
            c(l + pw + 10.0),
            c(y + 4.0),
            signed(*v, 1)
        );
    }
    // Legend above the plot.
    let mut x = l;
    for (name, _, colour, dash) in series {
        let text = match name {
            "Gain" => "Gain (deposits)",
            "Loss" => "Loss (erosion, rockfall)",
            _ => "Net",
        };
        w!(
            s,
            "<line x1=\"{}\" y1=\"16\" x2=\"{}\" y2=\"16\" stroke=\"{colour}\" stroke-width=\"2\"{dash}/>\
             <text x=\"{}\" y=\"20\" font-size=\"12.5\" fill=\"{INK}\">{text}</text>\n",
            c(x),
            c(x + 22.0),
            c(x + 28.0)
        );
        x += 28.0 + 7.0 * text.chars().count() as f64 + 24.0;
    }
    s.push_str("</svg>\n");
    s
}

/// A horizontal grid line across `span` at `y` with its label left of it.
fn y_grid(s: &mut String, span: (f64, f64), y: f64, colour: &str, label: &str) {
    w!(
        s,
        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{2}\" y2=\"{1}\" stroke=\"{colour}\"/>\
         <text x=\"{3}\" y=\"{4}\" text-anchor=\"end\" font-size=\"12\" fill=\"{MUTED}\">{label}</text>\n",
        c(span.0),
        c(y),
        c(span.1),
        c(span.0 - 8.0),
        c(y + 4.0)
    );
}

/// A tick below the axis at `base` and its label under it.
fn x_tick(s: &mut String, x: f64, base: f64, label: &str) {
    w!(
        s,
        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"{AXIS}\"/>\
         <text x=\"{0}\" y=\"{3}\" text-anchor=\"middle\" font-size=\"12\" fill=\"{MUTED}\">{label}</text>\n",
        c(x),
        c(base),
        c(base + 5.0),
        c(base + 18.0)
    );
}

/// Positions for labels wanted at the ascending `ys`, at least `gap` apart, within [lo, hi].
fn spread(ys: &[f64], gap: f64, lo: f64, hi: f64) -> Vec<f64> {
    let mut out: Vec<f64> = ys.to_vec();
    for i in 0..out.len() {
        out[i] = out[i].max(lo);
        if i > 0 {
            out[i] = out[i].max(out[i - 1] + gap);
        }
    }
    for i in (0..out.len()).rev() {
        out[i] = out[i].min(hi);
        if i + 1 < out.len() {
            out[i] = out[i].min(out[i + 1] - gap);
        }
    }
    out
}

const MONTHS: [&str; 12] = [
    "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
];

/// Ticks on the first day of months between days x0 and x1, every 1, 2, 3, 6 or 12 months or
/// a multiple of years, as many as fit 70 px apart: (day, month label, year where it changes).
fn month_ticks(x0: f64, x1: f64, width: f64) -> Vec<(f64, String, Option<i64>)> {
    let (y0, m0, _) = civil_from_days(x0.floor() as i64);
    let months = ((x1 - x0) / 30.44).max(1.0);
    let fit = (width / 70.0).max(1.0);
    let step = [1, 2, 3, 6, 12, 24, 60, 120]
        .into_iter()
        .find(|&k| months / k as f64 <= fit)
        .unwrap_or(240);
    let mut out = Vec::new();
    let mut last_year = None;
    let (mut y, mut m) = (y0, m0);
    loop {
        let day = days_from_civil(y, m, 1) as f64;
        if day > x1 {
            break;
        }
        if day >= x0 && (y * 12 + (m - 1)) % step == 0 {
            let year = (last_year != Some(y)).then_some(y);
            last_year = Some(y);
            let label = if step >= 12 {
                y.to_string()
            } else {
                MONTHS[(m - 1) as usize].to_string()
            };
            out.push((day, label, if step >= 12 { None } else { year }));
        }
        m += 1;
        if m > 12 {
            m = 1;
            y += 1;
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Magnitude–frequency

fn magnitude_section(s: &mut String, report: &Report) {
    s.push_str(
        "<section id=\"magnitude-frequency\" aria-labelledby=\"h-mf\">\n\
         <h2 id=\"h-mf\">3. Magnitude–frequency</h2>\n",
    );
    s.push_str(&magnitude_svg(report));
    s.push_str(
        "<p class=\"note\">Marks: the number of significant events of each kind, over all \
         pairs, whose volume is at least |V|. Lines: the fitted power laws \
         N(≥ |V|) = n<sub>tail</sub> (|V| / x<sub>min</sub>)<sup>1−α</sup> over their tails \
         |V| ≥ x<sub>min</sub> (density ∝ |V|<sup>−α</sup>); ± is one standard error.</p>\n\
         </section>\n",
    );
}

fn magnitude_svg(report: &Report) -> String {
    let (w, h) = (WIDTH, 440.0);
    let (l, t, b) = (78.0, 16.0, 56.0);
    // The legend takes the right 300 px.
    let pw = w - l - 330.0;
    let ph = h - t - b;
    let mut s = svg_open(
        w,
        h,
        "mf-title",
        "Magnitude–frequency: exceedance of event volume, log–log, with fitted power laws",
    );
    let kinds = [
        ("gain", "Gains", GAIN, &report.gain_fit),
        ("loss", "Losses", LOSS, &report.loss_fit),
    ];
    let rows: Vec<Vec<(f64, usize, f64)>> = kinds
        .iter()
        .map(|(k, ..)| powerlaw::exceedance(&magnitudes(&report.events, k)))
        .collect();
    let values = rows.iter().flatten().map(|r| r.0);
    let (Some(vmin), Some(vmax)) = (
        values.clone().min_by(f64::total_cmp),
        values.max_by(f64::total_cmp),
    ) else {
        empty_note(&mut s, w, h, "No significant events with a volume");
        s.push_str("</svg>\n");
        return s;
    };
    let nmax = rows.iter().map(|r| r.len()).max().unwrap_or(1).max(1) as f64;
    let lx0 = (vmin.log10() - 0.05).floor();
    let mut lx1 = (vmax.log10() + 0.05).ceil();
    if lx1 <= lx0 {
        lx1 = lx0 + 1.0;
    }
    let ly0 = -0.15;
    let ly1 = (nmax.log10() + 0.08).ceil().max(1.0);
    let px = |v: f64| l + (v.log10() - lx0) / (lx1 - lx0) * pw;
    let py = |n: f64| t + (ly1 - n.log10()) / (ly1 - ly0) * ph;

    w!(
        s,
        "<defs><clipPath id=\"mf-clip\"><rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/></clipPath></defs>\n",
        c(l),
        c(t),
        c(pw),
        c(ph)
    );
    // Decade grid, ticks and labels; minor ticks at 2..9.
    for (lo, hi, horizontal) in [(lx0, lx1, false), (ly0.ceil(), ly1, true)] {
        let mut k = lo as i64;
        while k as f64 <= hi {
            let v = 10f64.powi(k as i32);
            let label = decade(k);
            if horizontal {
                y_grid(&mut s, (l, l + pw), py(v), GRID, &label);
            } else {
                let x = px(v);
                w!(
                    s,
                    "<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"{GRID}\"/>",
                    c(x),
                    c(t),
                    c(t + ph)
                );
                x_tick(&mut s, x, t + ph, &label);
            }
            for m in 2..10 {
                let mv = v * m as f64;
                if horizontal && mv.log10() < ly1 {
                    w!(
                        s,
                        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{2}\" y2=\"{1}\" stroke=\"{AXIS}\"/>",
                        c(l - 3.0),
                        c(py(mv)),
                        c(l)
                    );
                } else if !horizontal && mv.log10() < lx1 {
                    w!(
                        s,
                        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"{AXIS}\"/>",
                        c(px(mv)),
                        c(t + ph),
                        c(t + ph + 3.0)
                    );
                }
            }
            s.push('\n');
            k += 1;
        }
    }
    w!(
        s,
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"{AXIS}\"/>\n\
         <text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12.5\" fill=\"{INK}\">Event volume |V| (m³)</text>\n\
         <text transform=\"translate(20 {}) rotate(-90)\" text-anchor=\"middle\" font-size=\"12.5\" fill=\"{INK}\">Number of events ≥ |V|</text>\n",
        c(l),
        c(t),
        c(pw),
        c(ph),
        c(l + pw / 2.0),
        c(h - 10.0),
        c(t + ph / 2.0)
    );
    // Fit lines under the marks.
    for ((kind, _, colour, fit), rows) in kinds.iter().zip(&rows) {
        let (Some(f), Some(top)) = (fit, rows.first()) else {
            continue;
        };
        if !(f.x_min > 0.0 && f.alpha.is_finite()) {
            continue;
        }
        let x_end = top.0.max(f.x_min);
        let n_at = |v: f64| f.n_tail as f64 * (v / f.x_min).powf(1.0 - f.alpha);
        w!(
            s,
            "<line class=\"fit\" data-kind=\"{kind}\" x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{colour}\" stroke-width=\"2\" clip-path=\"url(#mf-clip)\"/>\
             <line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{4}\" stroke=\"{colour}\" stroke-width=\"1\" stroke-dasharray=\"2 3\"/>\n",
            c(px(f.x_min)),
            c(py(n_at(f.x_min))),
            c(px(x_end)),
            c(py(n_at(x_end))),
            c(t + ph)
        );
    }
    for ((kind, name, colour, _), rows) in kinds.iter().zip(&rows) {
        w!(
            s,
            "<g class=\"marks\" data-kind=\"{kind}\" fill=\"{colour}\" fill-opacity=\"0.85\" stroke=\"#fff\" stroke-width=\"0.8\">"
        );
        // One mark per distinct value (tied values share their count).
        let mut prev = None;
        for &(v, n, _) in rows {
            if prev == Some(v) {
                continue;
            }
            prev = Some(v);
            let (x, y) = (px(v), py(n as f64));
            let tip = format!("{}: {} events ≥ {} m³", name, n, sig3(v));
            if *kind == "gain" {
                w!(
                    s,
                    "<circle cx=\"{}\" cy=\"{}\" r=\"3.6\"><title>{tip}</title></circle>",
                    c(x),
                    c(y)
                );
            } else {
                w!(
                    s,
                    "<rect x=\"{}\" y=\"{}\" width=\"6.6\" height=\"6.6\"><title>{tip}</title></rect>",
                    c(x - 3.3),
                    c(y - 3.3)
                );
            }
        }
        s.push_str("</g>\n");
    }
    // Legend to the right of the plot.
    let lx = l + pw + 34.0;
    let mut y = t + 14.0;
    for ((kind, name, colour, fit), rows) in kinds.iter().zip(&rows) {
        let mark = if *kind == "gain" {
            format!(
                "<circle cx=\"{}\" cy=\"{}\" r=\"4\" fill=\"{colour}\"/>",
                c(lx + 5.0),
                c(y - 4.0)
            )
        } else {
            format!(
                "<rect x=\"{}\" y=\"{}\" width=\"7.5\" height=\"7.5\" fill=\"{colour}\"/>",
                c(lx + 1.25),
                c(y - 7.75)
            )
        };
        w!(
            s,
            "{mark}<text x=\"{}\" y=\"{}\" font-size=\"13\" font-weight=\"600\" fill=\"{INK}\">{name}: {} event{}</text>\n",
            c(lx + 16.0),
            c(y),
            rows.len(),
            plural(rows.len())
        );
        y += 19.0;
        match fit {
            Some(f) => {
                w!(
                    s,
                    "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{1}\" stroke=\"{colour}\" stroke-width=\"2\"/>\
                     <text class=\"fit-legend\" x=\"{}\" y=\"{}\" font-size=\"12.5\" fill=\"{INK}\">α = {} ± {}</text>\n\
                     <text x=\"{3}\" y=\"{}\" font-size=\"12.5\" fill=\"{MUTED}\">x<tspan font-size=\"9\" dy=\"3\">min</tspan><tspan dy=\"-3\"> = {} m³, n</tspan><tspan font-size=\"9\" dy=\"3\">tail</tspan><tspan dy=\"-3\"> = {} of {}</tspan></text>\n",
                    c(lx),
                    c(y - 4.0),
                    c(lx + 11.0),
                    c(lx + 16.0),
                    c(y),
                    fixed(f.alpha, 2),
                    fixed(f.alpha_se, 2),
                    c(y + 17.0),
                    sig3(f.x_min),
                    f.n_tail,
                    f.n
                );
                y += 17.0;
            }
            None => {
                w!(
                    s,
                    "<text x=\"{}\" y=\"{}\" font-size=\"12.5\" fill=\"{MUTED}\">no power-law fit (fewer than {} values)</text>\n",
                    c(lx + 16.0),
                    c(y),
                    powerlaw::MIN_TAIL
                );
            }
        }
        y += 34.0;
    }
    w!(
        s,
        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{1}\" stroke=\"{MUTED}\" stroke-dasharray=\"2 3\"/>\
         <text x=\"{}\" y=\"{}\" font-size=\"12\" fill=\"{MUTED}\">x<tspan font-size=\"9\" dy=\"3\">min</tspan></text>\n",
        c(lx),
        c(y - 4.0),
        c(lx + 11.0),
        c(lx + 16.0),
        c(y)
    );
    s.push_str("</svg>\n");
    s
}

/// A decade's tick label: 0.001 … 100 000, else 10 with a superscript exponent.
fn decade(k: i64) -> String {
    match k {
        -3..=-1 => format!("0.{}1", "0".repeat((-k - 1) as usize)),
        0..=5 => grouped(10i64.pow(k as u32)),
        _ => format!(
            "10<tspan dy=\"-6\" font-size=\"9\">{}</tspan>",
            minus(k.to_string())
        ),
    }
}

// ---------------------------------------------------------------------------------------------
// Maps

/// The x/y box of every event (regions and centroids), with a margin.
#[derive(Clone, Copy)]
struct Extent {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

fn extent(report: &Report) -> Option<Extent> {
    let mut e: Option<Extent> = None;
    let mut add = |x: f64, y: f64| {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let b = e.get_or_insert(Extent {
            x0: x,
            y0: y,
            x1: x,
            y1: y,
        });
        b.x0 = b.x0.min(x);
        b.y0 = b.y0.min(y);
        b.x1 = b.x1.max(x);
        b.y1 = b.y1.max(y);
    };
    for ev in report.events.iter().filter(|e| e.pair < report.pairs.len()) {
        add(ev.centroid[0], ev.centroid[1]);
        for p in ev.region.iter().flatten().flatten() {
            add(p[0], p[1]);
        }
    }
    e.map(|b| {
        let margin = (0.06 * (b.x1 - b.x0).max(b.y1 - b.y0)).max(2.0);
        Extent {
            x0: b.x0 - margin,
            y0: b.y0 - margin,
            x1: b.x1 + margin,
            y1: b.y1 + margin,
        }
    })
}

fn maps_section(s: &mut String, report: &Report) {
    s.push_str(
        "<section id=\"maps\" aria-labelledby=\"h-maps\">\n<h2 id=\"h-maps\">4. Event maps</h2>\n\
         <div class=\"legend\"><span><i class=\"sw g\"></i>Gain (red: material added)</span><span><i class=\"sw l\"></i>Loss (blue: material removed)</span>\
         <span><i class=\"sw hg\"></i><i class=\"sw hl\"></i>Below its 95 % uncertainty (hollow marks where small)</span>\
         <span><i class=\"sw inc\"></i>Dashed: incomplete, measured in part only (no 95 % bound)</span>\
         <span><i class=\"sw o\"></i>Events of the other pairs</span><span>T4: track 4 (events at one place across pairs)</span></div>\n",
    );
    let ext = extent(report);
    if report.pairs.is_empty() {
        s.push_str("<p class=\"note\">No pairs.</p>\n");
    }
    s.push_str("<div class=\"maps\">\n");
    for k in 0..report.pairs.len() {
        let p = &report.pairs[k];
        s.push_str("<figure>\n");
        s.push_str(&map_svg(report, k, ext));
        w!(
            s,
            "<figcaption><strong>{}</strong><span class=\"u\">{} → {}, {} days</span>\
             <span class=\"u\">{} event{}: <span class=\"gain\">{} m³</span>, \
             <span class=\"loss\">{} m³</span></span></figcaption>\n</figure>\n",
            esc(&p.label),
            esc(&p.before_date),
            esc(&p.after_date),
            grouped(p.days),
            grouped(p.events as i64),
            plural(p.events),
            signed(p.gain_m3, 1),
            signed(p.loss_m3, 1)
        );
    }
    s.push_str("</div>\n");
    if let Some(e) = ext {
        w!(
            s,
            "<p class=\"note\">Plan view (x east, y north{}), the same extent and scale in every \
             panel: x {} to {}, y {} to {} m; the grid is the scale bar's length. Hatched events \
             are below their 95 % uncertainty; hover a region for its volume.</p>\n",
            if report.crs.is_empty() {
                String::new()
            } else {
                format!(", {}", esc(&crs_name(&report.crs)))
            },
            grouped(e.x0.round() as i64),
            grouped(e.x1.round() as i64),
            grouped(e.y0.round() as i64),
            grouped(e.y1.round() as i64)
        );
    }
    s.push_str("</section>\n");
}

/// A label's box in pixels.
#[derive(Clone, Copy)]
struct Box2 {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Box2 {
    fn overlaps(&self, o: &Box2) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }
}

fn map_svg(report: &Report, k: usize, ext: Option<Extent>) -> String {
    let p = &report.pairs[k];
    let w = 360.0;
    let pad = 1.0;
    let strip = 30.0;
    let max_h = 300.0;
    let Some(e) = ext else {
        let h = 200.0;
        let mut s = svg_open(
            w,
            h,
            &format!("map-title-{k}"),
            &format!("Map of pair {}: no events", p.label),
        );
        w!(
            s,
            "<rect x=\"0.5\" y=\"0.5\" width=\"{}\" height=\"{}\" fill=\"#fbfbfb\" stroke=\"{GRID}\"/>\n",
            c(w - 1.0),
            c(h - 1.0)
        );
        empty_note(&mut s, w, h, "No events");
        s.push_str("</svg>\n");
        return s;
    };
    let (dx, dy) = (e.x1 - e.x0, e.y1 - e.y0);
    let scale = ((w - 2.0 * pad) / dx).min(max_h / dy);
    let (mw, mh) = (dx * scale, dy * scale);
    let ox = pad + ((w - 2.0 * pad) - mw) / 2.0;
    let oy = pad;
    let h = oy + mh + strip;
    let px = |x: f64| ox + (x - e.x0) * scale;
    let py = |y: f64| oy + (e.y1 - y) * scale;
    let mut s = svg_open(
        w,
        h,
        &format!("map-title-{k}"),
        &format!(
            "Plan-view map of the events of pair {} ({} to {})",
            p.label, p.before_date, p.after_date
        ),
    );
    w!(
        s,
        "<defs><clipPath id=\"map-clip-{k}\"><rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/></clipPath>",
        c(ox),
        c(oy),
        c(mw),
        c(mh)
    );
    for (kind, colour) in [("gain", GAIN), ("loss", LOSS)] {
        w!(
            s,
            "<pattern id=\"hatch-{kind}-{k}\" patternUnits=\"userSpaceOnUse\" width=\"4\" height=\"4\" patternTransform=\"rotate(45)\">\
             <rect width=\"4\" height=\"4\" fill=\"#fff\"/><line x1=\"1\" y1=\"0\" x2=\"1\" y2=\"4\" stroke=\"{colour}\" stroke-width=\"1.5\"/></pattern>"
        );
    }
    s.push_str("</defs>\n");
    w!(
        s,
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"#fbfbfb\"/>\n",
        c(ox),
        c(oy),
        c(mw),
        c(mh)
    );
    // Grid at the scale bar's length.
    let step = nice_step(dx.max(dy) / 4.0);
    let mut g = String::new();
    let mut x = (e.x0 / step).ceil() * step;
    while x < e.x1 {
        w!(g, "M{} {}V{}", c(px(x)), c(oy), c(oy + mh));
        x += step;
    }
    let mut y = (e.y0 / step).ceil() * step;
    while y < e.y1 {
        w!(g, "M{} {}H{}", c(ox), c(py(y)), c(ox + mw));
        y += step;
    }
    w!(
        s,
        "<path d=\"{g}\" stroke=\"#ececec\" stroke-width=\"1\" fill=\"none\"/>\n"
    );
    let path_of = |ev: &EventRow| {
        let mut d = String::new();
        for ring in ev.region.iter().flatten() {
            for (i, q) in ring.iter().enumerate() {
                w!(
                    d,
                    "{}{} {}",
                    if i == 0 { "M" } else { "L" },
                    c(px(q[0])),
                    c(py(q[1]))
                );
            }
            if !ring.is_empty() {
                d.push('Z');
            }
        }
        d
    };
    // The other pairs' events, faint.
    let mut others = String::new();
    for ev in report
        .events
        .iter()
        .filter(|e| e.pair != k && e.pair < report.pairs.len())
    {
        others.push_str(&path_of(ev));
    }
    if !others.is_empty() {
        w!(
            s,
            "<path class=\"context\" d=\"{others}\" fill=\"none\" stroke=\"#c4c4c4\" stroke-width=\"0.8\" clip-path=\"url(#map-clip-{k})\"/>\n"
        );
    }
    // This pair's events.
    let mut mine: Vec<&EventRow> = report.events.iter().filter(|e| e.pair == k).collect();
    mine.sort_by_key(|e| e.id);
    s.push_str(&format!("<g clip-path=\"url(#map-clip-{k})\">\n"));
    let mut label_at = Vec::new();
    let mut regions: Vec<(u32, Box2)> = Vec::new();
    for ev in &mine {
        let colour = if ev.kind == "gain" { GAIN } else { LOSS };
        let fill = if ev.significant {
            format!("fill=\"{colour}\" fill-opacity=\"0.78\"")
        } else {
            format!("fill=\"url(#hatch-{}-{k})\"", kind_key(&ev.kind))
        };
        // An incomplete event's interval is no 95 % bound: none is shown.
        let interval = if ev.complete {
            format!(" ± {}", ev.uncertainty_m3.map_or("—".into(), sig3))
        } else {
            String::new()
        };
        let tip = format!(
            "Event {} ({}): {}{interval} m³{}{}{}",
            ev.id,
            esc(&ev.kind),
            ev.volume_m3
                .map_or("no volume".into(), |v| with_sign(v, sig3(v))),
            if ev.complete {
                ""
            } else {
                ", incomplete: measured in part only (see volume_note in events.csv)"
            },
            if ev.significant {
                ""
            } else {
                ", below its uncertainty"
            },
            if ev.track_id > 0 {
                format!(", track {}", ev.track_id)
            } else {
                String::new()
            }
        );
        // Pixel box of the region (or the centroid).
        let pts: Vec<(f64, f64)> = ev
            .region
            .iter()
            .flatten()
            .flatten()
            .map(|q| (px(q[0]), py(q[1])))
            .chain(std::iter::once((px(ev.centroid[0]), py(ev.centroid[1]))))
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        if pts.is_empty() {
            continue;
        }
        let (mx, my) = (px(ev.centroid[0]), py(ev.centroid[1]));
        // At least the centroid's mark.
        let bx = Box2 {
            x0: pts.iter().map(|p| p.0).fold(mx - 2.5, f64::min),
            y0: pts.iter().map(|p| p.1).fold(my - 2.5, f64::min),
            x1: pts.iter().map(|p| p.0).fold(mx + 2.5, f64::max),
            y1: pts.iter().map(|p| p.1).fold(my + 2.5, f64::max),
        };
        let d = path_of(ev);
        let small = (bx.x1 - bx.x0).max(bx.y1 - bx.y0) < 4.0;
        let dash = if ev.complete {
            ""
        } else {
            " stroke-dasharray=\"3 2\""
        };
        if !d.is_empty() {
            w!(
                s,
                "<path class=\"event {}\" d=\"{d}\" {fill} fill-rule=\"evenodd\" stroke=\"{colour}\" stroke-width=\"1\"{dash} stroke-linejoin=\"round\"><title>{tip}</title></path>\n",
                kind_key(&ev.kind)
            );
        }
        if d.is_empty() || small {
            // Too small to see at this scale (or no region): a mark at the centroid, hollow
            // where the event is below its uncertainty (a hatch would not show).
            let fill = if ev.significant {
                format!("fill=\"{colour}\"")
            } else {
                "fill=\"#fff\"".to_string()
            };
            w!(
                s,
                "<circle class=\"event-mark\" cx=\"{}\" cy=\"{}\" r=\"2.4\" {fill} stroke=\"{colour}\" stroke-width=\"1\"{dash}><title>{tip}</title></circle>\n",
                c(px(ev.centroid[0])),
                c(py(ev.centroid[1]))
            );
        }
        regions.push((ev.id, bx));
        if ev.track_id > 0 {
            label_at.push((ev, bx));
        }
    }
    s.push_str("</g>\n");
    // Track labels: the largest events first, each beside its region (right, left, above,
    // below: the first place that is free), skipped where every place would overlap a label
    // already placed or another event, or leave the map.
    label_at.sort_by(|a, b| {
        let va = a.0.volume_m3.map_or(-1.0, f64::abs);
        let vb = b.0.volume_m3.map_or(-1.0, f64::abs);
        vb.total_cmp(&va).then(a.0.id.cmp(&b.0.id))
    });
    let mut placed: Vec<Box2> = Vec::new();
    let mut labels = String::new();
    for (ev, bx) in &label_at {
        let text = format!("T{}", ev.track_id);
        // The glyphs' box at 10 px (≈ 6.2 px a character, 11 px high) and a pixel around it.
        let (tw, th) = (6.2 * text.len() as f64 + 2.0, 13.0);
        let (cx, cy) = ((bx.x0 + bx.x1) / 2.0, (bx.y0 + bx.y1) / 2.0);
        let at = |x0: f64, y0: f64| Box2 {
            x0,
            y0,
            x1: x0 + tw,
            y1: y0 + th,
        };
        let places = [
            at(bx.x1 + 2.0, cy - th / 2.0),
            at(bx.x0 - 2.0 - tw, cy - th / 2.0),
            at(cx - tw / 2.0, bx.y0 - 1.0 - th),
            at(cx - tw / 2.0, bx.y1 + 1.0),
        ];
        let inside = |b: &Box2| b.x0 >= ox && b.x1 <= ox + mw && b.y0 >= oy && b.y1 <= oy + mh;
        let free = |b: &Box2| {
            !placed.iter().any(|p| p.overlaps(b))
                && !regions.iter().any(|(id, r)| *id != ev.id && r.overlaps(b))
        };
        let Some(b) = places.into_iter().find(|b| inside(b) && free(b)) else {
            continue;
        };
        placed.push(b);
        w!(
            labels,
            "<text class=\"track\" x=\"{}\" y=\"{}\">{text}</text>",
            c(b.x0 + 1.0),
            c(b.y1 - 3.0)
        );
    }
    if !labels.is_empty() {
        w!(
            s,
            "<g font-size=\"10\" fill=\"{INK}\" stroke=\"#fff\" stroke-width=\"2.5\" paint-order=\"stroke\" stroke-linejoin=\"round\">{labels}</g>\n"
        );
    }
    if mine.is_empty() {
        w!(
            s,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12\" fill=\"{MUTED}\">No events in this pair</text>\n",
            c(ox + mw / 2.0),
            c(oy + mh / 2.0)
        );
    }
    w!(
        s,
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"{AXIS}\"/>\n",
        c(ox),
        c(oy),
        c(mw),
        c(mh)
    );
    // Scale bar (left) and north arrow (right) below the map.
    let bar = step * scale;
    let by = oy + mh + 16.0;
    w!(
        s,
        "<g class=\"scale-bar\"><rect x=\"{0}\" y=\"{1}\" width=\"{2}\" height=\"4\" fill=\"#fff\" stroke=\"{INK}\" stroke-width=\"1\"/>\
         <rect x=\"{0}\" y=\"{1}\" width=\"{3}\" height=\"4\" fill=\"{INK}\"/>\
         <text x=\"{4}\" y=\"{5}\" font-size=\"11\" fill=\"{INK}\">{6} m</text></g>\n",
        c(ox + 4.0),
        c(by - 5.0),
        c(bar),
        c(bar / 2.0),
        c(ox + 10.0 + bar),
        c(by),
        fixed(step, step_decimals(step))
    );
    let nx = ox + mw - 10.0;
    w!(
        s,
        "<g class=\"north\"><path d=\"M{0} {1}L{2} {3}L{0} {4}L{5} {3}Z\" fill=\"{INK}\"/>\
         <text x=\"{6}\" y=\"{7}\" font-size=\"11\" font-weight=\"600\" fill=\"{INK}\" text-anchor=\"end\">N</text></g>\n",
        c(nx),
        c(by - 13.0),
        c(nx + 4.5),
        c(by + 1.0),
        c(by - 2.5),
        c(nx - 4.5),
        c(nx - 8.0),
        c(by + 1.0)
    );
    s.push_str("</svg>\n");
    s
}

/// "gain" or "loss" for class names and ids (anything else counts as a loss).
fn kind_key(kind: &str) -> &'static str {
    if kind == "gain" {
        "gain"
    } else {
        "loss"
    }
}

// ---------------------------------------------------------------------------------------------
// Pieces

fn svg_open(w: f64, h: f64, id: &str, title: &str) -> String {
    format!(
        "<svg width=\"{}\" height=\"{}\" viewBox=\"0 0 {} {}\" role=\"img\" aria-labelledby=\"{id}\">\
         <title id=\"{id}\">{}</title>\n",
        c(w),
        c(h),
        c(w),
        c(h),
        esc(title)
    )
}

fn empty_note(s: &mut String, w: f64, h: f64, text: &str) {
    w!(
        s,
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"13\" fill=\"{MUTED}\">{}</text>\n",
        c(w / 2.0),
        c(h / 2.0),
        esc(text)
    );
}

/// Text for HTML content and attribute values.
fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(ch),
        }
    }
    out
}

fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

fn finite(v: f64) -> f64 {
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// An SVG coordinate: one decimal, never "-0.0".
fn c(v: f64) -> String {
    let s = format!("{v:.1}");
    if s == "-0.0" {
        "0.0".into()
    } else {
        s
    }
}

/// `v` with `d` decimals, digits grouped by thin spaces, a real minus sign; "—" if not finite.
fn fixed(v: f64, d: usize) -> String {
    if !v.is_finite() {
        return "—".into();
    }
    let s = format!("{v:.d$}");
    let (neg, digits) = match s.strip_prefix('-') {
        Some(rest) if rest.chars().any(|c| c.is_ascii_digit() && c != '0') => (true, rest),
        Some(rest) => (false, rest),
        None => (false, s.as_str()),
    };
    let (int, frac) = digits.split_once('.').unwrap_or((digits, ""));
    let mut out = String::new();
    if neg {
        out.push('−');
    }
    out.push_str(&group_digits(int));
    if !frac.is_empty() {
        out.push('.');
        out.push_str(frac);
    }
    out
}

/// `fixed` with a "+" on positive values.
fn signed(v: f64, d: usize) -> String {
    with_sign(v, fixed(v, d))
}

/// `text` (the formatted `v`) with a "+" when `v` is positive and does not print as zero.
fn with_sign(v: f64, text: String) -> String {
    if v > 0.0 && text.chars().any(|c| c.is_ascii_digit() && c != '0') {
        format!("+{text}")
    } else {
        text
    }
}

/// A tick value: `signed` without grouping concerns for zero.
fn signed_tick(v: f64, d: usize) -> String {
    if v.abs() < 1e-12 {
        fixed(0.0, d)
    } else {
        signed(v, d)
    }
}

/// Three significant figures at most, fixed by magnitude.
fn sig3(v: f64) -> String {
    let a = v.abs();
    let d = if a >= 100.0 {
        0
    } else if a >= 10.0 {
        1
    } else if a >= 1.0 {
        2
    } else {
        (2 - a.log10().floor() as i64).clamp(2, 6) as usize
    };
    fixed(v, d)
}

fn grouped(v: i64) -> String {
    minus(format!(
        "{}{}",
        if v < 0 { "-" } else { "" },
        group_digits(&v.unsigned_abs().to_string())
    ))
}

fn grouped_u(v: u64) -> String {
    group_digits(&v.to_string())
}

fn minus(s: String) -> String {
    s.replace('-', "−")
}

/// "1234567" → "1 234 567" (narrow no-break spaces), for four digits and more.
fn group_digits(int: &str) -> String {
    if int.len() < 4 {
        return int.to_string();
    }
    let mut out = String::new();
    for (i, ch) in int.chars().enumerate() {
        if i > 0 && (int.len() - i).is_multiple_of(3) {
            out.push('\u{202f}');
        }
        out.push(ch);
    }
    out
}

/// 1, 2 or 5 × 10^k, the nearest to `raw` (on a log scale, roughly).
fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(raw.log10().floor());
    let m = raw / p;
    let f = if m < 1.5 {
        1.0
    } else if m < 3.0 {
        2.0
    } else if m < 7.0 {
        5.0
    } else {
        10.0
    };
    f * p
}

/// [lo, hi] widened to multiples of a nice step giving at most about `ticks` intervals.
fn nice_range(lo: f64, hi: f64, ticks: usize) -> (f64, f64, f64) {
    let (lo, hi) = if hi - lo > 0.0 {
        (lo, hi)
    } else {
        (lo - 1.0, hi + 1.0)
    };
    let step = nice_step((hi - lo) / ticks as f64);
    ((lo / step).floor() * step, (hi / step).ceil() * step, step)
}

/// Decimals a tick step needs (0.5 → 1, 20 → 0).
fn step_decimals(step: f64) -> usize {
    if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    }
}

/// Days since 1970-01-01 of `YYYY-MM-DD` or `YYYYMMDD`.
fn parse_date(s: &str) -> Option<i64> {
    let s = s.trim();
    let (y, m, d) = match s.len() {
        10 if s.as_bytes()[4] == b'-' && s.as_bytes()[7] == b'-' => (&s[0..4], &s[5..7], &s[8..10]),
        8 => (&s[0..4], &s[4..6], &s[6..8]),
        _ => return None,
    };
    let all_digits = |t: &str| t.bytes().all(|b| b.is_ascii_digit());
    if !(all_digits(y) && all_digits(m) && all_digits(d)) {
        return None;
    }
    let (y, m, d): (i64, i64, i64) = (y.parse().ok()?, m.parse().ok()?, d.parse().ok()?);
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let month_days = [
        31,
        if leap { 29 } else { 28 },
        31,
        30,
        31,
        30,
        31,
        31,
        30,
        31,
        30,
        31,
    ];
    if !(1..=12).contains(&m) || d < 1 || d > month_days[(m - 1) as usize] {
        return None;
    }
    Some(days_from_civil(y, m, d))
}

/// Days since 1970-01-01 of a proleptic Gregorian date (Hinnant, "chrono-compatible low-level
/// date algorithms").
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// The date of a day number (inverse of [`days_from_civil`]).
fn civil_from_days(z: i64) -> (i64, i64, i64) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair(label: &str, before: &str, after: &str, b: &str, a: &str) -> PairRow {
        PairRow {
            label: label.into(),
            before: before.into(),
            after: after.into(),
            before_date: b.into(),
            after_date: a.into(),
            days: parse_date(a).unwrap() - parse_date(b).unwrap(),
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
        let viewer = include_str!("../../viewer/src/colormap.js");
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

    #[test]
    fn numbers_and_dates() {
        assert_eq!(fixed(-0.04, 1), "0.0");
        assert_eq!(fixed(-1234.56, 1), "−1\u{202f}234.6");
        assert_eq!(fixed(999.0, 0), "999");
        assert_eq!(fixed(f64::NAN, 1), "—");
        assert_eq!(signed(0.04, 1), "0.0");
        assert_eq!(signed(2.0, 1), "+2.0");
        assert_eq!(sig3(0.0123), "0.0123");
        assert_eq!(sig3(3.21), "3.21");
        assert_eq!(sig3(432.1), "432");
        assert_eq!(decade(-2), "0.01");
        assert_eq!(decade(4), "10\u{202f}000");
        assert_eq!(c(-0.01), "0.0");
        assert_eq!(parse_date("1970-01-01"), Some(0));
        assert_eq!(parse_date("20240229"), Some(19_782));
        assert_eq!(parse_date("2023-02-29"), None);
        assert_eq!(parse_date("2023-1-01"), None);
        for d in [-800_000, -1, 0, 19_782, 2_000_000] {
            let (y, m, dd) = civil_from_days(d);
            assert_eq!(days_from_civil(y, m, dd), d);
        }
        assert_eq!(
            spread(&[10.0, 12.0, 13.0], 5.0, 0.0, 100.0),
            vec![10.0, 15.0, 20.0]
        );
        assert_eq!(spread(&[98.0, 99.0], 5.0, 0.0, 100.0), vec![95.0, 100.0]);
        assert_eq!(nice_range(-91.5, 36.8, 6), (-100.0, 40.0, 20.0));
        let ticks = month_ticks(19_430.0, 19_885.0, 800.0);
        assert_eq!(ticks[0].1, "May");
        assert_eq!(ticks[0].2, Some(2023));
        assert!(ticks.len() <= 800 / 70);
    }
}
