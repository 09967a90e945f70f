//! talus-base: what every talus crate shares, beneath all of them — the [`error`] type (and its
//! exit codes), the seeded generators ([`rng`]) and the geometry of a point and its bounds
//! ([`geom`]). It depends on no other talus crate.

pub mod error;
pub mod geom;
pub mod rng;

pub use error::{Error, Result};
