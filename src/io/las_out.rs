//! Streaming LAS 1.4 / LAZ writer for result points with extra-bytes dimensions (`m3c2.laz`).
//!
//! Layout (ASPRS LAS 1.4 R15):
//! - point format 6 (30-byte base record, §2.6.7), except when the input CRS is GeoTIFF only:
//!   then point format 0 (§2.6.1). Formats 6–10 must carry the CRS as WKT (§2.4, global
//!   encoding bit 4), and `las` 0.11 sets the WKT bit for every extended format; GeoTIFF records
//!   under that bit would be ignored by readers that honour it (PDAL). Format 0 keeps the
//!   GeoTIFF records valid and copied verbatim, since we have no EPSG database to turn them into
//!   WKT.
//! - each record is the base record followed by the extra bytes of the dimensions, in order,
//!   little-endian;
//! - an Extra Bytes VLR (user id `LASF_Spec`, record id 4, §2.5.5 / Table 24) with one 192-byte
//!   descriptor per dimension, written here because `las` does not write it;
//! - coordinates on a [`CoordinateGrid`]: the inputs' finest scale but at most 0.001
//!   (millimetres), with an offset near the data (rounded to a whole kilometre) so that UTM-sized
//!   coordinates keep that precision in the i32 records;
//! - the input CRS copied: the WKT VLR when the input had WKT (with the WKT bit), otherwise the
//!   GeoTIFF VLRs verbatim. Records over 65 535 bytes go to EVLRs.
//!
//! The file is written to `<path>.tmp` and renamed onto `path` by [`ResultWriter::finish`]; a
//! writer dropped before `finish` (an error, a panic, an interrupt) deletes the temporary file,
//! so nothing half-written is ever left under the final name (SPEC.md §2).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use super::Crs;
use crate::error::{Error, Result};

/// Storage type of an extra dimension (LAS 1.4 R15 Table 25 data_type codes in `ExtraType::code`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExtraType {
    U8,
    U32,
    I32,
    F32,
    F64,
}

impl ExtraType {
    /// Bytes per value.
    pub(crate) fn size(self) -> usize {
        match self {
            ExtraType::U8 => 1,
            ExtraType::U32 | ExtraType::I32 | ExtraType::F32 => 4,
            ExtraType::F64 => 8,
        }
    }

    /// The `data_type` code of the Extra Bytes descriptor.
    pub(crate) fn code(self) -> u8 {
        match self {
            ExtraType::U8 => 1,
            ExtraType::U32 => 5,
            ExtraType::I32 => 6,
            ExtraType::F32 => 9,
            ExtraType::F64 => 10,
        }
    }
}

/// One extra dimension appended to every point record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExtraDim {
    /// At most 32 bytes (LAS descriptor field), unique within a file. Borrowed for the fixed
    /// dimensions of m3c2.laz, owned for the per-pair ones of a campaign's time series.
    pub name: std::borrow::Cow<'static, str>,
    pub ty: ExtraType,
    /// At most 32 bytes.
    pub description: &'static str,
}

/// Points of a LAZ chunk when the number of points is not known (LASzip's default).
const CHUNK: u64 = 50_000;

/// Chunks per batch: points are handed to the compressor four chunks at a time, so that the
/// parallel compressor has a chunk for every core of a small machine.
const CHUNKS_PER_BATCH: usize = 4;

/// The LAZ chunk size for `n` points: about `CHUNK` (50 000), the chunks a multiple of
/// `CHUNKS_PER_BATCH` (4) in number and all of one size, with fewer points left over (a last,
/// small chunk) than there are chunks. The compressor compresses the complete chunks of a batch in parallel and a last partial
/// chunk alone when the file is closed: with fixed 50 000-point chunks the 49 856 points after
/// the first 50 000 of a 99 856-point file were compressed on one core after the first chunk,
/// also on one core. Depends only on `n`, so the file's bytes do not depend on the machine.
pub fn laz_chunk_size(n: Option<u64>) -> u32 {
    let Some(n) = n else {
        return CHUNK as u32;
    };
    let per = CHUNKS_PER_BATCH as u64;
    // Below this, one chunk: not worth splitting.
    if n < per * 10_000 {
        return n.clamp(1, CHUNK) as u32;
    }
    let chunks = n.div_ceil(CHUNK).div_ceil(per) * per;
    (n / chunks).clamp(1, u64::from(u32::MAX)) as u32
}

/// The coarsest coordinate scale written: millimetres.
pub(crate) const SCALE: f64 = 0.001;

/// How coordinates are stored in the i32 records: per-axis scale and offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoordinateGrid {
    pub scale: [f64; 3],
    pub offset: [f64; 3],
}

impl CoordinateGrid {
    /// Millimetres, with offsets at `origin_hint` rounded to a whole kilometre.
    pub fn millimetre(origin_hint: [f64; 3]) -> Self {
        CoordinateGrid {
            scale: [SCALE; 3],
            offset: origin_hint.map(round_to_km),
        }
    }

    /// The grid for points within `min..=max` that come from files with the coordinate quanta
    /// `input_scales`: per axis the finest of those, but never coarser than a millimetre, so that
    /// input coordinates are written back exactly (a core point of a 0.1 mm survey keeps its
    /// 0.1 mm) when the files' grids nest (scales that are powers of ten, offsets on them).
    /// Offsets at the centre rounded to a whole kilometre (a multiple of every usual scale). An
    /// axis whose extent would overflow the i32 records at that scale is coarsened tenfold until
    /// it fits.
    pub(crate) fn for_extent(min: [f64; 3], max: [f64; 3], input_scales: &[[f64; 3]]) -> Self {
        let mut grid = CoordinateGrid::millimetre([0.0; 3]);
        for a in 0..3 {
            let finest = input_scales
                .iter()
                .map(|s| s[a])
                .filter(|s| s.is_finite() && *s > 0.0)
                .fold(SCALE, f64::min);
            let centre = 0.5 * (min[a] + max[a]);
            let offset = round_to_km(centre);
            let reach = (max[a] - offset).abs().max((min[a] - offset).abs());
            let mut scale = finest;
            // 2³¹ − 1 with a margin for rounding.
            while reach.is_finite() && reach / scale > 2.0e9 && scale < SCALE {
                scale = decimal(scale * 10.0);
            }
            grid.scale[a] = scale.min(SCALE);
            grid.offset[a] = offset;
        }
        grid
    }
}

impl CoordinateGrid {
    /// The record of coordinate `v` of axis `axis` on the grid (the nearest step); None when it
    /// does not fit an i32.
    pub(crate) fn record(&self, axis: usize, v: f64) -> Option<i32> {
        let r = ((v - self.offset[axis]) / self.scale[axis]).round();
        (r >= f64::from(i32::MIN) && r <= f64::from(i32::MAX)).then_some(r as i32)
    }

    /// `xyz` as a LAS reader decodes it once written on the grid: record · scale + offset per
    /// axis (LAS 1.4 R15 §2.4), in f64 as laspy and PDAL compute it. None when a record does not
    /// fit.
    pub(crate) fn decoded(&self, xyz: [f64; 3]) -> Option<[f64; 3]> {
        let mut out = [0.0; 3];
        for (a, o) in out.iter_mut().enumerate() {
            *o = f64::from(self.record(a, xyz[a])?) * self.scale[a] + self.offset[a];
        }
        Some(out)
    }
}

/// The most extra dimensions whose descriptors (192 bytes each) fit the Extra Bytes VLR, whose
/// record length is a u16 (LAS 1.4 R15 §2.5.1): 341. More go to an EVLR, which laspy does not
/// read extra bytes from.
pub(crate) const MAX_VLR_EXTRA_DIMS: usize = u16::MAX as usize / 192;

/// `s` itself, or the power of ten it is within rounding of, written exactly as that decimal
/// (1e-5, not 1.0000000000000002e-5, in the header a reader prints).
fn decimal(s: f64) -> f64 {
    let k = s.log10().round();
    if (s.log10() - k).abs() < 1e-9 && (-22.0..=22.0).contains(&k) {
        if k < 0.0 {
            1.0 / 10f64.powi(-k as i32)
        } else {
            10f64.powi(k as i32)
        }
    } else {
        s
    }
}

fn round_to_km(v: f64) -> f64 {
    if v.is_finite() {
        (v / 1000.0).round() * 1000.0
    } else {
        0.0
    }
}

/// Where the records go: `las`'s writer for LAS, for LAZ the compressor itself, so that the chunk
/// size is ours ([`laz_chunk_size`]; `las` 0.11 always writes 50 000-point chunks).
enum Sink {
    Las(las::Writer<BufWriter<File>>),
    Laz(Box<LazSink>),
}

/// The header as written, counting the points and their bounds as they come, and the
/// compressor: what the compressing thread holds.
type Compressing = (las::Header, laz::ParLasZipCompressor<BufWriter<File>>);

/// A LAZ file compressed on a thread of its own, a batch at a time, while the caller fills the
/// next batch (compressing had the caller wait: a third of writing m3c2.laz at 120M points).
struct LazSink {
    to_thread: Option<crossbeam_channel::Sender<las::PointData>>,
    /// Batches compressed and emptied, for the caller to fill again.
    back: crossbeam_channel::Receiver<las::PointData>,
    thread: Option<std::thread::JoinHandle<std::io::Result<Compressing>>>,
}

impl LazSink {
    fn start(header: las::Header, compressor: laz::ParLasZipCompressor<BufWriter<File>>) -> Self {
        let (to_thread, batches) = crossbeam_channel::bounded::<las::PointData>(1);
        let (done, back) = crossbeam_channel::bounded(2);
        // The caller's first spare batch: an empty one of the file's layout.
        let _ = done.send(las::PointDataBuilder::new().for_header(&header).build());
        let thread = std::thread::spawn(move || -> std::io::Result<Compressing> {
            let (mut header, mut compressor) = (header, compressor);
            for mut batch in batches {
                header.add_point_data(&batch);
                compressor.compress_many(batch.raw_bytes())?;
                batch.resize_for(0);
                let _ = done.send(batch);
            }
            Ok((header, compressor))
        });
        LazSink {
            to_thread: Some(to_thread),
            back,
            thread: Some(thread),
        }
    }

    /// Why the compressing thread stopped taking batches.
    fn stopped(&mut self) -> las::Error {
        las::Error::Io(
            self.join()
                .err()
                .unwrap_or_else(|| std::io::Error::other("the LAZ compressing thread stopped")),
        )
    }

    /// The compressing thread's outcome, once it has stopped.
    fn join(&mut self) -> std::io::Result<Compressing> {
        self.to_thread = None;
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(outcome)) => outcome,
            Some(Err(_)) => Err(std::io::Error::other("the LAZ compressing thread panicked")),
            None => Err(std::io::Error::other("the LAZ compressing thread is gone")),
        }
    }
}

impl Sink {
    /// Write `batch`; it comes back empty (for LAZ, another batch of the same layout).
    fn write(&mut self, batch: &mut las::PointData) -> std::result::Result<(), las::Error> {
        match self {
            Sink::Las(w) => w.write_points(batch),
            Sink::Laz(z) => {
                let Ok(spare) = z.back.recv() else {
                    return Err(z.stopped());
                };
                let full = std::mem::replace(batch, spare);
                let sent = z.to_thread.as_ref().is_some_and(|t| t.send(full).is_ok());
                if !sent {
                    return Err(z.stopped());
                }
                Ok(())
            }
        }
    }

    /// Complete the file (the last chunk, the chunk table, the EVLRs, the header's counts and
    /// bounds) and hand back the file.
    fn close(self) -> std::result::Result<File, std::io::Error> {
        let w = match self {
            Sink::Las(mut w) => {
                // `close` explicitly: `las::Writer`'s own Drop/into_inner would panic on a
                // failing close.
                if let Err(e) = w.close() {
                    std::mem::forget(w);
                    return Err(to_io(e));
                }
                w.into_inner().map_err(to_io)?
            }
            Sink::Laz(mut z) => {
                let (header, mut compressor) = z.join()?;
                compressor
                    .done()
                    .map_err(|e| std::io::Error::other(e.to_string()))?;
                let mut w = compressor.into_inner();
                let start_of_first_evlr = w.stream_position()?;
                for evlr in header.evlrs() {
                    evlr.clone()
                        .into_raw(true)
                        .and_then(|r| r.write_to(&mut w))
                        .map_err(to_io)?;
                }
                let mut raw = header.into_raw().map_err(to_io)?;
                if let Some(e) = raw.evlr.as_mut() {
                    e.start_of_first_evlr = start_of_first_evlr;
                }
                w.seek(SeekFrom::Start(0))?;
                raw.write_to(&mut w).map_err(to_io)?;
                w
            }
        };
        w.into_inner().map_err(|e| e.into_error())
    }
}

/// A streaming LAS/LAZ writer of result points; see the module doc.
pub struct ResultWriter {
    path: PathBuf,
    /// Written under its temporary name; removed if never finished.
    file: Option<talus_tiling::AtomicFile>,
    sink: Option<Sink>,
    batch: las::PointData,
    buffered: usize,
    /// Points handed over at a time.
    batch_len: usize,
    dims: Vec<ExtraDim>,
    base_len: usize,
    record_len: usize,
    extended: bool,
    grid: CoordinateGrid,
    count: u64,
}

impl ResultWriter {
    /// Writes to `<path>.tmp` then renames on finish. LAZ when path ends with .laz. Coordinates
    /// in millimetres (see [`CoordinateGrid::millimetre`]).
    pub fn create(
        path: &Path,
        crs: &Crs,
        dims: &[ExtraDim],
        origin_hint: [f64; 3],
    ) -> Result<Self> {
        Self::create_on_grid(
            path,
            crs,
            dims,
            CoordinateGrid::millimetre(origin_hint),
            None,
        )
    }

    /// [`ResultWriter::create`] with coordinates stored on `grid`; `expected` points, when the
    /// caller knows how many it will write, size the LAZ chunks ([`laz_chunk_size`]; any number
    /// may still be written).
    pub fn create_on_grid(
        path: &Path,
        crs: &Crs,
        dims: &[ExtraDim],
        grid: CoordinateGrid,
        expected: Option<u64>,
    ) -> Result<Self> {
        let mut seen = std::collections::HashSet::new();
        for d in dims {
            if d.name.is_empty() || d.name.len() > 32 || d.description.len() > 32 {
                return Err(Error::Internal(format!(
                    "extra dimension '{}': name must be 1..=32 bytes, description at most 32",
                    d.name
                )));
            }
            if !seen.insert(d.name.as_ref()) {
                return Err(Error::Internal(format!(
                    "extra dimension '{}' given twice",
                    d.name
                )));
            }
        }
        let compress = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("laz"));
        let atomic = talus_tiling::AtomicFile::new(path);
        let tmp = atomic.tmp().to_path_buf();

        let has_wkt = crs.vlrs.iter().any(|v| v.record_id == 2112) || crs.wkt.is_some();
        let has_geotiff = crs
            .vlrs
            .iter()
            .any(|v| (34735..=34737).contains(&v.record_id));
        // See the module doc: GeoTIFF-only CRS -> point format 0, otherwise 6.
        let extended = has_wkt || !has_geotiff;
        let extra: usize = dims.iter().map(|d| d.ty.size()).sum();
        let mut format = las::point::Format::new(if extended { 6 } else { 0 })
            .map_err(|e| Error::Internal(e.to_string()))?;
        format.extra_bytes = u16::try_from(extra)
            .map_err(|_| Error::Internal("too many extra bytes per point".into()))?;
        format.is_compressed = compress;
        let base_len = usize::from(format.len()) - extra;

        let axis = |a: usize| las::Transform {
            scale: grid.scale[a],
            offset: grid.offset[a],
        };
        let transforms = las::Vector {
            x: axis(0),
            y: axis(1),
            z: axis(2),
        };

        let mut builder = las::Builder::from((1, 4));
        builder.point_format = format;
        builder.transforms = transforms;
        builder.system_identifier = "talus".into();
        builder.generating_software = format!("talus {}", env!("CARGO_PKG_VERSION"));
        if !dims.is_empty() {
            builder.vlrs.push(las::Vlr {
                user_id: "LASF_Spec".into(),
                record_id: 4,
                description: "Extra Bytes Record".into(),
                data: extra_bytes_descriptors(dims),
            });
        }
        let mut crs_vlrs: Vec<las::Vlr> = Vec::new();
        if has_wkt {
            if let Some(v) = crs.vlrs.iter().find(|v| v.record_id == 2112) {
                crs_vlrs.push(to_las_vlr(v));
            } else if let Some(w) = &crs.wkt {
                let mut data = w.as_bytes().to_vec();
                data.push(0);
                crs_vlrs.push(las::Vlr {
                    user_id: "LASF_Projection".into(),
                    record_id: 2112,
                    description: "OGC WKT".into(),
                    data,
                });
            }
            builder.has_wkt_crs = true;
        } else {
            crs_vlrs.extend(
                crs.vlrs
                    .iter()
                    .filter(|v| (34735..=34737).contains(&v.record_id))
                    .map(to_las_vlr),
            );
        }
        for v in crs_vlrs {
            if v.data.len() > usize::from(u16::MAX) {
                builder.evlrs.push(v);
            } else {
                builder.vlrs.push(v);
            }
        }
        let chunk = laz_chunk_size(expected);
        let header_error =
            |e: las::Error| Error::Internal(format!("LAS header for {}: {e}", path.display()));
        let laz_vlr = if compress {
            // The LASzip VLR `las` would write (its items for this point format), with our chunk
            // size.
            let mut probe = builder.clone().into_header().map_err(header_error)?;
            probe.add_laz_vlr().map_err(header_error)?;
            let items = probe.laz_vlr().map_err(header_error)?.items().clone();
            let vlr = laz::LazVlrBuilder::new(items)
                .with_fixed_chunk_size(chunk)
                .build();
            let mut data = Vec::new();
            vlr.write_to(&mut data)
                .map_err(|e| Error::Internal(format!("LASzip VLR: {e}")))?;
            builder.vlrs.push(las::Vlr {
                user_id: laz::LazVlr::USER_ID.to_owned(),
                record_id: laz::LazVlr::RECORD_ID,
                description: laz::LazVlr::DESCRIPTION.to_owned(),
                data,
            });
            Some(vlr)
        } else {
            None
        };
        let header = builder.into_header().map_err(header_error)?;
        let batch = las::PointDataBuilder::new().for_header(&header).build();
        let record_len = batch.record_len();

        let file = File::create(&tmp).map_err(|e| Error::output(path, e))?;
        let mut out = BufWriter::with_capacity(1 << 20, file);
        let sink = match laz_vlr {
            None => las::Writer::new(out, header).map(Sink::Las).map_err(to_io),
            Some(vlr) => header
                .write_to(&mut out)
                .map_err(to_io)
                .and_then(|()| laz::ParLasZipCompressor::new(out, vlr).map_err(to_io_laz))
                .map(|compressor| Sink::Laz(Box::new(LazSink::start(header, compressor)))),
        };
        let sink = match sink {
            Ok(s) => s,
            Err(e) => return Err(Error::output(path, e)),
        };
        Ok(ResultWriter {
            path: path.to_path_buf(),
            file: Some(atomic),
            sink: Some(sink),
            batch,
            buffered: 0,
            batch_len: CHUNKS_PER_BATCH * chunk as usize,
            dims: dims.to_vec(),
            base_len,
            record_len,
            extended,
            grid,
            count: 0,
        })
    }

    /// Append one point. `extra.len()` must equal the number of dims; each value is converted
    /// to its dim's type (integers rounded to nearest; NaN is allowed for floats only).
    pub fn write(&mut self, xyz: [f64; 3], extra: &[f64]) -> Result<()> {
        if extra.len() != self.dims.len() {
            return Err(Error::Internal(format!(
                "{} extra values for {} dimensions",
                extra.len(),
                self.dims.len()
            )));
        }
        let mut raw = [0i32; 3];
        for k in 0..3 {
            let Some(v) = self.grid.record(k, xyz[k]) else {
                return Err(Error::output(
                    &self.path,
                    std::io::Error::new(
                        std::io::ErrorKind::InvalidInput,
                        format!(
                            "coordinate {} cannot be stored at scale {} around offset {}",
                            xyz[k], self.grid.scale[k], self.grid.offset[k]
                        ),
                    ),
                ));
            };
            raw[k] = v;
        }
        let start = self.buffered * self.record_len;
        let bytes = &mut self.batch.resize_for(self.buffered + 1)[start..];
        bytes[..self.record_len].fill(0);
        for k in 0..3 {
            bytes[4 * k..4 * k + 4].copy_from_slice(&raw[k].to_le_bytes());
        }
        // Return number 1 of 1 (a return number of 0 is invalid in LAS 1.4).
        if self.extended {
            bytes[14] = 0x11;
        } else {
            bytes[14] = 0b0000_1001;
        }
        let mut at = self.base_len;
        for (d, &v) in self.dims.iter().zip(extra) {
            let out = &mut bytes[at..at + d.ty.size()];
            match d.ty {
                ExtraType::F32 => out.copy_from_slice(&(v as f32).to_le_bytes()),
                ExtraType::F64 => out.copy_from_slice(&v.to_le_bytes()),
                ExtraType::U8 => out.copy_from_slice(&[int_value(d, v, 0.0, 255.0)? as u8]),
                ExtraType::U32 => out.copy_from_slice(
                    &(int_value(d, v, 0.0, f64::from(u32::MAX))? as u32).to_le_bytes(),
                ),
                ExtraType::I32 => out.copy_from_slice(
                    &(int_value(d, v, f64::from(i32::MIN), f64::from(i32::MAX))? as i32)
                        .to_le_bytes(),
                ),
            }
            at += d.ty.size();
        }
        self.buffered += 1;
        if self.buffered == self.batch_len {
            self.flush_batch()?;
        }
        Ok(())
    }

    fn flush_batch(&mut self) -> Result<()> {
        if self.buffered == 0 {
            return Ok(());
        }
        let w = self
            .sink
            .as_mut()
            .ok_or_else(|| Error::Internal("write after finish".into()))?;
        // A write that failed half-way may have grown the batch by a record: trim it.
        self.batch.resize_for(self.buffered);
        w.write(&mut self.batch)
            .map_err(|e| Error::output(&self.path, to_io(e)))?;
        self.count += self.buffered as u64;
        self.buffered = 0;
        self.batch.resize_for(0);
        Ok(())
    }

    /// Write the remaining points, complete the header, and rename `<path>.tmp` onto `path`.
    /// Returns the number of points written.
    pub fn finish(mut self) -> Result<u64> {
        self.flush_batch()?;
        let w = self
            .sink
            .take()
            .ok_or_else(|| Error::Internal("finish called twice".into()))?;
        let file = w.close().map_err(|e| Error::output(&self.path, e))?;
        file.sync_all().map_err(|e| Error::output(&self.path, e))?;
        drop(file);
        if let Some(f) = self.file.take() {
            f.commit()?;
        }
        Ok(self.count)
    }
}

impl Drop for ResultWriter {
    /// Not finished: discard the temporary file.
    fn drop(&mut self) {
        if let Some(w) = self.sink.take() {
            // A `las::Writer` that fails to close is leaked by `close` (its Drop would retry and
            // panic); the file is about to be deleted anyway.
            let _ = w.close();
        }
        // The temporary itself goes with `file` (not committed), dropped after this.
    }
}

/// An integer value of dim `d`, rounded; NaN or out of `[lo, hi]` is a bug of the caller.
fn int_value(d: &ExtraDim, v: f64, lo: f64, hi: f64) -> Result<f64> {
    let r = v.round();
    if r >= lo && r <= hi {
        Ok(r)
    } else {
        Err(Error::Internal(format!(
            "value {v} does not fit the {:?} extra dimension '{}'",
            d.ty, d.name
        )))
    }
}

/// The Extra Bytes VLR payload: one 192-byte descriptor per dim (LAS 1.4 R15 Table 24):
/// `reserved[2], data_type, options, name[32], unused[4], no_data[24], deprecated[16], min[24],
/// deprecated[16], max[24], deprecated[16], scale[24], deprecated[16], offset[24],
/// deprecated[16], description[32]`. options = 0: no no_data/min/max/scale/offset.
pub(crate) fn extra_bytes_descriptors(dims: &[ExtraDim]) -> Vec<u8> {
    let mut data = vec![0u8; 192 * dims.len()];
    for (d, rec) in dims.iter().zip(data.chunks_exact_mut(192)) {
        rec[2] = d.ty.code();
        rec[4..4 + d.name.len()].copy_from_slice(d.name.as_bytes());
        rec[160..160 + d.description.len()].copy_from_slice(d.description.as_bytes());
    }
    data
}

fn to_las_vlr(v: &super::RawVlr) -> las::Vlr {
    las::Vlr {
        user_id: v.user_id.clone(),
        record_id: v.record_id,
        description: v.description.clone(),
        data: v.data.clone(),
    }
}

fn to_io_laz(e: laz::LasZipError) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

fn to_io(e: las::Error) -> std::io::Error {
    match e {
        las::Error::Io(e) => e,
        other => std::io::Error::other(other.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_takes_the_finest_input_scale_but_at_most_a_millimetre() {
        let (lo, hi) = (
            [499_000.0, 5_001_000.0, 10.0],
            [501_000.0, 5_003_000.0, 90.0],
        );
        let g = CoordinateGrid::for_extent(lo, hi, &[[1e-3, 1e-3, 1e-2], [1e-4, 1e-3, 1e-2]]);
        assert_eq!(g.scale, [1e-4, 1e-3, 1e-3]);
        assert_eq!(g.offset, [500_000.0, 5_002_000.0, 0.0]);
        // Text inputs only: millimetres.
        assert_eq!(CoordinateGrid::for_extent(lo, hi, &[]).scale, [1e-3; 3]);
        // 1e-6 over 10 km would overflow i32: coarsened until it fits.
        let g = CoordinateGrid::for_extent([0.0; 3], [10_000.0, 1.0, 1.0], &[[1e-6; 3]]);
        assert_eq!(g.scale, [1e-5, 1e-6, 1e-6]);
    }
}
