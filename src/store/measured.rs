//! The measured spacing of an input file, cached by its content key: a resumed run, and every
//! run of a campaign after its first, would otherwise decode the first survey again (≈ 20 s at
//! 120M points) only to find the numbers it found before. The entry is the pass's whole result
//! (the spacing and the density grid the tiles are sized by), for one class filter and one
//! version of the measurement ([`crate::sampling::METHOD`]); any other entry, or one that does
//! not read, is no entry. Written whole under a temporary name and renamed, like `inputs.json`.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::sampling::{Spacing, METHOD};
use crate::spatial::DensityGrid;

use super::fsops::replace_file;
use super::Store;

#[derive(Serialize, Deserialize)]
struct Entry {
    method: u32,
    key: String,
    classes: String,
    spacing: Spacing,
    density: DensityGrid,
}

impl Store {
    fn measured_path(&self, key: &str, classes: &str) -> PathBuf {
        let mut h = talus_tiling::Fnv64::new();
        h.write(classes.as_bytes());
        let name = format!("spacing-{key}-{:016x}.json", h.finish());
        self.work.join("cache").join(name)
    }

    /// The spacing and density grid measured on the file of content key `key` read with the
    /// class filter `classes` (its canonical text), when this store has them.
    pub fn cached_spacing(&self, key: &str, classes: &str) -> Option<(Spacing, DensityGrid)> {
        let bytes = super::fsops::read_store_file(&self.measured_path(key, classes)).ok()?;
        let e: Entry = serde_json::from_slice(&bytes).ok()?;
        (e.method == METHOD && e.key == key && e.classes == classes)
            .then_some((e.spacing, e.density))
    }

    /// Keep what was measured on the file of content key `key` with `classes`. A cache only ever
    /// saves work: failing to write it is not an error.
    pub fn cache_spacing(
        &self,
        key: &str,
        classes: &str,
        spacing: &Spacing,
        density: &DensityGrid,
    ) {
        let entry = Entry {
            method: METHOD,
            key: key.to_string(),
            classes: classes.to_string(),
            spacing: spacing.clone(),
            density: density.clone(),
        };
        if let Ok(bytes) = serde_json::to_vec(&entry) {
            let _ = replace_file(&self.tmp(), &self.measured_path(key, classes), &bytes);
        }
    }
}
