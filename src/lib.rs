//! talus: change events and volumes between terrain surveys.
//!
//! The layers, from the bottom (ARCHITECTURE.md; `tests/layers.rs` checks that imports only go
//! down):
//! - base: [`error`], [`interrupt`], [`progress`], [`memory`], [`geom`], [`rng`];
//! - pure algorithms, functions of their inputs: [`spatial`] indexes, [`m3c2`] (normals and
//!   distances at core points), [`events`] (stable ground, filter, smoothing, signed DBSCAN,
//!   description), [`volume`] (regions, clipped watertight solids, uncertainty), [`campaign`]
//!   (pairs, tracks, magnitude–frequency, the report), [`synth`] (scenes with exact truth);
//! - formats: [`io`] (and the `talus_tiling` crate's tile files);
//! - parameters: [`sampling`], [`params`];
//! - the [`store`] of immutable units in DIR/.talus;
//! - the [`plan`] of a run's units, and the stages that plan and do them: [`units`];
//! - drivers that execute a plan: [`exec`] (this process, `talus worker`, Slurm);
//! - the [`commands`] and the command line over them, [`cli`].
//!
//! [`error`], [`geom`] and [`rng`] (the `talus-base` crate), the [`store`] (`talus-store`) and
//! [`synth`] (`talus-synth`) are crates of their own beneath this one, re-exported here under
//! their layers' names; `talus-tiling` is the tiling crate (ARCHITECTURE.md "The crates").

pub mod campaign;
pub mod cli;
pub mod commands;
pub mod events;
pub mod exec;
pub mod interrupt;
pub mod io;
pub mod m3c2;
pub mod memory;
pub mod params;
pub mod plan;
pub mod progress;
pub mod sampling;
pub mod spatial;
pub mod units;
pub mod volume;

/// Large blocks on huge pages (see `memory::large`).
#[global_allocator]
static ALLOCATOR: memory::large::Allocator = memory::large::Allocator;

pub use error::{Error, Result};

// The crates beneath this one, under the names the layers give them (`crate::store::Store`,
// `talus::synth::synth`): base (error, rng, geom), store, synth.
pub use talus_base::{error, geom, rng};
pub use talus_store as store;
pub use talus_synth as synth;
