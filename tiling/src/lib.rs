//! talus-tiling: out-of-core spatial tiles with halos, for talus (SPEC.md §3).
//!
//! A 120M-point epoch does not fit in a 2 GiB budget together with its kd-trees, so talus cuts
//! both epochs into the same grid of square XY tiles, each stored on disk with a halo wide enough
//! for every neighbourhood computed inside it, and processes one tile at a time. Every file here
//! is written whole and atomically and checked whole when read, so a run killed with SIGKILL
//! leaves either a complete tile file or none; what is finished and where a run resumes is
//! talus's store (`talus::store`: a unit directory committed by one rename), not this crate's.
//!
//! Modules: [`grid`] (tile geometry and planning), [`tile_file`] (compact checksummed tile files,
//! [`framed`] among them), [`splitter`] (stream points into tiles with bounded memory),
//! [`atomic`] (crash-safe file replacement) and [`hash`] (stable 64-bit keys).
//!
//! This crate depends on `talus-base` alone (its bounds type, and the error its own [`Error`]
//! converts into); its [`Error`] carries the path and the problem.

pub mod atomic;
pub mod error;
pub mod grid;
pub mod hash;
pub mod splitter;
pub mod tile_file;

pub use atomic::{atomic_write, atomic_write_with, AtomicFile};
pub use error::{Error, Result};
pub use grid::{BoundsXY, TileGrid, TileId};
pub use hash::{hash64, Fnv64};
pub use splitter::{empty_columns, tile_path, TileSplitter, OWNED_COLUMN};
pub use tile_file::framed;
pub use tile_file::{
    encode_tile, read_tile, read_tile_frames, read_tile_header, read_u32_columns, write_tile,
    write_tile_with, Column, ColumnData, FileDigest, Quantisation, TileColumns, TileFrames,
    TileHeader, WriteOptions,
};
