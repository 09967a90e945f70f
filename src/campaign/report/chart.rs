//! What the report's charts share: their colours, the `<svg>` element with its title, the note
//! an empty chart shows, grid lines and ticks with their labels, nice tick steps, labels pushed
//! apart, and month ticks on a time axis.

use std::fmt::Write;

use super::text::{c, esc};
use crate::campaign::date::Date;

// The viewer's colours (its distance ramp, ColorBrewer RdBu): see the module doc of the page.
pub(super) const GAIN: &str = "#b2182b";
pub(super) const LOSS: &str = "#2166ac";
/// Vegetation events (`--vegetation flag|remove`).
pub(super) const VEGETATION: &str = "#4d9221";
pub(super) const NET: &str = "#2b2b2b";
pub(super) const INK: &str = "#1a1a1a";
pub(super) const MUTED: &str = "#5f6368";
pub(super) const GRID: &str = "#e4e4e4";
pub(super) const AXIS: &str = "#8a8a8a";
/// Chart widths in CSS pixels (the page's content is 1120 px wide).
pub(super) const WIDTH: f64 = 1120.0;

/// The opening `<svg>` of a `w` × `h` chart, labelled by its `<title>` (id `id`) for screen
/// readers.
pub(super) fn svg_open(w: f64, h: f64, id: &str, title: &str) -> String {
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

/// `text` in the middle of a `w` × `h` chart that has nothing to draw.
pub(super) fn empty_note(s: &mut String, w: f64, h: f64, text: &str) {
    w!(
        s,
        "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" font-size=\"13\" fill=\"{MUTED}\">{}</text>\n",
        c(w / 2.0),
        c(h / 2.0),
        esc(text)
    );
}

/// A horizontal grid line across `span` at `y` with its label left of it.
pub(super) fn y_grid(s: &mut String, span: (f64, f64), y: f64, colour: &str, label: &str) {
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
pub(super) fn x_tick(s: &mut String, x: f64, base: f64, label: &str) {
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
pub(super) fn spread(ys: &[f64], gap: f64, lo: f64, hi: f64) -> Vec<f64> {
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

/// 1, 2 or 5 × 10^k, the nearest to `raw` (on a log scale, roughly).
pub(super) fn nice_step(raw: f64) -> f64 {
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
pub(super) fn nice_range(lo: f64, hi: f64, ticks: usize) -> (f64, f64, f64) {
    let (lo, hi) = if hi - lo > 0.0 {
        (lo, hi)
    } else {
        (lo - 1.0, hi + 1.0)
    };
    let step = nice_step((hi - lo) / ticks as f64);
    ((lo / step).floor() * step, (hi / step).ceil() * step, step)
}

/// Decimals a tick step needs (0.5 → 1, 20 → 0).
pub(super) fn step_decimals(step: f64) -> usize {
    if step >= 1.0 {
        0
    } else {
        (-step.log10().floor()) as usize
    }
}

const MONTHS: [&str; 12] = [
    "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
];

/// A tick of a time axis: its day (since 1970-01-01), its label (a month, or a year when the
/// ticks are a year or more apart), and the year to write under it where the year changes
/// (none when the label is the year).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct MonthTick {
    pub day: f64,
    pub label: String,
    pub year: Option<i32>,
}

/// Ticks on the first day of months between days x0 and x1, every 1, 2, 3, 6 or 12 months or
/// a multiple of years, as many as fit 70 px apart in `width`.
pub(super) fn month_ticks(x0: f64, x1: f64, width: f64) -> Vec<MonthTick> {
    let months = ((x1 - x0) / 30.44).max(1.0);
    let fit = (width / 70.0).max(1.0);
    let step: i64 = [1, 2, 3, 6, 12, 24, 60, 120]
        .into_iter()
        .find(|&k| months / k as f64 <= fit)
        .unwrap_or(240);
    let mut out = Vec::new();
    let mut last_year = None;
    let mut first = Date {
        day: 1,
        ..Date::from_days(x0.floor() as i64)
    };
    loop {
        let day = first.days() as f64;
        if day > x1 {
            break;
        }
        // Counted in months since year 0, so every step lands on the same months each year
        // (a 3-month step: Jan, Apr, Jul, Oct).
        let index = i64::from(first.year) * 12 + i64::from(first.month) - 1;
        if day >= x0 && index % step == 0 {
            let year = (last_year != Some(first.year)).then_some(first.year);
            last_year = Some(first.year);
            out.push(if step >= 12 {
                MonthTick {
                    day,
                    label: first.year.to_string(),
                    year: None,
                }
            } else {
                MonthTick {
                    day,
                    label: MONTHS[(first.month - 1) as usize].to_string(),
                    year,
                }
            });
        }
        first = first.next_month();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_ranges_and_spread() {
        assert_eq!(
            spread(&[10.0, 12.0, 13.0], 5.0, 0.0, 100.0),
            vec![10.0, 15.0, 20.0]
        );
        assert_eq!(spread(&[98.0, 99.0], 5.0, 0.0, 100.0), vec![95.0, 100.0]);
        assert_eq!(nice_range(-91.5, 36.8, 6), (-100.0, 40.0, 20.0));
        assert_eq!(nice_step(0.0), 1.0);
        assert_eq!(nice_step(25.0), 20.0);
        assert_eq!(nice_step(310.0), 500.0);
        assert_eq!(step_decimals(0.5), 1);
        assert_eq!(step_decimals(20.0), 0);
    }

    #[test]
    fn month_ticks_over_months() {
        let ticks = month_ticks(19_430.0, 19_885.0, 800.0);
        assert_eq!(ticks[0].label, "May");
        assert_eq!(ticks[0].year, Some(2023));
        assert!(ticks.len() <= 800 / 70);
        // Monthly across a new year: December, then January with its year under it.
        let start = Date::parse("2023-11-15").unwrap().days() as f64;
        let end = Date::parse("2024-02-10").unwrap().days() as f64;
        let ticks = month_ticks(start, end, 800.0);
        let labels: Vec<(&str, Option<i32>)> =
            ticks.iter().map(|t| (t.label.as_str(), t.year)).collect();
        assert_eq!(
            labels,
            vec![("Dec", Some(2023)), ("Jan", Some(2024)), ("Feb", None)]
        );
        assert_eq!(
            ticks[1].day,
            Date::parse("2024-01-01").unwrap().days() as f64
        );
    }

    #[test]
    fn month_ticks_over_years_are_years() {
        let start = Date::parse("2021-03-01").unwrap().days() as f64;
        let end = Date::parse("2031-03-01").unwrap().days() as f64;
        let ticks = month_ticks(start, end, 886.0);
        assert!(ticks.iter().all(|t| t.year.is_none()));
        assert_eq!(ticks[0].label, "2022");
        assert_eq!(
            ticks[0].day,
            Date::parse("2022-01-01").unwrap().days() as f64
        );
    }
}
