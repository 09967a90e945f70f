//! Neighbourhood queries on one epoch's points, in a local frame (coordinates relative to an
//! origin, so that UTM-sized values do not cost precision in the distance arithmetic).
//!
//! - [`Index`]: a kd-tree (kiddo 6) for k-nearest and radius queries of the later stages
//!   (spacing, smoothing, DBSCAN, volumes).
//! - [`Columns`]: a grid of vertical point columns sorted by height, for the two queries M3C2 makes
//!   at every core point: a sphere (normals) and a cylinder along an arbitrary axis.
//! - `BoxIndex`: which of many xy boxes contain a point (events' search boxes and claims).
//! - `DensityGrid`: points per XY cell of a survey, and its densest square (tile sizes).
//! - `Pairs`: the pairs of points within a distance (the stable ground's variogram).
//! - `Tubes`: which of many long thin cylinders hold a point (M3C2's walk across tiles).
//! - [`areas::Areas`]: the user's stable areas (`--stable`), polygons and point-in-polygon.

pub mod areas;
mod boxes;
mod columns;
mod density;
mod grid;
mod kdtree;
mod pairs;
mod tubes;

pub(crate) use boxes::BoxIndex;
pub use columns::{in_cylinder, Columns};
pub(crate) use density::DensityGrid;
pub use kdtree::Index;
pub(crate) use pairs::Pairs;
pub(crate) use tubes::Tubes;
