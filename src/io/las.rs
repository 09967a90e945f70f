//! LAS 1.2–1.4 and LAZ reader (any point format), streamed in chunks.
//!
//! Decoding uses the `las` crate (0.11): [`las::Reader::fill_points`] fills one reused
//! [`las::PointData`] per chunk and only the x/y/z columns are swept (no `Point` is ever
//! materialised), which is what keeps 120M-point epochs cheap. LAZ is decompressed with the
//! crate's parallel (rayon, chunk-table based) decompressor.
//!
//! `las::Reader` is not `Send` (it boxes its backend without a `Send` bound) while
//! [`PointReader`] must be, so the `las::Reader` lives on its own thread and hands decoded
//! chunks of `[f64; 3]` over a bounded channel (capacity 2: back-pressure bounds memory to a few
//! chunks). A side effect is that decoding overlaps with the consumer's work.
//!
//! Checks up front: a readable header, at least one point, scale factors a survey could have
//! (see `MAX_SCALE`), finite offsets, finite ordered bounds, and for uncompressed LAS that the
//! file is long enough for the number of points the header promises (LAS 1.4 R15 §2.4: point
//! data starts at `offset_to_point_data`, `point_data_record_length` bytes each). A truncated
//! LAZ is only found while decompressing and is reported as a read error naming the point index
//! reached.
//!
//! Every decoded point must lie within the header's bounds (widened by half a scale step and
//! rounding): a flipped bit in compressed point data decodes to garbage coordinates without any
//! error from the decompressor, and those would silently wreck the tiling and every result. The
//! check is six comparisons per point on the decoding thread, next to the decompression.
//!
//! CRS: the WKT (LASF_Projection 2112) and GeoTIFF (34735/34736/34737) (E)VLRs are copied
//! verbatim; the EPSG code is decoded from the GeoKeyDirectory (ProjectedCSTypeGeoKey 3072, else
//! GeographicTypeGeoKey 2048; GeoTIFF 1.0 §2.7 / OGC 19-008r4).

use std::fs::File;
use std::io::{BufReader, Seek, SeekFrom};
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Once;

use crossbeam_channel::{bounded, Receiver, Sender};

use std::sync::{Arc, Mutex};

use super::classes::{ClassCounts, Classes};
use super::{
    check_finite, open_file, Bounds, CloudFormat, CloudInfo, Crs, Point3, PointReader, RawVlr,
};
use crate::error::{Error, Result};

/// Points decoded per `fill_points` call from a LAZ file: several LAZ chunks (usually 50 000
/// points each), so the parallel decompressor has work for every core, yet only ~5 MB of
/// coordinates per chunk. Four chunks, not five: `laz` decompresses a call's last chunk beside
/// the others (`rayon::join`), and five chunks of equal work on two cores take three chunks'
/// time where four take two.
const LAZ_CHUNK: u64 = 200_000;

/// Points read per call from a LAS file: there is nothing to decompress in parallel, and buffers
/// of 1.5 MB are recycled between calls where fresh 6 MB ones were each mapped and faulted in
/// anew (a third of the reading thread's time on a 1M-point file).
const LAS_CHUNK: u64 = 65_536;

/// GeoTIFF key ids (GeoTIFF 1.0 §6.2): projected CRS and geographic CRS.
const PROJECTED_CS_TYPE_GEO_KEY: u16 = 3072;
const GEOGRAPHIC_TYPE_GEO_KEY: u16 = 2048;

/// A streaming LAS/LAZ reader; see the module doc.
pub(crate) struct LasReader {
    info: CloudInfo,
    /// The points it delivers, those left out by class included (the file's, or its range's).
    expected: u64,
    rx: Receiver<Result<Vec<Point3>>>,
    recycle: Sender<Vec<Point3>>,
    current: Vec<Point3>,
    pos: usize,
    delivered: u64,
    finished: bool,
    /// With a class filter: points read and left out per class so far (the decoding thread
    /// adds each chunk's before sending it).
    counts: Option<Arc<Mutex<Tally>>>,
}

/// Points read and left out per class.
type Tally = ([u64; 256], [u64; 256]);

impl LasReader {
    /// Open `path` (which starts with `LASF`), check its header and start the decoding thread,
    /// delivering only the points of the classes `classes` keeps (None or all classes: every
    /// point, the classification not even decoded).
    pub(crate) fn open_with(path: &Path, classes: Option<&Classes>) -> Result<Self> {
        Self::open_range(path, classes, None)
    }

    /// [`LasReader::open_with`], delivering only the points `start..start + count` of the file
    /// (`range`: `(start, count)`; before the class filter, which applies within it): a part of
    /// a large survey that a task of its own tiles (`units::tiling`).
    pub(crate) fn open_range(
        path: &Path,
        classes: Option<&Classes>,
        range: Option<(u64, u64)>,
    ) -> Result<Self> {
        let classes = classes.filter(|c| !c.keeps_all()).cloned();
        let file = open_file(path)?;
        let file_len = file
            .metadata()
            .map_err(|e| Error::input(path, format!("cannot read: {e}")))?
            .len();
        let mut read = BufReader::new(file);
        let raw = guarded(path, "LAS header", || {
            las::raw::Header::read_from(&mut read)
                .map_err(|e| Error::input(path, format!("unreadable LAS header: {e}")))
        })?;
        let promised = if raw.number_of_point_records > 0 {
            u64::from(raw.number_of_point_records)
        } else {
            raw.large_file.map_or(0, |l| l.number_of_point_records)
        };
        // Both counts enter the las crate's size arithmetic: refuse what overflows it.
        let largest = raw
            .large_file
            .map_or(0, |l| l.number_of_point_records)
            .max(u64::from(raw.number_of_point_records));
        let end_of_points = largest
            .checked_mul(u64::from(raw.point_data_record_length))
            .and_then(|n| n.checked_add(u64::from(raw.offset_to_point_data)));
        if end_of_points.is_none() {
            return Err(Error::input(
                path,
                format!(
                    "LAS header promises {largest} points of {} bytes: more than any file \
                     holds; corrupt header",
                    raw.point_data_record_length
                ),
            ));
        }
        // LAS 1.4 keeps two counts: the legacy 32-bit one must be 0 or equal the 64-bit one.
        // Which to believe is not ours to guess (a count cut to the legacy field reads 5 points
        // of 829 and gives a result): a file that disagrees with itself is refused.
        if let Some(l) = raw.large_file {
            let legacy = u64::from(raw.number_of_point_records);
            if legacy > 0 && l.number_of_point_records > 0 && legacy != l.number_of_point_records {
                return Err(Error::input(
                    path,
                    format!(
                        "LAS header disagrees with itself: its legacy point count is {legacy} \
                         but its 64-bit point count is {}; corrupt header",
                        l.number_of_point_records
                    ),
                ));
            }
        }
        let compressed = raw.point_data_record_format & 0xC0 != 0;
        if !compressed {
            // Uncompressed points are fixed-size records, so truncation shows in the file size.
            let needed = u64::from(raw.offset_to_point_data)
                + promised * u64::from(raw.point_data_record_length);
            if file_len < needed {
                let held = file_len.saturating_sub(u64::from(raw.offset_to_point_data))
                    / u64::from(raw.point_data_record_length.max(1));
                return Err(Error::input(
                    path,
                    format!(
                        "truncated LAS file: the header promises {promised} points but the file \
                         holds only {held} ({file_len} of {needed} bytes)"
                    ),
                ));
            }
        }
        if let Some(evlr) = raw.evlr.filter(|e| e.number_of_evlrs > 0) {
            // EVLRs follow the point data (LAS 1.4), so a cut file loses them first.
            if evlr.start_of_first_evlr >= file_len {
                return Err(Error::input(
                    path,
                    format!(
                        "truncated {} file: its extended VLRs start at byte {} but the file has \
                         only {file_len} bytes",
                        if compressed { "LAZ" } else { "LAS" },
                        evlr.start_of_first_evlr
                    ),
                ));
            }
        }
        read.rewind()
            .map_err(|e| Error::input(path, format!("cannot read: {e}")))?;
        let header = guarded(path, "LAS header", || {
            las::Header::new(&mut read)
                .map_err(|e| Error::input(path, format!("unreadable LAS header: {e}")))
        })?;
        let point_count = header.number_of_points();
        if point_count == 0 {
            return Err(Error::input(path, "contains no points"));
        }
        let (start, count) = range.unwrap_or((0, point_count));
        if start.checked_add(count).is_none_or(|end| end > point_count) {
            return Err(Error::input(
                path,
                format!(
                    "holds {point_count} points, not the {count} from point {start} the plan \
                     reads (the file changed since the run was planned)"
                ),
            ));
        }
        let t = header.transforms();
        check_transforms(path, [t.x, t.y, t.z])?;
        let is_laz = header.point_format().is_compressed
            || header
                .vlrs()
                .iter()
                .any(|v| v.user_id.eq_ignore_ascii_case("laszip encoded") && v.record_id == 22204);
        let kind = if is_laz { "LAZ" } else { "LAS" };
        let v = header.version();
        let hb = header.bounds();
        let bounds = Bounds {
            min: [hb.min.x, hb.min.y, hb.min.z],
            max: [hb.max.x, hb.max.y, hb.max.z],
        };
        let scale = [t.x.scale.abs(), t.y.scale.abs(), t.z.scale.abs()];
        let accepted = bounds_check(path, &bounds, [t.x, t.y, t.z])?;
        let info = CloudInfo {
            path: path.to_path_buf(),
            format: if is_laz {
                CloudFormat::Laz
            } else {
                CloudFormat::Las
            },
            format_detail: format!(
                "{kind} {}.{} point format {}",
                v.major,
                v.minor,
                raw.point_data_record_format & 0x3F
            ),
            point_count,
            bounds,
            crs: crs_from_header(&header),
            scale: Some(scale),
            transform: Some([t.x, t.y, t.z].map(|t| [t.scale, t.offset])),
        };
        drop(read);

        let (tx, rx) = bounded(2);
        let (recycle, recycle_rx) = bounded(4);
        let (ready_tx, ready_rx) = bounded(1);
        let counts = classes
            .as_ref()
            .map(|_| Arc::new(Mutex::new(([0u64; 256], [0u64; 256]))));
        let source = Source {
            path: path.to_path_buf(),
            kind,
            start,
            total: start + count,
            accepted,
            filter: classes.zip(counts.clone()),
            // Point formats 6 to 10 are compressed in layers: only the coordinates' are decoded.
            layered: (header.point_format().is_compressed && header.point_format().is_extended)
                .then(|| (header.clone(), u64::from(raw.offset_to_point_data))),
        };
        std::thread::Builder::new()
            .name("talus-las-reader".into())
            .spawn(move || decode(source, ready_tx, tx, recycle_rx))
            .map_err(|e| Error::Internal(format!("cannot start the LAS reader thread: {e}")))?;
        match ready_rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(e),
            Err(_) => return Err(Error::Internal("the LAS reader thread died".into())),
        }
        Ok(LasReader {
            info,
            expected: count,
            rx,
            recycle,
            current: Vec::new(),
            pos: 0,
            delivered: 0,
            finished: false,
            counts,
        })
    }
}

/// How many [`guarded`] calls are running: while any is, panics raised inside the las and laz
/// crates are not printed (the guard reports them as one input error).
static GUARDED: AtomicUsize = AtomicUsize::new(0);

/// Run `f`, a call into the las/laz crates on an untrusted file, turning a panic inside it (a
/// debug assertion of the decompressor, an overflow on absurd header values) into an input
/// error naming the file. The panic's own message is kept off stderr by a hook installed once.
fn guarded<T>(path: &Path, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let in_decoder = info.location().is_some_and(|l| {
                let file = l.file().replace('\\', "/");
                file.contains("/laz-") || file.contains("/las-")
            });
            if !(in_decoder && GUARDED.load(Ordering::SeqCst) > 0) {
                default(info);
            }
        }));
    });
    GUARDED.fetch_add(1, Ordering::SeqCst);
    let result = std::panic::catch_unwind(AssertUnwindSafe(f));
    GUARDED.fetch_sub(1, Ordering::SeqCst);
    result.unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        let why = why.lines().map(str::trim).collect::<Vec<_>>().join("; ");
        Err(Error::input(
            path,
            format!("corrupt {what}: the decoder gave up ({why})"),
        ))
    })
}

/// The coarsest and the finest coordinate quantum accepted (the magnitude of a LAS scale factor).
/// Real files use 0.01 to 1e-9 (degrees); anything outside these is a corrupt header, and would
/// turn the 32-bit record values into coordinates beyond any survey (or into subnormal numbers).
/// A negative scale is accepted: LAS 1.4 R15 §2.4 only says the record value is multiplied by
/// it, and the bounds remain the coordinates' minimum and maximum.
const MAX_SCALE: f64 = 1e6;
const MIN_SCALE: f64 = 1e-12;

/// Refuse scale factors and offsets no survey has, naming the header field.
fn check_transforms(path: &Path, t: [las::Transform; 3]) -> Result<()> {
    for (axis, t) in ["x", "y", "z"].into_iter().zip(t) {
        let scale = t.scale.abs();
        if !(MIN_SCALE..=MAX_SCALE).contains(&scale) {
            return Err(Error::input(
                path,
                format!(
                    "LAS header {axis} scale factor is {:?}: not a coordinate quantum (it must \
                     lie between {MIN_SCALE:e} and {MAX_SCALE:e}); corrupt header",
                    t.scale
                ),
            ));
        }
        if !t.offset.is_finite() {
            return Err(Error::input(
                path,
                format!("LAS header {axis} offset is {:?}: corrupt header", t.offset),
            ));
        }
    }
    Ok(())
}

/// The header's bounds and the box every decoded point must lie in: the bounds widened by half
/// a scale step (a writer may take them before quantising) plus a few ulps of rounding.
#[derive(Debug, Clone, Copy)]
struct BoundsCheck {
    header: Bounds,
    lo: Point3,
    hi: Point3,
}

/// Also refused: bounds that are not finite and ordered, or that reach beyond every coordinate
/// the scale and offset can express (32-bit records): no point can lie there, so the header is
/// corrupt, and tiling a grid over such bounds would not end.
fn bounds_check(path: &Path, header: &Bounds, t: [las::Transform; 3]) -> Result<BoundsCheck> {
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for (k, t) in t.iter().enumerate() {
        let axis = ["x", "y", "z"][k];
        let (min, max) = (header.min[k], header.max[k]);
        if !(min.is_finite() && max.is_finite() && min <= max) {
            return Err(Error::input(
                path,
                format!("LAS header bounds of {axis} are {min:?} .. {max:?}: corrupt header"),
            ));
        }
        let scale = t.scale.abs();
        let tol = 0.5 * scale + 4.0 * f64::EPSILON * min.abs().max(max.abs());
        lo[k] = min - tol;
        hi[k] = max + tol;
        let reach = scale * 2f64.powi(31);
        let (first, last) = (t.offset - reach, t.offset + reach);
        if lo[k] < first - tol || hi[k] > last + tol {
            return Err(Error::input(
                path,
                format!(
                    "LAS header bounds of {axis} ({min:?} .. {max:?}) reach beyond what its \
                     scale and offset can express ({first:?} .. {last:?}): corrupt header"
                ),
            ));
        }
    }
    Ok(BoundsCheck {
        header: *header,
        lo,
        hi,
    })
}

/// Whether `p` lies outside the accepted box (or has a NaN): six comparisons, which the
/// compiler keeps branch-free; negligible beside decoding (see the module doc).
#[inline]
fn outside(b: &BoundsCheck, p: &Point3) -> bool {
    !((p[0] >= b.lo[0])
        & (p[0] <= b.hi[0])
        & (p[1] >= b.lo[1])
        & (p[1] <= b.hi[1])
        & (p[2] >= b.lo[2])
        & (p[2] <= b.hi[2]))
}

/// The error for point `index` at `p`, which [`outside`] refused: the first bound it violates.
fn out_of_bounds(path: &Path, index: u64, p: &Point3, b: &BoundsCheck) -> Error {
    let k = (0..3)
        .find(|&k| !(p[k] >= b.lo[k] && p[k] <= b.hi[k]))
        .unwrap_or(0);
    let axis = ["x", "y", "z"][k];
    let (side, bound) = if p[k] < b.lo[k] {
        ("below the header's minimum", b.header.min[k])
    } else {
        ("above the header's maximum", b.header.max[k])
    };
    Error::input(
        path,
        format!(
            "point {index} has {axis} = {:?}, {side} {axis} {bound:?} (corrupt point data or \
             header bounds)",
            p[k]
        ),
    )
}

/// A LAZ file's points decompress to its LASzip VLR's items, whose sizes must add up to the
/// header's point record length: the las crate sizes its buffers by the one and the decompressor
/// fills them by the other, so a record length of 65 535 in a 96 KB file would decode gigabytes
/// of garbage before failing.
fn laz_items_match(path: &Path, header: &las::Header) -> Result<()> {
    if !header.point_format().is_compressed {
        return Ok(());
    }
    let Ok(vlr) = header.laz_vlr() else {
        return Ok(()); // the decompressor reports a missing LASzip VLR itself
    };
    let (items, record) = (vlr.items_size(), u64::from(header.point_format().len()));
    if items != record {
        return Err(Error::input(
            path,
            format!(
                "corrupt LAZ header: its point record length is {record} bytes but its LASzip \
                 VLR's items make {items}"
            ),
        ));
    }
    Ok(())
}

/// What the decoding thread reads.
struct Source {
    path: PathBuf,
    kind: &'static str,
    /// The first point it reads, and the point it stops before.
    start: u64,
    total: u64,
    accepted: BoundsCheck,
    /// A LAZ file of a layered point format: its header and where its points start.
    layered: Option<(las::Header, u64)>,
    /// The classes to keep, and where to count what is read and left out.
    filter: Option<(Classes, Arc<Mutex<Tally>>)>,
}

/// The decoding thread: open the file, report readiness, then stream chunks until the end, an
/// error, or the consumer hanging up.
fn decode(
    source: Source,
    ready: Sender<Result<()>>,
    tx: Sender<Result<Vec<Point3>>>,
    recycle: Receiver<Vec<Point3>>,
) {
    let Source {
        path,
        kind,
        start,
        total,
        accepted,
        layered,
        filter,
    } = source;
    let classified = filter.is_some();
    let opened = match &layered {
        Some((header, start)) => coordinates_only(&path, header, *start, classified)
            .map(|l| Decoder::Layers(Box::new(l))),
        None => super::open_file(&path)
            .and_then(|f| {
                guarded(&path, &format!("{kind} file"), || {
                    las::Reader::new(BufReader::with_capacity(1 << 20, f)).map_err(|e| {
                        Error::input(&path, format!("truncated or corrupt {kind} file: {e}"))
                    })
                })
            })
            .and_then(|r| {
                laz_items_match(&path, r.header())?;
                Ok(r)
            })
            .map(|r| {
                let pd = las::PointDataBuilder::new().for_header(r.header()).build();
                Decoder::Las(Box::new((r, pd)))
            }),
    };
    let opened = opened.and_then(|mut d| {
        if start > 0 {
            guarded(&path, &format!("{kind} file"), || {
                d.seek(start).map_err(|e| {
                    Error::input(
                        &path,
                        format!(
                            "truncated or corrupt {kind} file: cannot reach point {start}: {e}"
                        ),
                    )
                })
            })?;
        }
        Ok(d)
    });
    let mut decoder = match opened {
        Ok(r) => {
            if ready.send(Ok(())).is_err() {
                return;
            }
            r
        }
        Err(e) => {
            let _ = ready.send(Err(e));
            return;
        }
    };
    let mut index = start;
    let mut classes: Vec<u8> = Vec::new();
    loop {
        let mut chunk = recycle.try_recv().unwrap_or_default();
        chunk.clear();
        let what = format!("{kind} data after {index} of {total} points");
        let wanted = classified.then_some(&mut classes);
        let filled = guarded(&path, &what, || {
            decoder
                .fill(&mut chunk, wanted, total - index)
                .map_err(|e| {
                    Error::input(
                        &path,
                        format!(
                        "truncated or corrupt {kind} data: read failed after {index} of {total} \
                         points: {e}"
                    ),
                    )
                })
        });
        let n = match filled {
            Ok(n) => n,
            Err(e) => {
                let _ = tx.send(Err(e));
                return;
            }
        };
        if n == 0 {
            return;
        }
        // One pass of comparisons per point (NaN fails them too); the cost is in the noise of
        // decoding, see `outside`.
        if let Some(i) = chunk.iter().position(|p| outside(&accepted, p)) {
            let p = &chunk[i];
            let e = check_finite(&path, index + i as u64, p)
                .err()
                .unwrap_or_else(|| out_of_bounds(&path, index + i as u64, p, &accepted));
            let _ = tx.send(Err(e));
            return;
        }
        index += n;
        if let Some((keep, tally)) = &filter {
            // Count every point's class, keep those of the kept classes (in their order).
            let (mut read, mut out) = ([0u64; 256], [0u64; 256]);
            let mut c = classes.iter();
            chunk.retain(|_| {
                let k = *c.next().unwrap_or(&0);
                read[k as usize] += 1;
                let kept = keep.keeps(k);
                if !kept {
                    out[k as usize] += 1;
                }
                kept
            });
            if let Ok(mut t) = tally.lock() {
                for k in 0..256 {
                    t.0[k] += read[k];
                    t.1[k] += out[k];
                }
            }
        }
        if tx.send(Ok(chunk)).is_err() {
            return; // the consumer dropped the reader
        }
    }
}

/// How the decoding thread gets points: through `las` (every point format, LAS and LAZ), or
/// straight from the LAZ decompressor with only the coordinates' layers decoded.
enum Decoder {
    Las(Box<(las::Reader, las::PointData)>),
    Layers(Box<Layers>),
}

/// A LAZ file of a layered point format (6 to 10) read for its coordinates alone: the
/// decompressor skips the other layers (intensity, classification, flags, scan angle, user
/// data, point source, GPS time, colours, extra bytes) instead of decoding them, which was
/// most of reading such a file (talus uses nothing but x, y, z).
struct Layers {
    decompressor: laz::ParLasZipDecompressor<BufReader<File>>,
    /// Whether its chunks have one size (see [`Decoder::seek`]).
    fixed_chunks: bool,
    transforms: las::Vector<las::Transform>,
    record: usize,
    bytes: Vec<u8>,
}

impl Decoder {
    /// Go to point `index` of the file: through the LAZ chunk table where the chunks have one
    /// size (the decompressors find a point's chunk by dividing by it), else by decoding the
    /// points before it (a LAZ file of variable chunks, which few writers make).
    fn seek(&mut self, index: u64) -> std::result::Result<(), String> {
        let fixed = match self {
            Decoder::Las(las) => {
                let h = las.0.header();
                !h.point_format().is_compressed
                    || h.laz_vlr().is_ok_and(|v| v.chunk_size() != u32::MAX)
            }
            Decoder::Layers(l) => l.fixed_chunks,
        };
        if fixed {
            return match self {
                Decoder::Las(las) => las.0.seek(index).map_err(|e| e.to_string()),
                Decoder::Layers(l) => l.decompressor.seek(index).map_err(|e| e.to_string()),
            };
        }
        let (mut at, mut skipped) = (0u64, Vec::new());
        while at < index {
            let n = self.fill(&mut skipped, None, index - at)?;
            if n == 0 {
                return Err(format!("the file ends after {at} points"));
            }
            skipped.clear();
            at += n;
        }
        Ok(())
    }

    /// Decode up to one chunk of points (at most `left`) into `out`; how many (0: the end).
    /// With `classes`: each point's class too (cleared first).
    fn fill(
        &mut self,
        out: &mut Vec<Point3>,
        classes: Option<&mut Vec<u8>>,
        left: u64,
    ) -> std::result::Result<u64, String> {
        match self {
            Decoder::Las(las) => {
                let (reader, pd) = &mut **las;
                let chunk = if reader.header().point_format().is_compressed {
                    LAZ_CHUNK
                } else {
                    LAS_CHUNK
                };
                let n = reader
                    .fill_points(chunk.min(left), pd)
                    .map_err(|e| e.to_string())?;
                out.reserve(pd.len());
                out.extend(pd.x().zip(pd.y()).zip(pd.z()).map(|((x, y), z)| [x, y, z]));
                if let Some(c) = classes {
                    c.clear();
                    c.extend(pd.classification());
                }
                Ok(n)
            }
            Decoder::Layers(l) => {
                let n = left.min(LAZ_CHUNK) as usize;
                if n == 0 {
                    return Ok(0);
                }
                l.bytes.resize(n * l.record, 0);
                l.decompressor
                    .decompress_many(&mut l.bytes)
                    .map_err(|e| e.to_string())?;
                let t = &l.transforms;
                let at =
                    |b: &[u8], k: usize| i32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
                out.reserve(n);
                // Every point format starts with X, Y, Z as i32 (LAS 1.4 R15 §2.6); the
                // transforms are `las`'s, so the values are the ones it would give.
                out.extend(l.bytes.chunks_exact(l.record).map(|b| {
                    [
                        t.x.direct(at(b, 0)),
                        t.y.direct(at(b, 4)),
                        t.z.direct(at(b, 8)),
                    ]
                }));
                if let Some(c) = classes {
                    // The classification byte of formats 6 to 10 (LAS 1.4 R15 Table 7).
                    c.clear();
                    c.extend(l.bytes.chunks_exact(l.record).map(|b| b[16]));
                }
                Ok(n as u64)
            }
        }
    }
}

/// Open the points of the layered LAZ file `path` (its `header`, points from byte `start`) for
/// their coordinates alone (and their classification when `classified`).
fn coordinates_only(
    path: &Path,
    header: &las::Header,
    start: u64,
    classified: bool,
) -> Result<Layers> {
    laz_items_match(path, header)?;
    let corrupt = |e: String| Error::input(path, format!("truncated or corrupt LAZ file: {e}"));
    let mut f = BufReader::with_capacity(1 << 20, super::open_file(path)?);
    f.seek(SeekFrom::Start(start))
        .map_err(|e| corrupt(e.to_string()))?;
    let vlr = header.laz_vlr().map_err(|e| corrupt(e.to_string()))?;
    let record = vlr.items_size() as usize;
    let fixed_chunks = vlr.chunk_size() != u32::MAX;
    let mut selection = laz::DecompressionSelection::base().decompress_z();
    if classified {
        selection = selection.decompress_classification();
    }
    let decompressor = guarded(path, "LAZ file", || {
        laz::ParLasZipDecompressor::selective(f, vlr, selection).map_err(|e| corrupt(e.to_string()))
    })?;
    Ok(Layers {
        fixed_chunks,
        decompressor,
        transforms: *header.transforms(),
        record,
        bytes: Vec::new(),
    })
}

impl PointReader for LasReader {
    fn info(&self) -> &CloudInfo {
        &self.info
    }

    fn class_counts(&self) -> Option<ClassCounts> {
        let c = self.counts.as_ref()?;
        let t = c.lock().ok()?;
        Some(ClassCounts::from_tables(&t.0, &t.1))
    }

    fn left_out(&self) -> u64 {
        self.counts.as_ref().map_or(0, |c| {
            c.lock()
                .map(|t| t.1.iter().sum::<u64>())
                .unwrap_or_default()
        })
    }

    fn fill(&mut self, buf: &mut Vec<Point3>, max: usize) -> Result<usize> {
        buf.clear();
        while buf.len() < max {
            if self.pos == self.current.len() {
                if self.finished {
                    break;
                }
                let used = std::mem::take(&mut self.current);
                if used.capacity() > 0 {
                    let _ = self.recycle.try_send(used);
                }
                self.pos = 0;
                match self.rx.recv() {
                    Ok(Ok(chunk)) => self.current = chunk,
                    Ok(Err(e)) => {
                        self.finished = true;
                        return Err(e);
                    }
                    Err(_) => {
                        self.finished = true;
                        if self.delivered + self.left_out() != self.expected {
                            return Err(Error::input(
                                &self.info.path,
                                format!(
                                    "truncated: read {} of the {} points the header promises",
                                    self.delivered + self.left_out(),
                                    self.expected
                                ),
                            ));
                        }
                    }
                }
                continue;
            }
            let take = (max - buf.len()).min(self.current.len() - self.pos);
            buf.extend_from_slice(&self.current[self.pos..self.pos + take]);
            self.pos += take;
            self.delivered += take as u64;
        }
        Ok(buf.len())
    }
}

/// The CRS records of a LAS header: (E)VLRs copied verbatim, WKT text and EPSG code decoded.
pub(crate) fn crs_from_header(header: &las::Header) -> Crs {
    let mut crs = Crs::default();
    for v in header.all_vlrs() {
        let is_projection = v.user_id.eq_ignore_ascii_case("LASF_Projection");
        if !is_projection || !matches!(v.record_id, 2112 | 34735..=34737) {
            continue;
        }
        crs.vlrs.push(RawVlr {
            user_id: v.user_id.clone(),
            record_id: v.record_id,
            description: v.description.clone(),
            data: v.data.clone(),
        });
        match v.record_id {
            2112 if crs.wkt.is_none() => {
                // The WKT record is a null-terminated string (LAS 1.4 R15 §2.5.5).
                let end = v.data.iter().position(|&b| b == 0).unwrap_or(v.data.len());
                let text = String::from_utf8_lossy(&v.data[..end]).trim().to_string();
                if !text.is_empty() {
                    crs.wkt = Some(text);
                }
            }
            34735 if crs.epsg.is_none() => crs.epsg = epsg_from_geokeys(&v.data),
            _ => {}
        }
    }
    crs
}

/// The EPSG code in a GeoKeyDirectory record (LASF_Projection 34735): ProjectedCSTypeGeoKey
/// (3072), else GeographicTypeGeoKey (2048), when stored inline and in the EPSG range
/// 1024..=32766 (32767 = user-defined, 0 = undefined).
pub(crate) fn epsg_from_geokeys(data: &[u8]) -> Option<u32> {
    let words: Vec<u16> = data
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    // Header: KeyDirectoryVersion, KeyRevision, MinorRevision, NumberOfKeys; then 4 u16 per key:
    // KeyID, TIFFTagLocation (0 = value inline), Count, Value_Offset.
    let n_keys = usize::from(*words.get(3)?);
    let keys: Vec<&[u16]> = words[4..].chunks_exact(4).take(n_keys).collect();
    let find = |id: u16| {
        keys.iter()
            .find(|k| k[0] == id && k[1] == 0)
            .map(|k| k[3])
            .filter(|v| (1024..=32766).contains(v))
            .map(u32::from)
    };
    find(PROJECTED_CS_TYPE_GEO_KEY).or_else(|| find(GEOGRAPHIC_TYPE_GEO_KEY))
}
