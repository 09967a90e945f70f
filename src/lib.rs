//! talus: change events and volumes between terrain surveys.
//!
//! Three layers (ARCHITECTURE.md):
//! - pure algorithms, functions of their inputs: [`m3c2`] (normals and distances at core points),
//!   [`events`] (stable ground, filter, smoothing, signed DBSCAN, description), [`volume`]
//!   (regions, clipped watertight solids, uncertainty), over [`spatial`] indexes and [`io`];
//! - the [`store`] of immutable units in DIR/.talus, and the [`plan`] of a run's units with
//!   their dependencies, whose work [`units`] does (one module per kind of unit);
//! - drivers that execute a plan: [`exec`] (this process; `talus worker`), behind the commands
//!   [`compare`].
//!
//! [`synth`] writes synthetic pairs with exact ground truth; [`view`] serves the viewer.

pub mod campaign;
pub mod cli;
pub mod commands;
pub mod error;
pub mod events;
pub mod exec;
pub mod geom;
pub mod interrupt;
pub mod io;
pub mod m3c2;
pub mod memory;
pub mod params;
pub mod plan;
pub mod progress;
pub mod rng;
pub mod sampling;
pub mod spatial;
pub mod store;
pub mod synth;
pub mod units;
pub mod volume;

pub use error::{Error, Result};
