//! The report's text: every number it prints (table cells, tick labels, tooltips, SVG
//! coordinates) and every string it escapes go through here, so the page reads one way
//! throughout: a real minus sign, digits grouped by narrow no-break spaces, a fixed precision
//! (the same inputs give the same bytes) and "—" for what is not a number.

/// Text for HTML content and attribute values (and SVG's, which is XML).
pub(super) fn esc(s: &str) -> String {
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

/// The "s" of a plural noun after the count `n`.
pub(super) fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

/// An SVG coordinate: one decimal, never "-0.0".
pub(super) fn c(v: f64) -> String {
    let s = format!("{v:.1}");
    if s == "-0.0" {
        "0.0".into()
    } else {
        s
    }
}

/// `v` with `d` decimals, digits grouped by thin spaces, a real minus sign; "—" if not finite.
pub(super) fn fixed(v: f64, d: usize) -> String {
    if !v.is_finite() {
        return "—".into();
    }
    let s = format!("{v:.d$}");
    // A value that rounds to zero prints without a sign.
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
pub(super) fn signed(v: f64, d: usize) -> String {
    with_sign(v, fixed(v, d))
}

/// `text` (the formatted `v`) with a "+" when `v` is positive and does not print as zero.
pub(super) fn with_sign(v: f64, text: String) -> String {
    if v > 0.0 && text.chars().any(|c| c.is_ascii_digit() && c != '0') {
        format!("+{text}")
    } else {
        text
    }
}

/// A tick value: `signed`, and a plain zero where the tick sits at zero up to rounding.
pub(super) fn signed_tick(v: f64, d: usize) -> String {
    if v.abs() < 1e-12 {
        fixed(0.0, d)
    } else {
        signed(v, d)
    }
}

/// Three significant figures at most, fixed by magnitude.
pub(super) fn sig3(v: f64) -> String {
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

/// An integer with its digits grouped and a real minus sign.
pub(super) fn grouped(v: i64) -> String {
    minus(format!(
        "{}{}",
        if v < 0 { "-" } else { "" },
        group_digits(&v.unsigned_abs().to_string())
    ))
}

/// A count with its digits grouped.
pub(super) fn grouped_u(v: u64) -> String {
    group_digits(&v.to_string())
}

/// Every hyphen-minus of `s` as a real minus sign (U+2212).
pub(super) fn minus(s: String) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers() {
        assert_eq!(fixed(-0.04, 1), "0.0");
        assert_eq!(fixed(-1234.56, 1), "−1\u{202f}234.6");
        assert_eq!(fixed(999.0, 0), "999");
        assert_eq!(fixed(f64::NAN, 1), "—");
        assert_eq!(signed(0.04, 1), "0.0");
        assert_eq!(signed(2.0, 1), "+2.0");
        assert_eq!(sig3(0.0123), "0.0123");
        assert_eq!(sig3(3.21), "3.21");
        assert_eq!(sig3(432.1), "432");
        assert_eq!(c(-0.01), "0.0");
    }

    #[test]
    fn integers_and_ticks() {
        assert_eq!(grouped(-1_234_567), "−1\u{202f}234\u{202f}567");
        assert_eq!(grouped(999), "999");
        assert_eq!(grouped_u(12_345), "12\u{202f}345");
        assert_eq!(signed_tick(1e-13, 1), "0.0");
        assert_eq!(signed_tick(-20.0, 0), "−20");
        assert_eq!(plural(1), "");
        assert_eq!(plural(0), "s");
    }

    #[test]
    fn markup_is_escaped() {
        assert_eq!(esc("a<&>\"'b"), "a&lt;&amp;&gt;&quot;&#39;b");
    }
}
