//! The program's one calendar date: a survey's date (read from a file name or a config), the
//! days between two surveys, and the days an axis of the campaign report is drawn in.

/// A calendar date (proleptic Gregorian).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) struct Date {
    pub year: i32,
    pub month: u32,
    pub day: u32,
}

impl Date {
    /// A valid Gregorian date of a survey, or None. Years outside 1900–2200 are refused: a
    /// number like that in a file name is not a survey date.
    pub(crate) fn new(year: i32, month: u32, day: u32) -> Option<Date> {
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
    pub(crate) fn parse(s: &str) -> Option<Date> {
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
    pub(crate) fn find_in(name: &str) -> Option<Date> {
        tokens(name).find_map(Date::parse)
    }

    /// A `YYYYMMDD` or `YYYY-MM-DD` in `name` (where [`Date::find_in`] looks) of a survey's year
    /// that is no date, with why: "20210230 (2021-02 has 28 days)". For the message that a name
    /// holds a date, but an impossible one — not that it holds none.
    pub(crate) fn impossible_in(name: &str) -> Option<String> {
        tokens(name).find_map(|token| {
            let t = token.as_bytes();
            let dashed = t.len() == 10 && t[4] == b'-' && t[7] == b'-';
            let digits: String = token.chars().filter(|c| *c != '-').collect();
            if (token.len() == 10 && !dashed) || !digits.bytes().all(|c| c.is_ascii_digit()) {
                return None;
            }
            let (y, m, d): (i32, u32, u32) = (
                digits[..4].parse().ok()?,
                digits[4..6].parse().ok()?,
                digits[6..].parse().ok()?,
            );
            if !(1900..=2200).contains(&y) || Date::new(y, m, d).is_some() {
                return None;
            }
            let why = if (1..=12).contains(&m) {
                let days = (28..=31).rev().find(|&n| Date::new(y, m, n).is_some());
                format!("{y}-{m:02} has {} days", days.unwrap_or(0))
            } else {
                format!("there is no month {m}")
            };
            Some(format!("{token} ({why})"))
        })
    }

    /// Days since 1970-01-01 (proleptic Gregorian; Howard Hinnant's days_from_civil).
    pub(crate) fn days(&self) -> i64 {
        let y = self.year as i64 - (self.month <= 2) as i64;
        let era = if y >= 0 { y } else { y - 399 } / 400;
        let yoe = y - era * 400;
        let m = self.month as i64;
        let doy = (153 * (m + if m > 2 { -3 } else { 9 }) + 2) / 5 + self.day as i64 - 1;
        let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
        era * 146_097 + doe - 719_468
    }

    /// The date `days` days after 1970-01-01: the inverse of [`Date::days`] (Hinnant's
    /// civil_from_days). Not range-checked like [`Date::new`]: a chart's axis is laid out in
    /// days and may reach past the surveys' years.
    pub(crate) fn from_days(days: i64) -> Date {
        let z = days + 719_468;
        let era = z.div_euclid(146_097);
        let doe = z - era * 146_097;
        let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
        let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
        let mp = (5 * doy + 2) / 153;
        let day = doy - (153 * mp + 2) / 5 + 1;
        let month = if mp < 10 { mp + 3 } else { mp - 9 };
        Date {
            year: (yoe + era * 400 + i64::from(month <= 2)) as i32,
            month: month as u32,
            day: day as u32,
        }
    }

    /// The first day of the month after this date's.
    pub(crate) fn next_month(&self) -> Date {
        match self.month {
            12 => Date {
                year: self.year + 1,
                month: 1,
                day: 1,
            },
            m => Date {
                year: self.year,
                month: m + 1,
                day: 1,
            },
        }
    }

    /// `YYYY-MM-DD`.
    pub(crate) fn iso(&self) -> String {
        format!("{:04}-{:02}-{:02}", self.year, self.month, self.day)
    }

    /// `YYYYMMDD`.
    pub(crate) fn compact(&self) -> String {
        format!("{:04}{:02}{:02}", self.year, self.month, self.day)
    }
}

/// The runs of 10 or 8 characters in `name` that start and end a run of digits (not inside a
/// longer one), where a date may be written: the 10 first, at each start.
fn tokens(name: &str) -> impl Iterator<Item = &str> {
    let b = name.as_bytes();
    let digit = move |i: usize| i < b.len() && b[i].is_ascii_digit();
    (0..b.len())
        .filter(move |&start| digit(start) && !(start > 0 && digit(start - 1)))
        .flat_map(move |start| {
            [10, 8]
                .into_iter()
                .filter(move |&len| start + len <= b.len() && !digit(start + len))
                .filter_map(move |len| std::str::from_utf8(&b[start..start + len]).ok())
        })
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
        let bad = |s: &str| Date::impossible_in(s);
        assert_eq!(
            bad("x_20210230.laz").as_deref(),
            Some("20210230 (2021-02 has 28 days)")
        );
        assert_eq!(
            bad("x_2020-02-30.laz").as_deref(),
            Some("2020-02-30 (2020-02 has 29 days)")
        );
        assert_eq!(
            bad("survey_20191332.laz").as_deref(),
            Some("20191332 (there is no month 13)")
        );
        assert_eq!(bad("scan_1234567890.laz"), None);
        assert_eq!(bad("x_20210228.laz"), None);
        assert_eq!(bad("1234é56789x"), None);
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

    /// The checks of the report's own date code, which this type replaced.
    #[test]
    fn parse_and_day_numbers() {
        let days = |s: &str| Date::parse(s).map(|d| d.days());
        assert_eq!(days("1970-01-01"), Some(0));
        assert_eq!(days("20240229"), Some(19_782));
        assert_eq!(days("2023-02-29"), None);
        assert_eq!(days("2023-1-01"), None);
        assert_eq!(days("2023-01-0x"), None);
        for d in [-800_000, -1, 0, 19_782, 2_000_000] {
            assert_eq!(Date::from_days(d).days(), d, "{d}");
        }
        assert_eq!(Date::from_days(19_782).iso(), "2024-02-29");
        assert_eq!(Date::from_days(-1).iso(), "1969-12-31");
    }

    #[test]
    fn next_month_is_the_first_of_the_next() {
        let next = |s: &str| Date::parse(s).unwrap().next_month().iso();
        assert_eq!(next("2023-01-31"), "2023-02-01");
        assert_eq!(next("2023-12-15"), "2024-01-01");
        assert_eq!(next("2024-02-29"), "2024-03-01");
    }
}
