//! The output directory of a run and its work area (`DIR/.talus/`): tiles, per-tile results and
//! the resume manifest (tantivy's model: immutable unit files plus a manifest replaced
//! atomically; a unit counts as done only once the manifest names it with the hash of what it
//! was made from).

use std::path::{Path, PathBuf};

use talus_tiling::Manifest;

use crate::error::{Error, Result};

/// Names of the final outputs `compare` writes into DIR (removed by `--force`).
pub const OUTPUTS: &[&str] = &[
    "m3c2.laz",
    "events.geojson",
    "events.csv",
    "event_regions.geojson",
    "summary.json",
    "view.json",
    "terrain.bin",
    "meshes",
];

/// The directories and manifest of one run.
pub struct WorkDir {
    pub out: PathBuf,
    pub work: PathBuf,
    pub manifest_path: PathBuf,
    pub manifest: Manifest,
    /// True when this run created DIR (so a failed run removes it again).
    pub created_out: bool,
}

fn io_out(path: &Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
    move |e| Error::output(path, e)
}

impl WorkDir {
    /// Prepare DIR for a run keyed by `key_hash` (inputs and parameters).
    /// - a fresh or empty DIR is used as is;
    /// - `force` removes a previous result and work area first;
    /// - `resume` keeps the work area; units whose inputs changed are redone by their stage;
    /// - otherwise a DIR that already holds files is refused (nothing is overwritten silently).
    pub fn prepare(out: &Path, key_hash: &str, resume: bool, force: bool) -> Result<WorkDir> {
        let existed = out.exists();
        if existed && !out.is_dir() {
            return Err(Error::Usage(format!(
                "{}: --out exists and is not a directory",
                out.display()
            )));
        }
        let work = out.join(".talus");
        if existed && !resume && !force {
            let mut entries = std::fs::read_dir(out).map_err(io_out(out))?;
            if entries.next().is_some() {
                return Err(Error::Usage(format!(
                    "{}: the output directory is not empty; use --resume to continue a run there or --force to replace it",
                    out.display()
                )));
            }
        }
        if force {
            for name in OUTPUTS {
                let p = out.join(name);
                if p.is_dir() {
                    std::fs::remove_dir_all(&p).map_err(io_out(&p))?;
                } else if p.exists() {
                    std::fs::remove_file(&p).map_err(io_out(&p))?;
                }
            }
            if work.exists() {
                std::fs::remove_dir_all(&work).map_err(io_out(&work))?;
            }
        }
        std::fs::create_dir_all(&work).map_err(io_out(&work))?;
        // Probe writability now, before hours of work.
        let probe = work.join(".probe");
        std::fs::write(&probe, b"ok").map_err(io_out(&probe))?;
        let _ = std::fs::remove_file(&probe);
        let manifest_path = work.join("manifest.json");
        // `--resume` without a previous run (no manifest) is a fresh run. A damaged manifest
        // only costs the redo of its units; each unit is checked against its own inputs hash, so
        // the run key is not used to discard the manifest (a changed threshold must not redo
        // M3C2). A manifest that cannot be read at all (permissions, I/O) is an error.
        let mut manifest = if resume {
            Manifest::load_or_new(&manifest_path, key_hash, |m| {
                m.version == talus_tiling::manifest::MANIFEST_VERSION
            })
            .map_err(crate::pipeline::tiles::tiling_error)?
        } else {
            Manifest::new(key_hash)
        };
        manifest.key_hash = key_hash.to_string();
        Ok(WorkDir {
            out: out.to_path_buf(),
            work,
            manifest_path,
            manifest,
            created_out: !existed,
        })
    }

    /// A sub-directory of the work area, created.
    pub fn sub(&self, name: &str) -> Result<PathBuf> {
        let p = self.work.join(name);
        std::fs::create_dir_all(&p).map_err(io_out(&p))?;
        Ok(p)
    }

    /// Record `unit` as done (made from `inputs_hash`, stored in `file`, whose content has
    /// `checksum`) and save the manifest atomically. Call this only once the unit's files are
    /// complete under their final names: after a SIGKILL the manifest then names only finished
    /// units.
    pub fn done(
        &mut self,
        unit: &str,
        file: &str,
        inputs_hash: &str,
        checksum: &str,
    ) -> Result<()> {
        self.manifest.record(
            unit,
            talus_tiling::manifest::UnitEntry {
                file: file.to_string(),
                checksum: checksum.to_string(),
                inputs_hash: inputs_hash.to_string(),
            },
        );
        self.save()
    }

    /// Forget `unit` and save the manifest, before its files are overwritten: otherwise a run
    /// killed half-way through the rewrite would leave an entry naming the old inputs over new
    /// (or partial) files, which a later `--resume` with the old inputs would take as done.
    pub fn forget(&mut self, unit: &str) -> Result<()> {
        if self.manifest.forget(unit).is_some() {
            self.save()?;
        }
        Ok(())
    }

    fn save(&self) -> Result<()> {
        self.manifest
            .save(&self.manifest_path)
            .map_err(crate::pipeline::tiles::tiling_error)
    }

    /// The manifest entry of `unit`, if any.
    pub fn entry(&self, unit: &str) -> Option<&talus_tiling::UnitEntry> {
        self.manifest.units.get(unit)
    }

    /// The entry of `unit` when it can be reused: recorded as made from `inputs_hash`, and its
    /// files' checksum now (`checksum` of the entry; None when they cannot be read) is the
    /// recorded one.
    pub fn intact(
        &self,
        unit: &str,
        inputs_hash: &str,
        checksum: impl FnOnce(&talus_tiling::UnitEntry) -> Option<String>,
    ) -> Option<&talus_tiling::UnitEntry> {
        let e = self.entry(unit)?;
        (e.inputs_hash == inputs_hash && checksum(e).as_deref() == Some(e.checksum.as_str()))
            .then_some(e)
    }

    /// After a failure: remove DIR again if this run created it and nothing is worth resuming.
    pub fn discard_if_created(&self) {
        if self.created_out {
            let _ = std::fs::remove_dir_all(&self.out);
        }
    }
}
