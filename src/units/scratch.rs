//! Scratch rows: a temporary file of fixed-width rows of f64 in a unit's directory, written in
//! order and read back in order, for what a unit must keep of every row of a stream it cannot
//! hold (the events unit's kept core points' other fields, the campaign's later pairs'
//! distances). Exact (the values' bits), removed by the unit before it commits.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::store::UnitWriter;

/// Bytes buffered by a writer or a reader (what a caller holding several reserves for each).
pub(crate) const BUFFER: usize = 1 << 16;

/// Scratch rows being written.
pub(crate) struct RowsWriter {
    path: PathBuf,
    file: BufWriter<File>,
    width: usize,
    rows: u64,
}

impl RowsWriter {
    /// A new scratch file `name` (ending in `.tmp`) of rows of `width` values in `out`'s directory.
    pub(crate) fn create(out: &mut UnitWriter, name: &str, width: usize) -> Result<RowsWriter> {
        let path = out.path(name)?;
        let file = File::create(&path).map_err(|e| Error::output(&path, e))?;
        Ok(RowsWriter {
            file: BufWriter::with_capacity(BUFFER, file),
            path,
            width,
            rows: 0,
        })
    }

    /// Append one row of `width` values.
    pub(crate) fn push(&mut self, row: &[f64]) -> Result<()> {
        debug_assert_eq!(row.len(), self.width);
        for v in row {
            self.file
                .write_all(&v.to_le_bytes())
                .map_err(|e| Error::output(&self.path, e))?;
        }
        self.rows += 1;
        Ok(())
    }

    /// The rows written, ready to be read.
    pub(crate) fn finish(mut self) -> Result<Rows> {
        self.file
            .flush()
            .map_err(|e| Error::output(&self.path, e))?;
        Ok(Rows {
            path: self.path,
            width: self.width,
            rows: self.rows,
        })
    }
}

/// Finished scratch rows.
pub(crate) struct Rows {
    path: PathBuf,
    width: usize,
    rows: u64,
}

impl Rows {
    /// Rows in the file.
    pub(crate) fn len(&self) -> u64 {
        self.rows
    }

    /// A reader from the first row.
    pub(crate) fn reader(&self) -> Result<RowsReader> {
        let file = File::open(&self.path).map_err(|e| Error::output(&self.path, e))?;
        Ok(RowsReader {
            path: self.path.clone(),
            file: BufReader::with_capacity(BUFFER, file),
            row: vec![0.0; self.width],
            input: false,
        })
    }

    /// Remove the file.
    pub(crate) fn remove(self) -> Result<()> {
        std::fs::remove_file(&self.path).map_err(|e| Error::output(&self.path, e))
    }
}

/// Scratch rows read in order.
pub(crate) struct RowsReader {
    path: PathBuf,
    file: BufReader<File>,
    row: Vec<f64>,
    /// Another unit's file (`RowsReader::input`): a short read is that unit's damage.
    input: bool,
}

impl RowsReader {
    /// Rows of `width` values that another unit wrote in the same layout (the kept ranges' rows),
    /// read from the first; failures are [`Error::Damaged`], so the executor computes that unit
    /// again.
    pub(crate) fn input(path: PathBuf, width: usize) -> Result<RowsReader> {
        let file = File::open(&path).map_err(|e| Error::Damaged {
            path: path.clone(),
            problem: e.to_string(),
        })?;
        Ok(RowsReader {
            path,
            file: BufReader::with_capacity(BUFFER, file),
            row: vec![0.0; width],
            input: true,
        })
    }

    fn error(&self, e: std::io::Error) -> Error {
        match self.input {
            true => Error::Damaged {
                path: self.path.clone(),
                problem: format!("fewer rows than its record says: {e}"),
            },
            false => Error::output(&self.path, e),
        }
    }

    /// The next row (the caller knows how many there are).
    pub(crate) fn next_row(&mut self) -> Result<&[f64]> {
        let mut b = [0u8; 8];
        for k in 0..self.row.len() {
            if let Err(e) = self.file.read_exact(&mut b) {
                return Err(self.error(e));
            }
            self.row[k] = f64::from_le_bytes(b);
        }
        Ok(&self.row)
    }

    /// The next values in order, as many as `out` holds (rows × width).
    pub(crate) fn next_values(&mut self, out: &mut [f64]) -> Result<()> {
        let mut bytes = [0u8; 8 * 512];
        for part in out.chunks_mut(512) {
            let b = &mut bytes[..8 * part.len()];
            if let Err(e) = self.file.read_exact(b) {
                return Err(self.error(e));
            }
            for (v, x) in part.iter_mut().zip(b.chunks_exact(8)) {
                *v = f64::from_le_bytes(x.try_into().expect("8 bytes"));
            }
        }
        Ok(())
    }
}
