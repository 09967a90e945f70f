//! Section 3 of the report: the magnitude–frequency plot. The exceedance N(≥ |V|) of the
//! significant events' volumes, per gain and loss, on log–log axes with decade grid lines, the
//! fitted power laws ([`crate::campaign::powerlaw`]) over their tails, and a legend giving each
//! fit's exponent and tail.

use std::fmt::Write;

use super::chart::{
    empty_note, svg_open, x_tick, y_grid, AXIS, GAIN, GRID, INK, LOSS, MUTED, WIDTH,
};
use super::text::{c, fixed, grouped, minus, plural, sig3};
use super::{magnitudes, Report};
use crate::campaign::powerlaw::{self, PowerLawFit};

pub(super) fn magnitude_section(s: &mut String, report: &Report) {
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
    let mut s = svg_open(
        w,
        h,
        "mf-title",
        "Magnitude–frequency: exceedance of event volume, log–log, with fitted power laws",
    );
    let kinds = [
        Kind::of(report, "gain", "Gains", GAIN, &report.gain_fit),
        Kind::of(report, "loss", "Losses", LOSS, &report.loss_fit),
    ];
    let Some(plot) = LogPlot::fit(&kinds, w, h) else {
        empty_note(&mut s, w, h, "No significant events with a volume");
        s.push_str("</svg>\n");
        return s;
    };
    plot.clip_path(&mut s);
    plot.x_decades(&mut s);
    plot.y_decades(&mut s);
    plot.frame(&mut s);
    // Fit lines under the marks.
    for kind in &kinds {
        plot.fit_line(&mut s, kind);
    }
    for kind in &kinds {
        plot.marks(&mut s, kind);
    }
    plot.legend(&mut s, &kinds);
    s.push_str("</svg>\n");
    s
}

/// Gains or losses: what the plot draws of them.
struct Kind<'a> {
    /// "gain" or "loss" (class names and data attributes); gains are circles, losses squares.
    key: &'static str,
    /// For the legend and tooltips: "Gains", "Losses".
    name: &'static str,
    colour: &'static str,
    fit: &'a Option<PowerLawFit>,
    /// [`powerlaw::exceedance`] of their magnitudes: (|V|, N(≥ |V|), share), largest first.
    rows: Vec<(f64, usize, f64)>,
}

impl<'a> Kind<'a> {
    fn of(
        report: &Report,
        key: &'static str,
        name: &'static str,
        colour: &'static str,
        fit: &'a Option<PowerLawFit>,
    ) -> Kind<'a> {
        Kind {
            key,
            name,
            colour,
            fit,
            rows: powerlaw::exceedance(&magnitudes(&report.events, key)),
        }
    }
}

/// The log–log plot area: whole decades of volume across, of counts up.
struct LogPlot {
    /// Chart height (the x-axis title sits at its bottom).
    h: f64,
    /// Left and top margins; plot width and height.
    l: f64,
    t: f64,
    pw: f64,
    ph: f64,
    /// log10 ranges of volume (x) and count (y).
    lx0: f64,
    lx1: f64,
    ly0: f64,
    ly1: f64,
}

impl LogPlot {
    /// The plot of a `w` × `h` chart over every kind's values; `None` without any.
    fn fit(kinds: &[Kind], w: f64, h: f64) -> Option<LogPlot> {
        let (l, t, b) = (78.0, 16.0, 56.0);
        let values = kinds.iter().flat_map(|k| &k.rows).map(|r| r.0);
        let vmin = values.clone().min_by(f64::total_cmp)?;
        let vmax = values.max_by(f64::total_cmp)?;
        let nmax = kinds.iter().map(|k| k.rows.len()).max().unwrap_or(1).max(1) as f64;
        let lx0 = (vmin.log10() - 0.05).floor();
        let mut lx1 = (vmax.log10() + 0.05).ceil();
        if lx1 <= lx0 {
            lx1 = lx0 + 1.0;
        }
        Some(LogPlot {
            h,
            l,
            t,
            // The legend takes the right 300 px.
            pw: w - l - 330.0,
            ph: h - t - b,
            lx0,
            lx1,
            // Just below one event, so the marks at N = 1 are not on the frame.
            ly0: -0.15,
            ly1: (nmax.log10() + 0.08).ceil().max(1.0),
        })
    }

    fn px(&self, v: f64) -> f64 {
        self.l + (v.log10() - self.lx0) / (self.lx1 - self.lx0) * self.pw
    }

    fn py(&self, n: f64) -> f64 {
        self.t + (self.ly1 - n.log10()) / (self.ly1 - self.ly0) * self.ph
    }

    /// The x axis's line, on the bottom of the plot.
    fn base(&self) -> f64 {
        self.t + self.ph
    }

    /// The plot area as a clip path: a fit line stops at the frame.
    fn clip_path(&self, s: &mut String) {
        w!(
            s,
            "<defs><clipPath id=\"mf-clip\"><rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"/></clipPath></defs>\n",
            c(self.l),
            c(self.t),
            c(self.pw),
            c(self.ph)
        );
    }

    /// A grid line, tick and label at each decade of volume; minor ticks at 2..9 × it.
    fn x_decades(&self, s: &mut String) {
        let mut k = self.lx0 as i64;
        while k as f64 <= self.lx1 {
            let v = 10f64.powi(k as i32);
            let x = self.px(v);
            w!(
                s,
                "<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"{GRID}\"/>",
                c(x),
                c(self.t),
                c(self.base())
            );
            x_tick(s, x, self.base(), &decade(k));
            for m in 2..10 {
                let mv = v * m as f64;
                if mv.log10() < self.lx1 {
                    w!(
                        s,
                        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{2}\" stroke=\"{AXIS}\"/>",
                        c(self.px(mv)),
                        c(self.base()),
                        c(self.base() + 3.0)
                    );
                }
            }
            s.push('\n');
            k += 1;
        }
    }

    /// A grid line and label at each decade of counts from 1 up; minor ticks at 2..9 × it.
    fn y_decades(&self, s: &mut String) {
        let mut k = self.ly0.ceil() as i64;
        while k as f64 <= self.ly1 {
            let v = 10f64.powi(k as i32);
            y_grid(s, (self.l, self.l + self.pw), self.py(v), GRID, &decade(k));
            for m in 2..10 {
                let mv = v * m as f64;
                if mv.log10() < self.ly1 {
                    w!(
                        s,
                        "<line x1=\"{0}\" y1=\"{1}\" x2=\"{2}\" y2=\"{1}\" stroke=\"{AXIS}\"/>",
                        c(self.l - 3.0),
                        c(self.py(mv)),
                        c(self.l)
                    );
                }
            }
            s.push('\n');
            k += 1;
        }
    }

    /// The plot's frame and the axis titles.
    fn frame(&self, s: &mut String) {
        w!(
            s,
            "<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"{AXIS}\"/>\n\
             <text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"12.5\" fill=\"{INK}\">Event volume |V| (m³)</text>\n\
             <text transform=\"translate(20 {}) rotate(-90)\" text-anchor=\"middle\" font-size=\"12.5\" fill=\"{INK}\">Number of events ≥ |V|</text>\n",
            c(self.l),
            c(self.t),
            c(self.pw),
            c(self.ph),
            c(self.l + self.pw / 2.0),
            c(self.h - 10.0),
            c(self.t + self.ph / 2.0)
        );
    }

    /// The kind's fitted power law from x_min to its largest value, and a dotted drop line
    /// at x_min; nothing without a usable fit.
    fn fit_line(&self, s: &mut String, kind: &Kind) {
        let (Some(f), Some(top)) = (kind.fit, kind.rows.first()) else {
            return;
        };
        if !(f.x_min > 0.0 && f.alpha.is_finite()) {
            return;
        }
        let x_end = top.0.max(f.x_min);
        let n_at = |v: f64| f.n_tail as f64 * (v / f.x_min).powf(1.0 - f.alpha);
        let (key, colour) = (kind.key, kind.colour);
        w!(
            s,
            "<line class=\"fit\" data-kind=\"{key}\" x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"{colour}\" stroke-width=\"2\" clip-path=\"url(#mf-clip)\"/>\
             <line x1=\"{0}\" y1=\"{1}\" x2=\"{0}\" y2=\"{4}\" stroke=\"{colour}\" stroke-width=\"1\" stroke-dasharray=\"2 3\"/>\n",
            c(self.px(f.x_min)),
            c(self.py(n_at(f.x_min))),
            c(self.px(x_end)),
            c(self.py(n_at(x_end))),
            c(self.base())
        );
    }

    /// One mark per distinct value at its count (tied values share their count).
    fn marks(&self, s: &mut String, kind: &Kind) {
        let (key, colour) = (kind.key, kind.colour);
        w!(
            s,
            "<g class=\"marks\" data-kind=\"{key}\" fill=\"{colour}\" fill-opacity=\"0.85\" stroke=\"#fff\" stroke-width=\"0.8\">"
        );
        let mut prev = None;
        for &(v, n, _) in &kind.rows {
            if prev == Some(v) {
                continue;
            }
            prev = Some(v);
            let (x, y) = (self.px(v), self.py(n as f64));
            let tip = format!("{}: {} events ≥ {} m³", kind.name, n, sig3(v));
            if key == "gain" {
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

    /// Right of the plot: per kind its mark, count and fit; then what the dotted line means.
    fn legend(&self, s: &mut String, kinds: &[Kind]) {
        let lx = self.l + self.pw + 34.0;
        let mut y = self.t + 14.0;
        for kind in kinds {
            y = legend_entry(s, kind, lx, y);
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
    }
}

/// A kind's legend entry at (`lx`, `y`): its mark and count, then its fit's line, α ± se,
/// x_min and tail (or why there is none). Returns the next entry's `y`.
fn legend_entry(s: &mut String, kind: &Kind, lx: f64, mut y: f64) -> f64 {
    let colour = kind.colour;
    let mark = if kind.key == "gain" {
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
        "{mark}<text x=\"{}\" y=\"{}\" font-size=\"13\" font-weight=\"600\" fill=\"{INK}\">{}: {} event{}</text>\n",
        c(lx + 16.0),
        c(y),
        kind.name,
        kind.rows.len(),
        plural(kind.rows.len())
    );
    y += 19.0;
    match kind.fit {
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
    y + 34.0
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decade_labels() {
        assert_eq!(decade(-2), "0.01");
        assert_eq!(decade(4), "10\u{202f}000");
        assert_eq!(decade(-4), "10<tspan dy=\"-6\" font-size=\"9\">−4</tspan>");
    }
}
