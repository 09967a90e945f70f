//! A streaming Parquet writer of a flat table of DOUBLE or FLOAT columns (a campaign's
//! `timeseries.parquet`), through the `parquet` crate's low-level column writers.
//!
//! The file follows the Apache Parquet format specification (parquet-format,
//! <https://parquet.apache.org/docs/file-format/> and its `parquet.thrift`): the magic `PAR1`,
//! row groups each holding one column chunk per column, written column after column, and the
//! footer (`FileMetaData`: the schema, the row groups' column-chunk metadata, key-value
//! metadata, `created_by`). The schema is flat: every column a `DOUBLE` (IEEE 754 binary64) or
//! a `FLOAT` (binary32: a campaign's distances, stored as m3c2.laz stores them), `REQUIRED`, or
//! `OPTIONAL` where a value may be missing: a NaN given to an optional column is
//! written as a null (definition level 0, "Nested Encoding" in the specification, no value
//! stored), the others as values (definition level 1). Pages are data pages v1 (format 1.0,
//! what every reader reads), PLAIN-encoded (no dictionary: distances hardly repeat) and
//! zstd-compressed, with their min/max statistics and the page index.
//!
//! Memory is bounded whatever the table: a row group is written a column at a time, each column
//! in batches of [`BATCH`] values asked of the caller (`fill`), and each page goes to the file as
//! it fills; so the writer holds one batch and one page, not a row group, and the caller needs
//! one sequential source per column (the campaign's scratch columns on disk). Rows per group
//! ([`rows_per_group`]) are chosen for the readers: about [`GROUP_BYTES`] of values per group,
//! whatever the columns, so that a reader streaming row groups holds a bounded amount and the
//! footer (a column-chunk entry per column and group) stays small.
//!
//! The bytes depend on the values, the columns and the metadata only: no timestamp is written
//! and `created_by` is `talus version <crate version>`.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use parquet::basic::{Compression, Encoding, Repetition, Type as PhysicalType, ZstdLevel};
use parquet::data_type::{DoubleType, FloatType};
use parquet::file::metadata::KeyValue;
use parquet::file::properties::{WriterProperties, WriterVersion};
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::Type;

use crate::error::{Error, Result};

/// Values asked of the caller at a time, per column.
pub(crate) const BATCH: usize = 1 << 16;
/// Bytes of values (8 a value) a row group holds, about: rows per group are this over the row's
/// width, so that a group's decoded size stays near it however many columns.
pub(crate) const GROUP_BYTES: usize = 64 << 20;
/// Fewest rows per group (a table of more than 8,192 columns has groups above `GROUP_BYTES`).
pub(crate) const MIN_GROUP_ROWS: usize = 1024;
/// Most rows per group (the `parquet` crate's and pyarrow's default).
pub(crate) const MAX_GROUP_ROWS: usize = 1 << 20;
/// Rows per data page, at most (the `parquet` crate's default; a page closes at 1 MiB too).
const PAGE_ROWS: usize = 20_000;
/// The zstd level of the pages (3: zstd's default; level 1 saves little time on doubles).
const ZSTD_LEVEL: i32 = 3;

/// A column of the table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Column {
    pub name: String,
    /// OPTIONAL (NaN written as null) rather than REQUIRED (every value written; NaN refused).
    pub nullable: bool,
    /// FLOAT (IEEE 754 binary32: each value rounded to the nearest) rather than DOUBLE.
    pub single: bool,
}

impl Column {
    pub(crate) fn required(name: &str) -> Column {
        Column {
            name: name.into(),
            nullable: false,
            single: false,
        }
    }

    pub(crate) fn nullable(name: &str) -> Column {
        Column {
            name: name.into(),
            nullable: true,
            single: false,
        }
    }

    /// This column as FLOAT.
    pub(crate) fn single(self) -> Column {
        Column {
            single: true,
            ..self
        }
    }
}

/// Rows per row group for a table of `columns` DOUBLE columns: [`GROUP_BYTES`] over the row's
/// 8 · `columns` bytes, rounded down to a multiple of 1024, within [`MIN_GROUP_ROWS`] and
/// [`MAX_GROUP_ROWS`] (403 columns: 20,480 rows; 6 columns: 1,048,576).
pub(crate) fn rows_per_group(columns: usize) -> usize {
    let rows = GROUP_BYTES / (8 * columns.max(1));
    (rows / 1024 * 1024).clamp(MIN_GROUP_ROWS, MAX_GROUP_ROWS)
}

/// The memory (bytes) [`ParquetWriter`] needs for `rows` rows of `columns` columns: one batch of
/// values, non-null values and definition levels, one page and its compressed copy, zstd's
/// context, and the footer it keeps until the end (a column chunk's metadata,
/// column index and offset index, per column and row group, and per page).
pub(crate) fn memory_need(columns: usize, rows: u64) -> u64 {
    let groups = rows.div_ceil(rows_per_group(columns) as u64).max(1);
    let chunks = groups * columns as u64;
    let pages = chunks + rows.div_ceil(PAGE_ROWS as u64) * columns as u64;
    let fixed = BATCH * (8 + 8 + 4 + 2) + 4 * (PAGE_ROWS * 8) + crate::memory::IO_HEADROOM as usize;
    fixed as u64 + chunks * 1024 + pages * 64
}

/// A Parquet file being written; see the module documentation.
pub(crate) struct ParquetWriter {
    path: PathBuf,
    /// Written under its temporary name, renamed onto `path` by [`ParquetWriter::finish`];
    /// removed if never finished.
    file: Option<talus_tiling::AtomicFile>,
    writer: Option<SerializedFileWriter<File>>,
    columns: Vec<Column>,
    rows: u64,
    values: Vec<f64>,
    present: Vec<f64>,
    /// The batch's values as FLOAT, for a [`Column::single`].
    singles: Vec<f32>,
    levels: Vec<i16>,
}

impl ParquetWriter {
    /// A new file at `path` (written as `<path>.tmp`, renamed by `finish`) of `columns`, with the
    /// key-value metadata `metadata` (in this order) in its footer.
    pub(crate) fn create(
        path: &Path,
        columns: &[Column],
        metadata: &[(String, String)],
    ) -> Result<Self> {
        let mut seen = std::collections::HashSet::new();
        for c in columns {
            if c.name.is_empty() || !seen.insert(c.name.as_str()) {
                return Err(Error::Internal(format!(
                    "Parquet column '{}': empty or given twice",
                    c.name
                )));
            }
        }
        let fail = |e: parquet::errors::ParquetError| Error::output(path, std::io::Error::other(e));
        let fields = columns
            .iter()
            .map(|c| {
                let repetition = if c.nullable {
                    Repetition::OPTIONAL
                } else {
                    Repetition::REQUIRED
                };
                let physical = match c.single {
                    true => PhysicalType::FLOAT,
                    false => PhysicalType::DOUBLE,
                };
                Type::primitive_type_builder(&c.name, physical)
                    .with_repetition(repetition)
                    .build()
                    .map(Arc::new)
            })
            .collect::<std::result::Result<Vec<_>, _>>()
            .map_err(fail)?;
        let schema = Type::group_type_builder("schema")
            .with_fields(fields)
            .build()
            .map_err(fail)?;
        let level = ZstdLevel::try_new(ZSTD_LEVEL).map_err(fail)?;
        let properties = WriterProperties::builder()
            .set_writer_version(WriterVersion::PARQUET_1_0)
            .set_created_by(format!("talus version {}", env!("CARGO_PKG_VERSION")))
            .set_compression(Compression::ZSTD(level))
            .set_dictionary_enabled(false)
            .set_encoding(Encoding::PLAIN)
            .set_data_page_row_count_limit(PAGE_ROWS)
            .set_max_row_group_row_count(Some(MAX_GROUP_ROWS))
            .set_key_value_metadata(Some(
                metadata
                    .iter()
                    .map(|(k, v)| KeyValue::new(k.clone(), v.clone()))
                    .collect(),
            ))
            .build();
        let atomic = talus_tiling::AtomicFile::new(path);
        let file = File::create(atomic.tmp()).map_err(|e| Error::output(path, e))?;
        let writer = SerializedFileWriter::new(file, Arc::new(schema), Arc::new(properties))
            .map_err(fail)?;
        Ok(ParquetWriter {
            path: path.to_path_buf(),
            file: Some(atomic),
            writer: Some(writer),
            columns: columns.to_vec(),
            rows: 0,
            values: Vec::new(),
            present: Vec::new(),
            singles: Vec::new(),
            levels: Vec::new(),
        })
    }

    fn fail(&self, e: parquet::errors::ParquetError) -> Error {
        Error::output(&self.path, std::io::Error::other(e))
    }

    /// Write one row group of `rows` rows: column after column, each in batches of at most
    /// [`BATCH`] values, `fill(column, values)` filling `values` with the column's next values
    /// (so each column is asked for its values in order, a group after the other).
    pub(crate) fn write_group(
        &mut self,
        rows: usize,
        fill: &mut dyn FnMut(usize, &mut [f64]) -> Result<()>,
    ) -> Result<()> {
        if rows == 0 {
            return Ok(());
        }
        let mut writer = self
            .writer
            .take()
            .ok_or_else(|| Error::Internal("Parquet: write after finish".into()))?;
        let result = self.group(&mut writer, rows, fill);
        self.writer = Some(writer);
        result?;
        self.rows += rows as u64;
        Ok(())
    }

    fn group(
        &mut self,
        writer: &mut SerializedFileWriter<File>,
        rows: usize,
        fill: &mut dyn FnMut(usize, &mut [f64]) -> Result<()>,
    ) -> Result<()> {
        let mut group = writer.next_row_group().map_err(|e| self.fail(e))?;
        for (c, column) in self.columns.iter().enumerate() {
            let mut chunk = group
                .next_column()
                .map_err(|e| Error::output(&self.path, std::io::Error::other(e)))?
                .ok_or_else(|| Error::Internal("Parquet: fewer columns than the schema".into()))?;
            let mut left = rows;
            while left > 0 {
                let n = left.min(BATCH);
                self.values.resize(n, 0.0);
                fill(c, &mut self.values)?;
                let levels = if column.nullable {
                    self.present.clear();
                    self.levels.clear();
                    for &v in &self.values {
                        if v.is_nan() {
                            self.levels.push(0);
                        } else {
                            self.levels.push(1);
                            self.present.push(v);
                        }
                    }
                    Some(&self.levels[..])
                } else {
                    if self.values.iter().any(|v| v.is_nan()) {
                        return Err(Error::Internal(format!(
                            "Parquet column '{}' is required: NaN given",
                            column.name
                        )));
                    }
                    None
                };
                let values = match levels {
                    Some(_) => &self.present,
                    None => &self.values,
                };
                let written = if column.single {
                    self.singles.clear();
                    self.singles.extend(values.iter().map(|&v| v as f32));
                    let typed = chunk.typed::<FloatType>();
                    typed.write_batch(&self.singles, levels, None)
                } else {
                    let typed = chunk.typed::<DoubleType>();
                    typed.write_batch(values, levels, None)
                };
                written.map_err(|e| Error::output(&self.path, std::io::Error::other(e)))?;
                left -= n;
            }
            chunk
                .close()
                .map_err(|e| Error::output(&self.path, std::io::Error::other(e)))?;
        }
        group.close().map_err(|e| self.fail(e))?;
        Ok(())
    }

    /// Write the footer, sync and rename the file onto its name; the rows written.
    pub(crate) fn finish(mut self) -> Result<u64> {
        let writer = self
            .writer
            .take()
            .ok_or_else(|| Error::Internal("Parquet: finish called twice".into()))?;
        let file = writer.into_inner().map_err(|e| self.fail(e))?;
        file.sync_all().map_err(|e| Error::output(&self.path, e))?;
        drop(file);
        if let Some(f) = self.file.take() {
            f.commit()?;
        }
        Ok(self.rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use parquet::file::reader::{FileReader, SerializedFileReader};
    use parquet::record::Field;

    /// Rows of `columns` values as the `parquet` crate's reader gives them back (None: null).
    fn read_back(path: &Path) -> (Vec<Vec<Option<f64>>>, SerializedFileReader<File>) {
        let reader = SerializedFileReader::new(File::open(path).unwrap()).unwrap();
        let rows = reader
            .get_row_iter(None)
            .unwrap()
            .map(|r| {
                r.unwrap()
                    .get_column_iter()
                    .map(|(_, f)| match f {
                        Field::Double(v) => Some(*v),
                        Field::Null => None,
                        other => panic!("not a double: {other:?}"),
                    })
                    .collect()
            })
            .collect();
        (
            rows,
            SerializedFileReader::new(File::open(path).unwrap()).unwrap(),
        )
    }

    /// Write `table` (rows) in groups of `group` rows; column 0 required, the others nullable.
    fn write(path: &Path, table: &[Vec<f64>], group: usize, meta: &[(String, String)]) -> u64 {
        let width = table[0].len();
        let columns: Vec<Column> = (0..width)
            .map(|c| {
                if c == 0 {
                    Column::required("x")
                } else {
                    Column::nullable(&format!("d_{c}"))
                }
            })
            .collect();
        let mut w = ParquetWriter::create(path, &columns, meta).unwrap();
        let mut next = vec![0usize; width];
        let mut start = 0;
        while start < table.len() {
            let n = group.min(table.len() - start);
            w.write_group(n, &mut |c, out| {
                for v in out.iter_mut() {
                    *v = table[next[c]][c];
                    next[c] += 1;
                }
                Ok(())
            })
            .unwrap();
            start += n;
        }
        w.finish().unwrap()
    }

    fn table(rows: usize, width: usize) -> Vec<Vec<f64>> {
        (0..rows)
            .map(|r| {
                (0..width)
                    .map(|c| {
                        if c > 0 && (r + c) % 7 == 0 {
                            f64::NAN
                        } else {
                            (r as f64).sqrt() * 0.001 + c as f64 - 1e-300 * r as f64
                        }
                    })
                    .collect()
            })
            .collect()
    }

    /// Every value comes back (NaN of an optional column as null), in every row group, with the
    /// metadata, `created_by` and the schema's repetitions; nothing but the file is left.
    #[test]
    fn values_nulls_groups_and_metadata_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        // More rows than a batch, in groups that split batches.
        let t = table(BATCH + 1000, 4);
        let meta = vec![
            ("talus:version".to_string(), "x.y".to_string()),
            ("talus:crs_epsg".to_string(), "32633".to_string()),
        ];
        assert_eq!(write(&path, &t, 40_000, &meta), t.len() as u64);
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["t.parquet"]);
        let (rows, reader) = read_back(&path);
        assert_eq!(rows.len(), t.len());
        for (got, want) in rows.iter().zip(&t) {
            for (g, w) in got.iter().zip(want) {
                match g {
                    None => assert!(w.is_nan()),
                    Some(g) => assert_eq!(g.to_bits(), w.to_bits()),
                }
            }
        }
        let m = reader.metadata();
        assert_eq!(m.num_row_groups(), 2);
        assert_eq!(m.row_group(0).num_rows(), 40_000);
        let f = m.file_metadata();
        assert_eq!(
            f.created_by(),
            Some(format!("talus version {}", env!("CARGO_PKG_VERSION")).as_str())
        );
        let kv: Vec<(String, Option<String>)> = f
            .key_value_metadata()
            .unwrap()
            .iter()
            .map(|k| (k.key.clone(), k.value.clone()))
            .collect();
        assert_eq!(
            kv,
            meta.iter()
                .map(|(k, v)| (k.clone(), Some(v.clone())))
                .collect::<Vec<_>>()
        );
        let schema = f.schema_descr();
        assert_eq!(schema.num_columns(), 4);
        assert_eq!(schema.column(0).max_def_level(), 0);
        assert_eq!(schema.column(1).max_def_level(), 1);
        assert_eq!(schema.column(2).name(), "d_2");
        // Null counts in the statistics.
        let nulls = m
            .row_group(0)
            .column(1)
            .statistics()
            .unwrap()
            .null_count_opt();
        let want = t[..40_000].iter().filter(|r| r[1].is_nan()).count() as u64;
        assert_eq!(nulls, Some(want));
    }

    /// The same table gives the same bytes (no timestamp, no random hashing in the file).
    #[test]
    fn same_table_same_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let t = table(3000, 3);
        let (a, b) = (dir.path().join("a.parquet"), dir.path().join("b.parquet"));
        write(&a, &t, 1000, &[]);
        write(&b, &t, 1000, &[]);
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    }

    /// A NaN in a required column is refused; a writer dropped unfinished leaves no file.
    #[test]
    fn nan_in_a_required_column_is_refused_and_nothing_is_left() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        let mut w = ParquetWriter::create(&path, &[Column::required("x")], &[]).unwrap();
        let e = w.write_group(3, &mut |_, out| {
            out.fill(f64::NAN);
            Ok(())
        });
        assert!(e.is_err());
        drop(w);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        assert!(
            ParquetWriter::create(&path, &[Column::required("x"), Column::nullable("x")], &[])
                .is_err()
        );
    }

    /// Rows per group keep a group near GROUP_BYTES, within the bounds.
    #[test]
    fn rows_per_group_follow_the_width() {
        assert_eq!(rows_per_group(403), 20_480);
        assert_eq!(rows_per_group(6), MAX_GROUP_ROWS);
        assert_eq!(rows_per_group(100_000), MIN_GROUP_ROWS);
        for c in [1, 4, 50, 403, 2000, 8192] {
            let r = rows_per_group(c);
            assert!(r * 8 * c <= GROUP_BYTES, "{c}");
            assert!(r.is_multiple_of(1024));
        }
        assert!(memory_need(403, 1_000_000) < 64 << 20);
    }
}
