//! Garbage collection: finished units the current plan no longer needs, and what crashed writers
//! and interrupted deletions left in `tmp/`. Only `.talus/units` and `.talus/tmp` are ever
//! touched, and in `units/` only directories at the `<kind>/<name>` level.

use std::collections::HashSet;
use std::fs;
use std::path::Path;
use std::time::Duration;

use talus_base::Result;

use super::fsops::{newest_mtime, remove_any, sorted_names, trash};
use super::process;
use super::unit_ref::{check_component, UnitRef};
use super::Store;

/// Left-overs in `tmp/` from another host (whose pid cannot be checked) are removed once nothing
/// in them has changed for this long: a live writer touches its files far more often.
const TMP_IDLE: Duration = Duration::from_secs(3600);

/// What [`Store::gc`] removed, in sorted order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GcReport {
    /// Finished units removed.
    pub units: Vec<UnitRef>,
    /// Names of the entries removed from `tmp/`.
    pub tmp: Vec<String>,
    /// Bytes freed (file sizes).
    pub bytes: u64,
}

impl Store {
    /// Remove finished units not in `keep`, and entries of `tmp/` whose owner is gone: on this
    /// host a dead pid, from another host (or of unknown origin) an hour without change. A
    /// unit being read by another process at that moment is the caller's to prevent (run gc
    /// under the run lock, once the plan is known).
    pub fn gc(&self, keep: &HashSet<UnitRef>) -> Result<GcReport> {
        let mut report = GcReport::default();
        let units = self.units();
        for kind in sorted_names(&units)? {
            let kind_dir = units.join(&kind);
            // Never through a link: a `units/<kind>` planted as a link to a folder elsewhere
            // would have gc remove what is in it.
            if check_component("unit kind", &kind).is_err() || !real_dir(&kind_dir) {
                continue;
            }
            for name in sorted_names(&kind_dir)? {
                let path = kind_dir.join(&name);
                let Ok(unit) = UnitRef::new(kind.clone(), name) else {
                    continue;
                };
                if keep.contains(&unit) || !real_dir(&path) {
                    continue;
                }
                let bytes = tree_size(&path);
                if trash(&self.tmp(), &path)? {
                    report.bytes += bytes;
                    report.units.push(unit);
                }
            }
        }
        let tmp = self.tmp();
        for name in sorted_names(&tmp)? {
            let path = tmp.join(&name);
            let gone = match process::parse_unique(&name) {
                Some((host, pid, start)) if host == process::host() => !process::alive(pid, start),
                _ => newest_mtime(&path)
                    .and_then(|t| t.elapsed().ok())
                    .is_some_and(|idle| idle > TMP_IDLE),
            };
            if gone {
                report.bytes += tree_size(&path);
                remove_any(&path)?;
                report.tmp.push(name);
            }
        }
        Ok(report)
    }
}

/// A directory, not a link to one.
fn real_dir(path: &Path) -> bool {
    fs::symlink_metadata(path).is_ok_and(|m| m.is_dir())
}

/// The total size of the files at or below `path`.
fn tree_size(path: &Path) -> u64 {
    let Ok(meta) = fs::symlink_metadata(path) else {
        return 0;
    };
    if !meta.is_dir() {
        return meta.len();
    }
    fs::read_dir(path)
        .map(|entries| entries.flatten().map(|e| tree_size(&e.path())).sum())
        .unwrap_or(0)
}
