//! Which LAS classes of a survey take part in a comparison (SPEC.md §4 "Vegetation":
//! classification first), and how many points of each class a reader left out.
//!
//! By default every class is kept but the vegetation classes (3 low, 4 medium, 5 high
//! vegetation) and the noise classes (7 low point, 18 high noise) of the ASPRS standard
//! classes (LAS 1.4 R15 Table 17): shrubs, grass and trees change between surveys without any
//! material moving, and noise is not a surface. `--classes LIST` keeps the listed classes
//! instead (e.g. `2,6,9`), `--classes all` keeps every point. A survey without classification
//! (every point class 0 "never classified" or 1 "unclassified", and every text or PLY file)
//! loses nothing by the default.

use std::fmt;

/// Classes left out by default: vegetation (3, 4, 5) and noise (7, 18).
pub(crate) const LEFT_OUT_BY_DEFAULT: [u8; 5] = [3, 4, 5, 7, 18];

/// The classes a comparison keeps.
#[derive(Clone, PartialEq, Eq)]
pub struct Classes {
    keep: [bool; 256],
}

impl Default for Classes {
    /// Every class but `LEFT_OUT_BY_DEFAULT`.
    fn default() -> Self {
        let mut keep = [true; 256];
        for c in LEFT_OUT_BY_DEFAULT {
            keep[c as usize] = false;
        }
        Classes { keep }
    }
}

impl Classes {
    /// Every class.
    pub fn all() -> Self {
        Classes { keep: [true; 256] }
    }

    /// `all`, a comma-separated list of the class numbers to keep (0–255), or `all but LIST`
    /// (what [`Display`](fmt::Display) writes).
    pub fn parse(s: &str) -> std::result::Result<Self, String> {
        let s = s.trim();
        if s.eq_ignore_ascii_case("all") {
            return Ok(Self::all());
        }
        if let Some(out) = s.strip_prefix("all but ") {
            let out = Self::parse(out)?;
            let mut keep = [true; 256];
            for (k, o) in keep.iter_mut().zip(out.keep) {
                *k = !o;
            }
            return Ok(Classes { keep });
        }
        let mut keep = [false; 256];
        for part in s.split(',') {
            let part = part.trim();
            let c: u8 = part.parse().map_err(|_| {
                format!("'all' or class numbers 0 to 255 separated by commas, not '{part}'")
            })?;
            keep[c as usize] = true;
        }
        Ok(Classes { keep })
    }

    /// Whether points of class `c` are kept.
    pub(crate) fn keeps(&self, c: u8) -> bool {
        self.keep[c as usize]
    }

    /// Whether every class is kept (nothing to decode or filter).
    pub(crate) fn keeps_all(&self) -> bool {
        self.keep.iter().all(|&k| k)
    }
}

impl fmt::Display for Classes {
    /// `all`, `all but 3,4,5,7,18` (when fewer are left out than kept), or the kept list.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let list = |want: bool| -> String {
            (0..256)
                .filter(|&c| self.keep[c] == want)
                .map(|c| c.to_string())
                .collect::<Vec<_>>()
                .join(",")
        };
        let kept = self.keep.iter().filter(|&&k| k).count();
        if kept == 256 {
            write!(f, "all")
        } else if kept > 128 {
            write!(f, "all but {}", list(false))
        } else {
            write!(f, "{}", list(true))
        }
    }
}

impl fmt::Debug for Classes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Classes({self})")
    }
}

/// Points read per class, and of them those left out, of one or more files.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ClassCounts {
    /// (class, points read, points left out), by class, only classes that occurred.
    pub classes: Vec<(u8, u64, u64)>,
}

impl ClassCounts {
    /// From per-class totals.
    pub(crate) fn from_tables(read: &[u64; 256], left_out: &[u64; 256]) -> Self {
        ClassCounts {
            classes: (0..256)
                .filter(|&c| read[c] > 0)
                .map(|c| (c as u8, read[c], left_out[c]))
                .collect(),
        }
    }

    /// The sum of `self` and `other`.
    pub(crate) fn merge(&self, other: &ClassCounts) -> ClassCounts {
        let (mut read, mut out) = ([0u64; 256], [0u64; 256]);
        for &(c, r, o) in self.classes.iter().chain(&other.classes) {
            read[c as usize] += r;
            out[c as usize] += o;
        }
        Self::from_tables(&read, &out)
    }

    /// Points left out, in all.
    pub fn left_out(&self) -> u64 {
        self.classes.iter().map(|c| c.2).sum()
    }

    /// Points kept, in all.
    pub(crate) fn kept(&self) -> u64 {
        self.classes.iter().map(|c| c.1 - c.2).sum()
    }

    /// The classes read with their points: "class 2 (1000 points), class 7 (12 points)".
    pub(crate) fn describe(&self) -> String {
        let v: Vec<String> = self
            .classes
            .iter()
            .map(|&(c, r, _)| format!("class {c} ({r} point{})", if r == 1 { "" } else { "s" }))
            .collect();
        v.join(", ")
    }

    /// Why a file read with `classes` gave no point: what it holds and what was compared.
    pub(crate) fn none_kept(&self, classes: &Classes) -> String {
        let read: u64 = self.classes.iter().map(|c| c.1).sum();
        format!(
            "none of its {read} points is of the classes compared ({classes}): it holds {}; \
             choose the classes with --classes (e.g. --classes all)",
            self.describe()
        )
    }

    /// Whether the points carry a classification: some class other than 0 (never classified)
    /// and 1 (unclassified).
    pub fn classified(&self) -> bool {
        self.classes.iter().any(|&(c, r, _)| c > 1 && r > 0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_leaves_out_vegetation_and_noise() {
        let c = Classes::default();
        for k in [3, 4, 5, 7, 18] {
            assert!(!c.keeps(k));
        }
        for k in [0, 1, 2, 6, 9, 17, 255] {
            assert!(c.keeps(k));
        }
        assert_eq!(c.to_string(), "all but 3,4,5,7,18");
        assert_eq!(
            Classes::parse("3,4,5,7,18").unwrap().to_string(),
            "3,4,5,7,18"
        );
        assert_eq!(Classes::parse(&c.to_string()).unwrap(), c);
    }

    #[test]
    fn parse_lists_and_all() {
        assert!(Classes::parse("all").unwrap().keeps_all());
        let c = Classes::parse("2, 6,9").unwrap();
        assert!(c.keeps(2) && c.keeps(6) && c.keeps(9) && !c.keeps(1));
        assert_eq!(c.to_string(), "2,6,9");
        assert!(Classes::parse("2,x").unwrap_err().contains("'x'"));
        assert!(Classes::parse("256").is_err());
        assert!(Classes::parse("").is_err());
    }

    #[test]
    fn counts_merge_and_say_whether_classified() {
        let mut read = [0u64; 256];
        let mut out = [0u64; 256];
        read[1] = 10;
        let a = ClassCounts::from_tables(&read, &out);
        assert!(!a.classified());
        read[1] = 0;
        read[2] = 5;
        read[5] = 3;
        out[5] = 3;
        let b = ClassCounts::from_tables(&read, &out);
        assert!(b.classified());
        let m = a.merge(&b);
        assert_eq!(m.classes, vec![(1, 10, 0), (2, 5, 0), (5, 3, 3)]);
        assert_eq!(m.left_out(), 3);
    }
}
