//! Writing tile files of format version 1 (a framed tile is written by [`super::framed`]).

use std::path::Path;

use super::codec::encode;
use super::{FileDigest, TileColumns, WriteOptions};
use crate::atomic::atomic_write;
use crate::error::{Error, Result};

/// Write `cols` to `path` atomically with the default [`WriteOptions`].
pub fn write_tile(path: &Path, cols: &TileColumns) -> Result<FileDigest> {
    write_tile_with(path, cols, &WriteOptions::default())
}

/// Write `cols` to `path` atomically; returns the written file's digest.
pub fn write_tile_with(path: &Path, cols: &TileColumns, opts: &WriteOptions) -> Result<FileDigest> {
    let bytes = encode(cols, opts).map_err(|p| Error::invalid(path, p))?;
    atomic_write(path, &bytes)?;
    Ok(FileDigest::of(&bytes))
}

/// The bytes of a tile file holding `cols` (what [`write_tile_with`] writes), for a caller that
/// writes the file itself (into a directory it makes durable as a whole, say); the error names
/// what is wrong with the columns.
pub fn encode_tile(cols: &TileColumns, opts: &WriteOptions) -> Result<Vec<u8>, String> {
    encode(cols, opts)
}
