//! The epochs of a campaign (SPEC.md §5): each argument is a survey (a file, or a folder or
//! pattern of tiles), dated by the first `YYYYMMDD` or `YYYY-MM-DD` in its name or by an
//! `[[epoch]]` entry of the config (`path`, `date`, optional `label`). Epochs are ordered by date;
//! two epochs of one date without labels to tell them apart are refused. Pairs: each consecutive
//! pair, and with `--baseline` each later epoch against the first too.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::{Error, Result};

/// A survey's date: defined in [`super::date`] (the report's time axis uses it too), named here
/// as well, where it began, so that `epochs::Date` keeps working.
pub(crate) use super::date::Date;

/// An `[[epoch]]` entry of a campaign config.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct EpochEntry {
    pub path: PathBuf,
    pub date: String,
    pub label: Option<String>,
}

/// One epoch of the campaign, dated.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Epoch {
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
pub(crate) fn epochs(
    args: &[PathBuf],
    entries: &[EpochEntry],
    config: Option<&Path>,
) -> Result<Vec<Epoch>> {
    for (i, a) in args.iter().enumerate() {
        if let Some(b) = args[..i].iter().find(|b| same_path(a, b)) {
            return Err(Error::input(
                a,
                format!(
                    "given twice (also as {}): each survey once, it is compared with the others",
                    b.display()
                ),
            ));
        }
    }
    let mut out = Vec::with_capacity(args.len());
    // Whether each epoch's label is the config's (else its date's).
    let mut named = Vec::with_capacity(args.len());
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
                let date = Date::find_in(&name).ok_or_else(|| match Date::impossible_in(&name) {
                    Some(bad) => Error::input(
                        arg,
                        format!(
                            "the date in its name, {bad}, is not a date: rename it, or date it \
                             with an [[epoch]] entry in a config"
                        ),
                    ),
                    None => Error::input(
                        arg,
                        "no date in the name (YYYYMMDD or YYYY-MM-DD) and no [[epoch]] entry in a config: say when it was surveyed",
                    ),
                })?;
                (date, None)
            }
        };
        named.push(label.is_some());
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
    // One label, two surveys: say which kind of label it is (two of one date are below).
    for i in 0..out.len() {
        for j in 0..i {
            let (a, b) = (&out[j], &out[i]);
            if a.label != b.label || !(named[i] || named[j]) {
                continue;
            }
            let problem = if named[i] && named[j] {
                format!(
                    "[[epoch]] label '{}' names two surveys, {} and {}: each needs its own",
                    b.label,
                    a.arg.display(),
                    b.arg.display()
                )
            } else {
                let (labelled, dated) = if named[i] { (b, a) } else { (a, b) };
                format!(
                    "[[epoch]] label '{}' of {} is also {}'s label (its date, unlabelled): \
                     choose another",
                    labelled.label,
                    labelled.arg.display(),
                    dated.arg.display()
                )
            };
            return Err(Error::input(config.unwrap_or(Path::new("config")), problem));
        }
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
pub(crate) fn pairs(n: usize, baseline: bool) -> Vec<(usize, usize)> {
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
    fn pairs_consecutive_and_baseline() {
        assert_eq!(pairs(4, false), vec![(0, 1), (1, 2), (2, 3)]);
        assert_eq!(pairs(4, true), vec![(0, 1), (1, 2), (2, 3), (0, 2), (0, 3)]);
    }
}
