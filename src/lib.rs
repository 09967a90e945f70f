//! talus: change events and volumes between two terrain surveys.
//!
//! The pipeline, one module per stage: [`io`] (read epochs) → tiles (the `talus-tiling` crate)
//! → [`m3c2`] (normals and distances at core points) → events (filter, smoothing, signed
//! DBSCAN, PCA box) → volume (clipped watertight solids) → outputs.

pub mod error;
pub mod io;
pub mod view;

pub use error::{Error, Result};
