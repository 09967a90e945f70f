//! talus: change events and volumes between two terrain surveys.
//!
//! The pipeline, one module per stage: [`io`] (read epochs) → tiles (the `talus-tiling` crate,
//! driven by [`pipeline`]) → [`m3c2`] (normals and distances at core points) → [`events`]
//! (filter, smoothing, signed DBSCAN, PCA box) → [`volume`] (clipped watertight solids) →
//! outputs. [`synth`] writes synthetic pairs with exact ground truth; [`view`] serves the viewer.

pub mod commands;
pub mod error;
pub mod events;
pub mod info;
pub mod io;
pub mod m3c2;
pub mod params;
pub mod pipeline;
pub mod sampling;
pub mod spatial;
pub mod store;
pub mod synth;
pub mod view;
pub mod volume;

pub use error::{Error, Result};
