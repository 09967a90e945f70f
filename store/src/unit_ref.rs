//! Names in the store: a unit's `kind` and `name`, a run id, and the relative file names inside a
//! unit or an output set.
//!
//! Every name ends up as a path component on disk (often on NFS, shared by many hosts), so the
//! rules are strict and checked at every entry point: a name that could climb out of its
//! directory (`..`), hide (`.`), or be spelled differently by two hosts (non-ASCII, case tricks
//! aside) is refused as a caller bug (`Error::Internal`), never "fixed" silently.

use std::fmt;

use serde::{Deserialize, Serialize};

use talus_base::{Error, Result};

/// A unit of work: its kind ("tiling", "m3c2", ...) and a name that already carries the unit's
/// content key (e.g. `survey0-3f2a9c01d4e5b6a7`), so equal names mean equal content.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct UnitRef {
    pub kind: String,
    pub name: String,
}

impl UnitRef {
    /// A unit reference with both parts checked (see [`check_component`]).
    pub fn new(kind: impl Into<String>, name: impl Into<String>) -> Result<UnitRef> {
        let unit = UnitRef {
            kind: kind.into(),
            name: name.into(),
        };
        unit.check()?;
        Ok(unit)
    }

    /// Check both parts; the fields are public, so the store checks again at every call.
    pub(crate) fn check(&self) -> Result<()> {
        check_component("unit kind", &self.kind)?;
        check_component("unit name", &self.name)
    }
}

impl fmt::Display for UnitRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.kind, self.name)
    }
}

/// One path component: ASCII letters, digits, `_`, `.` and `-`; not empty, not `.` or `..`.
/// `what` says which name it was, for the error.
pub fn check_component(what: &str, s: &str) -> Result<()> {
    let ok_chars = s
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'.' | b'-'));
    if s.is_empty() || s == "." || s == ".." || !ok_chars {
        return Err(Error::Internal(format!(
            "{what} {s:?}: must be non-empty ASCII letters, digits, '_', '.' or '-', and not '.' or '..'"
        )));
    }
    Ok(())
}

/// A relative file name inside a unit or an output set: components checked as above, joined by
/// `/` (so `meshes/event_0001_before.ply` is fine, `../x`, `/x` and `a//b` are not).
pub fn check_rel_path(what: &str, s: &str) -> Result<()> {
    if s.is_empty() {
        return Err(Error::Internal(format!("{what}: empty file name")));
    }
    for part in s.split('/') {
        check_component(what, part).map_err(|_| {
            Error::Internal(format!(
                "{what} {s:?}: each '/'-separated part must be non-empty ASCII letters, digits, '_', '.' or '-', and not '.' or '..'"
            ))
        })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_checked() {
        assert!(UnitRef::new("m3c2", "survey0-3f2a9c01d4e5b6a7").is_ok());
        for bad in ["", ".", "..", "a/b", "a b", "é", "a~b"] {
            assert!(
                matches!(UnitRef::new("tiling", bad), Err(Error::Internal(_))),
                "{bad:?}"
            );
            assert!(UnitRef::new(bad, "x").is_err(), "{bad:?}");
        }
        assert!(check_rel_path("file", "meshes/event_0001_before.ply").is_ok());
        for bad in ["", "/x", "x/", "a//b", "../x", "a/./b"] {
            assert!(check_rel_path("file", bad).is_err(), "{bad:?}");
        }
    }
}
