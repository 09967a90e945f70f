//! What `talus synth` (and `talus demo`, through it) may replace in its `--out` folder: only
//! files it wrote there itself. The rule `compare` follows (never replace a file talus did not
//! write) holds for every command: a user's `before.laz` in the folder is not overwritten.
//!
//! The folder's `.talus-synth.json` lists the names synth wrote there. Before writing, every
//! name about to be written (and its temporary `<name>.tmp`) that exists must be listed, else
//! nothing is written and the file is named (exit 2). The list is updated before the files are
//! written, so a synth cut short leaves only listed files; a listed file the new scene does not
//! write (a campaign of fewer surveys, LAS after LAZ) is removed, so that a folder or glob of the
//! surveys never picks up one of an earlier scene.

use std::collections::BTreeSet;
use std::path::Path;

use serde::{Deserialize, Serialize};

use talus_base::{Error, Result};

/// The list's file name in the `--out` folder.
pub(crate) const LIST: &str = ".talus-synth.json";

#[derive(Serialize, Deserialize, Default)]
struct Written {
    /// Names (in the folder) that talus synth wrote.
    files: BTreeSet<String>,
}

/// Take `names` in folder `out` (created) for a scene about to be written: refuse an existing
/// file synth did not write; list the names; remove the listed files of an earlier scene that
/// `names` do not hold.
pub(crate) fn take(out: &Path, names: &[String]) -> Result<()> {
    std::fs::create_dir_all(out).map_err(|e| Error::output(out, e))?;
    let list = out.join(LIST);
    // A list that does not read is no list: every existing file then counts as the user's.
    let old: Written = std::fs::read(&list)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    for name in names {
        for n in [name.clone(), format!("{name}.tmp")] {
            let path = out.join(&n);
            if std::fs::symlink_metadata(&path).is_ok() && !old.files.contains(&n) {
                return Err(Error::input(
                    &path,
                    format!(
                        "exists, and talus synth did not write it (it is not in {LIST}): not \
                         replacing it; move it or choose another --out"
                    ),
                ));
            }
        }
    }
    let new: BTreeSet<String> = names.iter().cloned().collect();
    let bytes = serde_json::to_vec_pretty(&Written {
        files: old.files.union(&new).cloned().collect(),
    })
    .map_err(|e| Error::Internal(format!("{LIST}: {e}")))?;
    talus_tiling::atomic_write(&list, &bytes)?;
    for stale in old.files.difference(&new) {
        let path = out.join(stale);
        // Only a plain file it wrote (a name turned into a folder since is the user's).
        if std::fs::symlink_metadata(&path).is_ok_and(|m| m.is_file()) {
            std::fs::remove_file(&path).map_err(|e| Error::output(&path, e))?;
        }
    }
    let bytes = serde_json::to_vec_pretty(&Written { files: new })
        .map_err(|e| Error::Internal(format!("{LIST}: {e}")))?;
    Ok(talus_tiling::atomic_write(&list, &bytes)?)
}
