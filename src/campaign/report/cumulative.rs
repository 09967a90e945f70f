//! Section 2 of the report: cumulative significant gain, loss and net volume over time, along
//! the chain of consecutive pairs (baseline pairs would count the same change twice and are left
//! out): a line per total with a mark per survey, shaded areas under gain and loss, month ticks
//! on a time axis, the final totals at the lines' ends and a legend above.

use std::fmt::Write;

use super::chart::{
    empty_note, month_ticks, nice_range, spread, step_decimals, svg_open, x_tick, y_grid, AXIS,
    GAIN, GRID, INK, LOSS, MUTED, NET, WIDTH,
};
use super::text::{c, esc, signed, signed_tick};
use super::{PairRow, Report};
use crate::campaign::date::Date;

pub(super) fn cumulative_section(s: &mut String, report: &Report, chain: &[usize]) {
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
    let totals = Running::along(&pairs);
    let plot = Plot::fit(&totals, w, h);
    plot.y_axis(&mut s);
    plot.x_axis(&mut s, &totals);
    plot.axis_titles(&mut s);
    plot.areas(&mut s, &totals);
    plot.lines(&mut s, &totals);
    plot.end_labels(&mut s, &totals);
    plot.legend(&mut s, &totals);
    s.push_str("</svg>\n");
    s
}

/// The running totals at each survey of the chain: the first survey (all zero), then each
/// pair's after survey.
struct Running {
    /// The surveys' dates as the pairs give them.
    labels: Vec<String>,
    /// Every date parses: `xs` are days since 1970-01-01; else the survey's index.
    dated: bool,
    xs: Vec<f64>,
    gain: Vec<f64>,
    loss: Vec<f64>,
    net: Vec<f64>,
}

/// One line of the chart: its name, values, colour and dash attribute.
type Series<'a> = (&'static str, &'a [f64], &'static str, &'static str);

impl Running {
    fn along(pairs: &[&PairRow]) -> Running {
        let mut labels = vec![pairs[0].before_date.clone()];
        labels.extend(pairs.iter().map(|p| p.after_date.clone()));
        // Trimmed: the dates may come back from a hand-edited campaign.json.
        let days: Option<Vec<i64>> = labels
            .iter()
            .map(|d| Date::parse(d.trim()).map(|d| d.days()))
            .collect();
        let xs: Vec<f64> = match &days {
            Some(d) => d.iter().map(|&v| v as f64).collect(),
            None => (0..labels.len()).map(|i| i as f64).collect(),
        };
        let mut gain = vec![0.0];
        let mut loss = vec![0.0];
        let mut net = vec![0.0];
        for p in pairs {
            gain.push(gain[gain.len() - 1] + finite(p.gain_m3).abs());
            loss.push(loss[loss.len() - 1] - finite(p.loss_m3).abs());
            net.push(net[net.len() - 1] + finite(p.net_m3));
        }
        Running {
            labels,
            dated: days.is_some(),
            xs,
            gain,
            loss,
            net,
        }
    }

    /// The three lines in drawing order (net last, on top, dashed).
    fn series(&self) -> [Series<'_>; 3] {
        [
            ("Gain", &self.gain, GAIN, ""),
            ("Loss", &self.loss, LOSS, ""),
            ("Net", &self.net, NET, " stroke-dasharray=\"6 4\""),
        ]
    }
}

/// A missing total counts as no change.
fn finite(v: f64) -> f64 {
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// The plot area inside the chart's margins and the ranges it shows.
struct Plot {
    /// Chart height (the x-axis title sits at its bottom).
    h: f64,
    /// Left and top margins; plot width and height.
    l: f64,
    t: f64,
    pw: f64,
    ph: f64,
    /// x range (days or survey index).
    x0: f64,
    x1: f64,
    /// y range (m³) and its tick step.
    ylo: f64,
    yhi: f64,
    ystep: f64,
}

impl Plot {
    /// The plot of a `w` × `h` chart: margins for the tick labels (left, bottom) and the end
    /// labels (right); x over the surveys, y over every total and zero, in nice steps.
    fn fit(totals: &Running, w: f64, h: f64) -> Plot {
        let (l, r, t, b) = (84.0, 150.0, 40.0, 58.0);
        let xs = &totals.xs;
        let (mut x0, mut x1) = (xs[0], xs[xs.len() - 1]);
        if x1 <= x0 {
            x0 -= 1.0;
            x1 += 1.0;
        }
        let all = totals.gain.iter().chain(&totals.loss).chain(&totals.net);
        let lo = all.clone().fold(0.0f64, |a, &v| a.min(v));
        let hi = all.fold(0.0f64, |a, &v| a.max(v));
        let (ylo, yhi, ystep) = nice_range(lo, hi, 8);
        Plot {
            h,
            l,
            t,
            pw: w - l - r,
            ph: h - t - b,
            x0,
            x1,
            ylo,
            yhi,
            ystep,
        }
    }

    fn px(&self, x: f64) -> f64 {
        self.l + (x - self.x0) / (self.x1 - self.x0) * self.pw
    }

    fn py(&self, y: f64) -> f64 {
        self.t + (self.yhi - y) / (self.yhi - self.ylo) * self.ph
    }

    /// The x axis's line, on the bottom of the plot.
    fn base(&self) -> f64 {
        self.t + self.ph
    }

    /// Grid lines with their values, zero darker.
    fn y_axis(&self, s: &mut String) {
        let mut y = self.ylo;
        let decimals = step_decimals(self.ystep);
        while y <= self.yhi + self.ystep * 1e-9 {
            let colour = if y.abs() < self.ystep * 1e-9 {
                AXIS
            } else {
                GRID
            };
            y_grid(
                s,
                (self.l, self.l + self.pw),
                self.py(y),
                colour,
                &signed_tick(y, decimals),
            );
            y += self.ystep;
        }
    }

    /// The axis line and its ticks: months (and years) where the surveys are dated, else each
    /// survey's date as given.
    fn x_axis(&self, s: &mut String, totals: &Running) {
        let base = self.base();
        w!(
            s,
            "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{AXIS}\"/>\n",
            c(self.l),
            c(base),
            c(self.l + self.pw),
            c(base)
        );
        if !totals.dated {
            for (x, label) in totals.xs.iter().zip(&totals.labels) {
                x_tick(s, self.px(*x), base, &esc(label));
            }
            return;
        }
        for tick in month_ticks(self.x0, self.x1, self.pw) {
            let xx = self.px(tick.day);
            x_tick(s, xx, base, &tick.label);
            if let Some(year) = tick.year {
                w!(
                    s,
                    "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12\" fill=\"{MUTED}\">{year}</text>\n",
                    c(xx),
                    c(base + 32.0)
                );
            }
        }
    }

    fn axis_titles(&self, s: &mut String) {
        w!(
            s,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12.5\" fill=\"{INK}\">Survey date</text>\n\
             <text transform=\"translate(18 {}) rotate(-90)\" text-anchor=\"middle\" font-size=\"12.5\" fill=\"{INK}\">Cumulative volume (m³)</text>\n",
            c(self.l + self.pw / 2.0),
            c(self.h - 6.0),
            c(self.t + self.ph / 2.0)
        );
    }

    /// Faint areas between zero and the gain and loss lines.
    fn areas(&self, s: &mut String, totals: &Running) {
        let xs = &totals.xs;
        let zero = self.py(0.0);
        for (vals, colour) in [(&totals.gain, GAIN), (&totals.loss, LOSS)] {
            let mut d = format!("M{} {}", c(self.px(xs[0])), c(zero));
            for (x, v) in xs.iter().zip(vals.iter()) {
                w!(d, "L{} {}", c(self.px(*x)), c(self.py(*v)));
            }
            w!(d, "L{} {}Z", c(self.px(xs[xs.len() - 1])), c(zero));
            w!(
                s,
                "<path d=\"{d}\" fill=\"{colour}\" fill-opacity=\"0.09\" stroke=\"none\"/>\n"
            );
        }
    }

    /// The three lines, each with a mark per survey whose tooltip gives the total and date.
    fn lines(&self, s: &mut String, totals: &Running) {
        let xs = &totals.xs;
        for (name, vals, colour, dash) in totals.series() {
            let pts: Vec<String> = xs
                .iter()
                .zip(vals.iter())
                .map(|(x, v)| format!("{},{}", c(self.px(*x)), c(self.py(*v))))
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
                    c(self.px(*x)),
                    c(self.py(*v)),
                    name,
                    signed(*v, 1),
                    esc(&totals.labels[i])
                );
            }
        }
    }

    /// Each line's final total right of its end, pushed apart so they never overlap.
    fn end_labels(&self, s: &mut String, totals: &Running) {
        let last = totals.xs.len() - 1;
        let mut ends: Vec<(f64, &str, f64, &str)> = totals
            .series()
            .iter()
            .map(|(name, vals, colour, _)| (self.py(vals[last]), *name, vals[last], *colour))
            .collect();
        ends.sort_by(|a, b| a.0.total_cmp(&b.0));
        let ys = spread(
            &ends.iter().map(|e| e.0).collect::<Vec<_>>(),
            15.0,
            self.t,
            self.t + self.ph,
        );
        for ((_, name, v, colour), y) in ends.iter().zip(ys) {
            w!(
                s,
                "<text x=\"{}\" y=\"{}\" font-size=\"12.5\" fill=\"{colour}\" font-weight=\"600\">{name} {} m³</text>\n",
                c(self.l + self.pw + 10.0),
                c(y + 4.0),
                signed(*v, 1)
            );
        }
    }

    /// A sample of each line and what it totals, in a row above the plot.
    fn legend(&self, s: &mut String, totals: &Running) {
        let mut x = self.l;
        for (name, _, colour, dash) in totals.series() {
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
            // About 7 px a character at 12.5 px, then a gap.
            x += 28.0 + 7.0 * text.chars().count() as f64 + 24.0;
        }
    }
}
