//! The epochs of a campaign (SPEC.md §5): each argument is a survey (a file, or a folder or
//! pattern of tiles), dated by the first `YYYYMMDD` or `YYYY-MM-DD` in its name or by an
//! `[[epoch]]` entry of the config (`path`, `date`, optional `label`). Epochs are ordered by date;
//! two epochs of one date without labels to tell them apart are refused. Pairs: each consecutive
//! pair, and with `--baseline` each later epoch against the first too.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::{Error, Result};

/// A calendar date.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Date {
    pub year: i32,
    pub month: u32,
    pub day: u32,
}

impl Date {
    /// A valid Gregorian date, or None.
    pub fn new(year: i32, month: u32, day: u32) -> Option<Date> {
        let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
        let days = match month {
            1 | 3 | 5 | 7 | 8 | 10 | 12 => 31,
            4 | 6 | 9 | 11 => 30,
            2 if leap => 29,
            2 => 28,
            _ => return None,
        };
        ((1..=days).contains(&day) && (1900..=2200).contains(&year)).then_some(Date {
            year,
            month,
            day,
        })
    }

    /// `YYYY-MM-DD` or `YYYYMMDD`.
    pub fn parse(s: &str) -> Option<Date> {
        let digits: String = s.chars().filter(|c| *c != '-').collect();
        let ok =
            (s.len() == 10 && s.as_bytes()[4] == b'-' && s.as_bytes()[7] == b'-') || s.len() == 8;
        if !ok || digits.len() != 8 || !digits.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        Date::new(
            digits[..4].parse().ok()?,
            digits[4..6].parse().ok()?,
            digits[6..].parse().ok()?,
        )
    }

    /// The first date written `YYYYMMDD` or `YYYY-MM-DD` in `name` (not inside a longer run of
    /// digits, so a 10-digit id is not read as a date).
    pub fn find_in(name: &str) -> Option<Date> {
        let b = name.as_bytes();
        let digit = |i: usize| i < b.len() && b[i].is_ascii_digit();
        for start in 0..b.len() {
            if !digit(start) || (start > 0 && digit(start - 1)) {
                continue;
            }
            for len in [10, 8] {
                if start + len > b.len() || digit(start + len) {
                    continue;
                }
                if let Some(d) = std::str::from_utf8(&b[start..start + len])
                    .ok()
                    .and_then(Date::parse)
                {
                    return Some(d);
                }
            }
        }
        None
    }

    /// Days since 1970-01-01 (proleptic Gregorian; Howard Hinnant's days_from_civil).
    pub fn days(&self) -> i64 {
        let y = self.year as i64 - (self.month <= 2) as i64;
        let era = if y >= 0 { y } else { y - 399 } / 400;
        let yoe = y - era * 400;
        let m = self.month as i64;
        let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + self.day as i64 - 1;
        let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
        era * 146_097 + doe - 719_468
    }

    /// `YYYY-MM-DD`.
    pub fn iso(&self) -> String {
        format!("{:04}-{:02}-{:02}", self.year, self.month, self.day)
    }

    /// `YYYYMMDD`.
    pub fn compact(&self) -> String {
        format!("{:04}{:02}{:02}", self.year, self.month, self.day)
    }
}

/// An `[[epoch]]` entry of a campaign config.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EpochEntry {
    pub path: PathBuf,
    pub date: String,
    pub label: Option<String>,
}

/// One epoch of the campaign, dated.
#[derive(Debug, Clone, PartialEq)]
pub struct Epoch {
    pub arg: PathBuf,
    pub date: Date,
    /// `YYYYMMDD`, or the config's label.
    pub label: String,
}

/// Are two paths the same file or folder (as given, or once resolved)?
fn same_path(a: &Path, b: &Path) -> bool {
    a == b
        || match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
            (Ok(x), Ok(y)) => x == y,
            _ => false,
        }
}

/// Date the arguments (config entries first, then the names) and order them by date.
/// `config` names the config file for errors about its entries.
pub fn epochs(
    args: &[PathBuf],
    entries: &[EpochEntry],
    config: Option<&Path>,
) -> Result<Vec<Epoch>> {
    let mut out = Vec::with_capacity(args.len());
    for arg in args {
        let entry = entries.iter().find(|e| same_path(&e.path, arg));
        let (date, label) = match entry {
            Some(e) => {
                let date = Date::parse(&e.date).ok_or_else(|| {
                    Error::input(
                        config.unwrap_or(Path::new("config")),
                        format!(
                            "[[epoch]] {}: date '{}' is not a date (YYYY-MM-DD)",
                            e.path.display(),
                            e.date
                        ),
                    )
                })?;
                (date, e.label.clone())
            }
            None => {
                let name = arg
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let date = Date::find_in(&name).ok_or_else(|| {
                    Error::input(
                        arg,
                        "no date in the name (YYYYMMDD or YYYY-MM-DD) and no [[epoch]] entry in a config: say when it was surveyed",
                    )
                })?;
                (date, None)
            }
        };
        let label = match label {
            Some(l)
                if l.is_empty()
                    || !l
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_') =>
            {
                return Err(Error::input(
                    config.unwrap_or(Path::new("config")),
                    format!("[[epoch]] label '{l}': use letters, digits, '-' and '_'"),
                ))
            }
            Some(l) => l,
            None => date.compact(),
        };
        out.push(Epoch {
            arg: arg.clone(),
            date,
            label,
        });
    }
    for e in entries {
        if !args.iter().any(|a| same_path(a, &e.path)) {
            return Err(Error::input(
                config.unwrap_or(Path::new("config")),
                format!(
                    "[[epoch]] {}: not among the surveys given",
                    e.path.display()
                ),
            ));
        }
    }
    out.sort_by(|a, b| a.date.cmp(&b.date).then(a.label.cmp(&b.label)));
    for w in out.windows(2) {
        if w[0].label == w[1].label {
            return Err(Error::input(
                &w[1].arg,
                format!(
                    "surveyed on {} like {}: give the epochs labels in [[epoch]] entries of a config to tell them apart",
                    w[1].date.iso(),
                    w[0].arg.display()
                ),
            ));
        }
    }
    if out.len() < 2 {
        return Err(Error::Usage("a campaign needs at least two surveys".into()));
    }
    Ok(out)
}

/// The pairs of a campaign of `n` epochs in date order: (before, after) for each consecutive
/// pair, then with `baseline` (0, k) for k ≥ 2.
pub fn pairs(n: usize, baseline: bool) -> Vec<(usize, usize)> {
    let mut p: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
    if baseline {
        p.extend((2..n).map(|k| (0, k)));
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_in_names() {
        let d = |s: &str| Date::find_in(s).map(|d| d.iso());
        assert_eq!(
            d("leo_20180606_dsm_resampled_1m.laz").as_deref(),
            Some("2018-06-06")
        );
        assert_eq!(d("flight-2019-03-11.laz").as_deref(), Some("2019-03-11"));
        assert_eq!(d("scan_1234567890.laz"), None);
        assert_eq!(d("survey_20191332.laz"), None);
        assert_eq!(d("x20200229y").as_deref(), Some("2020-02-29"));
        assert_eq!(d("x20190229y"), None);
    }

    #[test]
    fn days_between_dates() {
        let a = Date::parse("2018-06-06").unwrap();
        let b = Date::parse("2019-07-31").unwrap();
        assert_eq!(b.days() - a.days(), 420);
        assert_eq!(Date::parse("1970-01-01").unwrap().days(), 0);
    }

    #[test]
    fn pairs_consecutive_and_baseline() {
        assert_eq!(pairs(4, false), vec![(0, 1), (1, 2), (2, 3)]);
        assert_eq!(pairs(4, true), vec![(0, 1), (1, 2), (2, 3), (0, 2), (0, 3)]);
    }
}
