//! The measured spacing of an input file, cached in the store by its content key: a resumed run,
//! and every run of a campaign after its first, would otherwise decode the first survey again
//! (≈ 20 s at 120M points) only to find the numbers it found before. The entry is the pass's
//! whole result (the spacing and the density grid the tiles are sized by), for one class filter
//! and one version of the measurement ([`crate::sampling::METHOD`]); any other entry, or one
//! that does not read, is no entry. Written whole under a temporary name and renamed, like
//! `inputs.json` (`Store::cache`).

use serde::{Deserialize, Serialize};

use crate::sampling::{Spacing, METHOD};
use crate::spatial::DensityGrid;
use crate::store::Store;

#[derive(Serialize, Deserialize)]
struct Entry {
    method: u32,
    key: String,
    classes: String,
    spacing: Spacing,
    density: DensityGrid,
}

/// The cache file's name: `spacing-<key>-<hash of the filter>.json`.
fn name(key: &str, classes: &str) -> String {
    let mut h = talus_tiling::Fnv64::new();
    h.write(classes.as_bytes());
    format!("spacing-{key}-{:016x}.json", h.finish())
}

/// The spacing and density grid measured on the file of content key `key` read with the class
/// filter `classes` (its canonical text), when `store` has them.
pub(crate) fn cached_spacing(
    store: &Store,
    key: &str,
    classes: &str,
) -> Option<(Spacing, DensityGrid)> {
    let bytes = store.cached(&name(key, classes))?;
    let e: Entry = serde_json::from_slice(&bytes).ok()?;
    (e.method == METHOD && e.key == key && e.classes == classes).then_some((e.spacing, e.density))
}

/// Keep what was measured on the file of content key `key` with `classes`. A cache only ever
/// saves work: failing to write it is not an error.
pub(crate) fn cache_spacing(
    store: &Store,
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
        store.cache(&name(key, classes), &bytes);
    }
}
