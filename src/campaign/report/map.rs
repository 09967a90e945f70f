//! Section 4 of the report: a plan-view map per pair (x/y of the event regions, one extent and
//! scale for all pairs). Gains and losses in two colours, vegetation in a third, events below their uncertainty
//! hatched, incomplete ones dashed, the other pairs' events as faint outlines, track ids where
//! they do not overlap, a grid at the scale bar's length, a scale bar and a north arrow.

use std::fmt::Write;

use super::chart::{
    empty_note, nice_step, step_decimals, svg_open, AXIS, GAIN, GRID, INK, LOSS, MUTED, VEGETATION,
};
use super::text::{c, esc, fixed, grouped, plural, sig3, signed, with_sign};
use super::{crs_name, EventRow, Report};

/// A map's width in CSS pixels: three to a row.
const MAP_WIDTH: f64 = 360.0;

pub(super) fn maps_section(s: &mut String, report: &Report) {
    s.push_str(
        "<section id=\"maps\" aria-labelledby=\"h-maps\">\n<h2 id=\"h-maps\">4. Event maps</h2>\n\
         <div class=\"legend\"><span><i class=\"sw g\"></i>Gain (red: material added)</span><span><i class=\"sw l\"></i>Loss (blue: material removed)</span>\
         <span><i class=\"sw hg\"></i><i class=\"sw hl\"></i>Below its 95 % uncertainty (hollow marks where small)</span>\
         <span><i class=\"sw inc\"></i>Dashed: incomplete, measured in part only (no 95 % bound)</span>\
         <span><i class=\"sw v\"></i>Vegetation (green: listed, but in no sum, track or fit)</span>\
         <span><i class=\"sw o\"></i>Events of the other pairs</span><span>T4: track 4 (events at one place across pairs)</span></div>\n",
    );
    let ext = extent(report);
    if report.pairs.is_empty() {
        s.push_str("<p class=\"note\">No pairs.</p>\n");
    }
    s.push_str("<div class=\"maps\">\n");
    for k in 0..report.pairs.len() {
        s.push_str("<figure>\n");
        s.push_str(&map_svg(report, k, ext));
        caption(s, report, k);
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

/// Pair `k`'s caption under its map: label, dates, days, events and volumes; closes the
/// figure.
fn caption(s: &mut String, report: &Report, k: usize) {
    let p = &report.pairs[k];
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

/// A box in pixels (an event's, or a label's).
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
    let Some(e) = ext else {
        return empty_map(k, &p.label);
    };
    let map = Map::fit(e, k);
    let mut s = svg_open(
        MAP_WIDTH,
        map.h,
        &format!("map-title-{k}"),
        &format!(
            "Plan-view map of the events of pair {} ({} to {})",
            p.label, p.before_date, p.after_date
        ),
    );
    map.defs(&mut s);
    map.background(&mut s);
    map.context(&mut s, report);
    // This pair's events.
    let mut mine: Vec<&EventRow> = report.events.iter().filter(|e| e.pair == k).collect();
    mine.sort_by_key(|e| e.id);
    let regions = map.events(&mut s, &mine);
    map.track_labels(&mut s, &regions);
    if mine.is_empty() {
        w!(
            s,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12\" fill=\"{MUTED}\">No events in this pair</text>\n",
            c(map.ox + map.mw / 2.0),
            c(map.oy + map.mh / 2.0)
        );
    }
    w!(
        s,
        "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"{AXIS}\"/>\n",
        c(map.ox),
        c(map.oy),
        c(map.mw),
        c(map.mh)
    );
    map.scale_bar_and_north(&mut s);
    s.push_str("</svg>\n");
    s
}

/// Pair `k`'s panel when no pair has an event to map.
fn empty_map(k: usize, label: &str) -> String {
    let (w, h) = (MAP_WIDTH, 200.0);
    let mut s = svg_open(
        w,
        h,
        &format!("map-title-{k}"),
        &format!("Map of pair {label}: no events"),
    );
    w!(
        s,
        "<rect x=\"0.5\" y=\"0.5\" width=\"{}\" height=\"{}\" fill=\"#fbfbfb\" stroke=\"{GRID}\"/>\n",
        c(w - 1.0),
        c(h - 1.0)
    );
    empty_note(&mut s, w, h, "No events");
    s.push_str("</svg>\n");
    s
}

/// One pair's panel: the extent's place and scale in it.
struct Map {
    /// The pair's index (ids of the clip path and hatches are per panel).
    k: usize,
    e: Extent,
    /// Pixels per metre.
    scale: f64,
    /// The map's top-left corner, width and height in pixels; the panel's height.
    ox: f64,
    oy: f64,
    mw: f64,
    mh: f64,
    h: f64,
    /// The grid's spacing and the scale bar's length, metres.
    step: f64,
}

impl Map {
    /// The extent at the largest scale that fits the panel's width and 300 px, centred, above
    /// a strip for the scale bar and north arrow.
    fn fit(e: Extent, k: usize) -> Map {
        let pad = 1.0;
        let strip = 30.0;
        let max_h = 300.0;
        let (dx, dy) = (e.x1 - e.x0, e.y1 - e.y0);
        let scale = ((MAP_WIDTH - 2.0 * pad) / dx).min(max_h / dy);
        let (mw, mh) = (dx * scale, dy * scale);
        let ox = pad + ((MAP_WIDTH - 2.0 * pad) - mw) / 2.0;
        let oy = pad;
        Map {
            k,
            e,
            scale,
            ox,
            oy,
            mw,
            mh,
            h: oy + mh + strip,
            step: nice_step(dx.max(dy) / 4.0),
        }
    }

    fn px(&self, x: f64) -> f64 {
        self.ox + (x - self.e.x0) * self.scale
    }

    fn py(&self, y: f64) -> f64 {
        self.oy + (self.e.y1 - y) * self.scale
    }

    /// The clip path of the map area and the hatches of events below their uncertainty.
    fn defs(&self, s: &mut String) {
        let k = self.k;
        w!(
            s,
            "<defs><clipPath id=\"map-clip-{k}\"><rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/></clipPath>",
            c(self.ox),
            c(self.oy),
            c(self.mw),
            c(self.mh)
        );
        for (kind, colour) in [("gain", GAIN), ("loss", LOSS)] {
            w!(
                s,
                "<pattern id=\"hatch-{kind}-{k}\" patternUnits=\"userSpaceOnUse\" width=\"4\" height=\"4\" patternTransform=\"rotate(45)\">\
                 <rect width=\"4\" height=\"4\" fill=\"#fff\"/><line x1=\"1\" y1=\"0\" x2=\"1\" y2=\"4\" stroke=\"{colour}\" stroke-width=\"1.5\"/></pattern>"
            );
        }
        s.push_str("</defs>\n");
    }

    /// The map's background and a grid at the scale bar's length.
    fn background(&self, s: &mut String) {
        let (ox, oy, mw, mh) = (self.ox, self.oy, self.mw, self.mh);
        w!(
            s,
            "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"#fbfbfb\"/>\n",
            c(ox),
            c(oy),
            c(mw),
            c(mh)
        );
        let (e, step) = (self.e, self.step);
        let mut g = String::new();
        let mut x = (e.x0 / step).ceil() * step;
        while x < e.x1 {
            w!(g, "M{} {}V{}", c(self.px(x)), c(oy), c(oy + mh));
            x += step;
        }
        let mut y = (e.y0 / step).ceil() * step;
        while y < e.y1 {
            w!(g, "M{} {}H{}", c(ox), c(self.py(y)), c(ox + mw));
            y += step;
        }
        w!(
            s,
            "<path d=\"{g}\" stroke=\"#ececec\" stroke-width=\"1\" fill=\"none\"/>\n"
        );
    }

    /// An event's region as path data (empty without a region).
    fn outline(&self, ev: &EventRow) -> String {
        let mut d = String::new();
        for ring in ev.region.iter().flatten() {
            for (i, q) in ring.iter().enumerate() {
                w!(
                    d,
                    "{}{} {}",
                    if i == 0 { "M" } else { "L" },
                    c(self.px(q[0])),
                    c(self.py(q[1]))
                );
            }
            if !ring.is_empty() {
                d.push('Z');
            }
        }
        d
    }

    /// The other pairs' events, faint, for where this pair's sit among them.
    fn context(&self, s: &mut String, report: &Report) {
        let k = self.k;
        let mut others = String::new();
        for ev in report
            .events
            .iter()
            .filter(|e| e.pair != k && e.pair < report.pairs.len())
        {
            others.push_str(&self.outline(ev));
        }
        if !others.is_empty() {
            w!(
                s,
                "<path class=\"context\" d=\"{others}\" fill=\"none\" stroke=\"#c4c4c4\" stroke-width=\"0.8\" clip-path=\"url(#map-clip-{k})\"/>\n"
            );
        }
    }

    /// The pixel box of an event's region and centroid, at least its centroid's mark; `None`
    /// where nothing of it has coordinates.
    fn pixel_box(&self, ev: &EventRow) -> Option<Box2> {
        let pts: Vec<(f64, f64)> = ev
            .region
            .iter()
            .flatten()
            .flatten()
            .map(|q| (self.px(q[0]), self.py(q[1])))
            .chain(std::iter::once((
                self.px(ev.centroid[0]),
                self.py(ev.centroid[1]),
            )))
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        if pts.is_empty() {
            return None;
        }
        let (mx, my) = (self.px(ev.centroid[0]), self.py(ev.centroid[1]));
        Some(Box2 {
            x0: pts.iter().map(|p| p.0).fold(mx - 2.5, f64::min),
            y0: pts.iter().map(|p| p.1).fold(my - 2.5, f64::min),
            x1: pts.iter().map(|p| p.0).fold(mx + 2.5, f64::max),
            y1: pts.iter().map(|p| p.1).fold(my + 2.5, f64::max),
        })
    }

    /// This pair's events (`mine`, by id), clipped to the map; returns each drawn event with
    /// its pixel box, for the track labels.
    fn events<'a>(&self, s: &mut String, mine: &[&'a EventRow]) -> Vec<(&'a EventRow, Box2)> {
        w!(s, "<g clip-path=\"url(#map-clip-{})\">\n", self.k);
        let mut regions = Vec::new();
        for &ev in mine {
            if let Some(bx) = self.event(s, ev) {
                regions.push((ev, bx));
            }
        }
        s.push_str("</g>\n");
        regions
    }

    /// One event: its region filled (hatched when below its uncertainty, dashed when
    /// incomplete), and a mark at its centroid where the region is too small to see or
    /// missing. Returns its pixel box; `None` (nothing drawn) without coordinates.
    fn event(&self, s: &mut String, ev: &EventRow) -> Option<Box2> {
        let colour = if ev.vegetation {
            VEGETATION
        } else if ev.kind == "gain" {
            GAIN
        } else {
            LOSS
        };
        let tip = event_tip(ev);
        let bx = self.pixel_box(ev)?;
        let d = self.outline(ev);
        let small = (bx.x1 - bx.x0).max(bx.y1 - bx.y0) < 4.0;
        let dash = if ev.complete {
            ""
        } else {
            " stroke-dasharray=\"3 2\""
        };
        if !d.is_empty() {
            let fill = if ev.vegetation {
                format!("fill=\"{colour}\" fill-opacity=\"0.45\"")
            } else if ev.significant {
                format!("fill=\"{colour}\" fill-opacity=\"0.78\"")
            } else {
                format!("fill=\"url(#hatch-{}-{})\"", kind_key(&ev.kind), self.k)
            };
            w!(
                s,
                "<path class=\"event {}\" d=\"{d}\" {fill} fill-rule=\"evenodd\" stroke=\"{colour}\" stroke-width=\"1\"{dash} stroke-linejoin=\"round\"><title>{tip}</title></path>\n",
                if ev.vegetation {
                    "vegetation"
                } else {
                    kind_key(&ev.kind)
                }
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
                c(self.px(ev.centroid[0])),
                c(self.py(ev.centroid[1]))
            );
        }
        Some(bx)
    }

    /// Track labels: the largest events first, each beside its region (right, left, above,
    /// below: the first place that is free), skipped where every place would overlap a label
    /// already placed or another event, or leave the map.
    fn track_labels(&self, s: &mut String, regions: &[(&EventRow, Box2)]) {
        let mut label_at: Vec<&(&EventRow, Box2)> =
            regions.iter().filter(|(ev, _)| ev.track_id > 0).collect();
        label_at.sort_by(|a, b| {
            let va = a.0.volume_m3.map_or(-1.0, f64::abs);
            let vb = b.0.volume_m3.map_or(-1.0, f64::abs);
            vb.total_cmp(&va).then(a.0.id.cmp(&b.0.id))
        });
        let mut placed: Vec<Box2> = Vec::new();
        let mut labels = String::new();
        for (ev, bx) in label_at {
            let text = format!("T{}", ev.track_id);
            let inside = |b: &Box2| {
                b.x0 >= self.ox
                    && b.x1 <= self.ox + self.mw
                    && b.y0 >= self.oy
                    && b.y1 <= self.oy + self.mh
            };
            let free = |b: &Box2| {
                !placed.iter().any(|p| p.overlaps(b))
                    && !regions.iter().any(|(o, r)| o.id != ev.id && r.overlaps(b))
            };
            let Some(b) = label_places(bx, &text)
                .into_iter()
                .find(|b| inside(b) && free(b))
            else {
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
    }

    /// Below the map: a scale bar `step` long (left) and a north arrow (right).
    fn scale_bar_and_north(&self, s: &mut String) {
        let (ox, step) = (self.ox, self.step);
        let bar = step * self.scale;
        let by = self.oy + self.mh + 16.0;
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
        let nx = ox + self.mw - 10.0;
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
    }
}

/// The places a track label `text` may take beside an event's box `bx`, in order of
/// preference: right, left, above, below.
fn label_places(bx: &Box2, text: &str) -> [Box2; 4] {
    // The glyphs' box at 10 px (≈ 6.2 px a character, 11 px high) and a pixel around it.
    let (tw, th) = (6.2 * text.len() as f64 + 2.0, 13.0);
    let (cx, cy) = ((bx.x0 + bx.x1) / 2.0, (bx.y0 + bx.y1) / 2.0);
    let at = |x0: f64, y0: f64| Box2 {
        x0,
        y0,
        x1: x0 + tw,
        y1: y0 + th,
    };
    [
        at(bx.x1 + 2.0, cy - th / 2.0),
        at(bx.x0 - 2.0 - tw, cy - th / 2.0),
        at(cx - tw / 2.0, bx.y0 - 1.0 - th),
        at(cx - tw / 2.0, bx.y1 + 1.0),
    ]
}

/// An event's tooltip: id, kind, volume ± its 95 % interval, and what else to know of it.
fn event_tip(ev: &EventRow) -> String {
    // An incomplete event's interval is no 95 % bound: none is shown.
    let interval = if ev.complete {
        format!(" ± {}", ev.uncertainty_m3.map_or("—".into(), sig3))
    } else {
        String::new()
    };
    format!(
        "Event {} ({}{}): {}{interval} m³{}{}{}",
        ev.id,
        esc(&ev.kind),
        if ev.vegetation { ", vegetation" } else { "" },
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
    )
}

/// "gain" or "loss" for class names and ids (anything else counts as a loss).
fn kind_key(kind: &str) -> &'static str {
    if kind == "gain" {
        "gain"
    } else {
        "loss"
    }
}
