//! Point-cloud input: LAS/LAZ, text (CSV or whitespace) and PLY, streamed in chunks.
//!
//! Every reader yields global coordinates as `[f64; 3]` (UTM-sized values keep millimetre
//! precision in f64), checks each point for NaN/infinity, and reports problems as
//! [`Error::Input`] naming the file.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

pub mod classes;
pub(crate) mod las;
pub mod las_out;
pub(crate) mod laz_join;
pub mod mesh_ply;
pub(crate) mod parquet_out;
pub(crate) mod ply;
pub mod replay;
pub mod result_table;
pub(crate) mod text;

pub use crate::geom::{Bounds, Point3};

/// The file format of a point cloud.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CloudFormat {
    Las,
    Laz,
    Text,
    Ply,
}

/// A raw (E)VLR carried from an input file to the outputs (CRS records).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawVlr {
    pub user_id: String,
    pub record_id: u16,
    pub description: String,
    pub data: Vec<u8>,
}

/// Coordinate reference system of an input, carried verbatim to the outputs.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Crs {
    /// OGC WKT, when the file holds it (LAS 1.4 WKT VLR) or it was derived.
    pub wkt: Option<String>,
    /// EPSG code of the projected (or geographic) CRS when known (GeoTIFF keys 3072/2048).
    pub epsg: Option<u32>,
    /// The CRS (E)VLRs exactly as read (WKT 2112, GeoTIFF 34735/34736/34737), to copy out.
    pub vlrs: Vec<RawVlr>,
}

impl Crs {
    /// The EPSG code of the CRS's horizontal part: the GeoTIFF keys' (3072/2048, horizontal by
    /// definition), else the WKT's. A compound CRS (`COMPD_CS`, `COMPOUNDCRS`: a projected CRS
    /// with a vertical one, e.g. NAD83 / Oregon LCC + NAVD88 height) is its horizontal part's
    /// code, the one polygons in the same map are given in: the first projected or geographic
    /// element's own authority (WKT 1: the last `AUTHORITY["EPSG","n"]` inside it; WKT 2: the
    /// last `ID["EPSG",n]`).
    pub fn epsg_code(&self) -> Option<u32> {
        if self.epsg.is_some() {
            return self.epsg;
        }
        let w = self.wkt.as_deref()?;
        horizontal_wkt(w).and_then(last_epsg)
    }

    /// A short human description: `EPSG:32755`, the WKT's name, or `unknown`.
    pub fn describe(&self) -> String {
        if let Some(e) = self.epsg {
            return format!("EPSG:{e}");
        }
        if let Some(w) = &self.wkt {
            // PROJCS["NAD83 / Oregon ..."  -> the quoted name
            if let Some(start) = w.find('"') {
                if let Some(len) = w[start + 1..].find('"') {
                    return w[start + 1..start + 1 + len].to_string();
                }
            }
            return "WKT".to_string();
        }
        "unknown".to_string()
    }
}

/// The horizontal CRS element of WKT `w`: the first projected or geographic element
/// (`PROJCS`, `GEOGCS`, `PROJCRS`, `GEOGCRS`, `GEODCRS`) with its brackets, or the whole WKT when
/// it names none.
fn horizontal_wkt(w: &str) -> Option<&str> {
    let start = ["PROJCS[", "PROJCRS[", "GEOGCS[", "GEOGCRS[", "GEODCRS["]
        .iter()
        .filter_map(|k| w.find(k))
        .min();
    let Some(start) = start else {
        return Some(w);
    };
    let mut depth = 0usize;
    let mut quoted = false;
    for (i, c) in w[start..].char_indices() {
        match c {
            '"' => quoted = !quoted,
            '[' | '(' if !quoted => depth += 1,
            ']' | ')' if !quoted => {
                depth = depth.checked_sub(1)?;
                if depth == 0 {
                    return Some(&w[start..=start + i]);
                }
            }
            _ => {}
        }
    }
    Some(&w[start..])
}

/// The last EPSG authority code in WKT `w` (WKT 1 `AUTHORITY["EPSG","n"]`, WKT 2 `ID["EPSG",n]`):
/// an element's own authority closes it, after those of the elements inside it.
fn last_epsg(w: &str) -> Option<u32> {
    let at = w.rfind("AUTHORITY[\"EPSG\"").max(w.rfind("ID[\"EPSG\""))?;
    let rest = &w[at..];
    let digits: String = rest[rest.find(',')? + 1..]
        .chars()
        .skip_while(|c| !c.is_ascii_digit())
        .take_while(|c| c.is_ascii_digit())
        .collect();
    digits.parse().ok()
}

/// What is known about a cloud from its header (or a first scan for formats without one).
#[derive(Debug, Clone)]
pub struct CloudInfo {
    pub path: PathBuf,
    pub format: CloudFormat,
    /// A short description of the format, e.g. `LAS 1.4 point format 7`, `PLY binary_little_endian`.
    pub format_detail: String,
    pub point_count: u64,
    pub bounds: Bounds,
    pub crs: Crs,
    /// The coordinate quantum per axis of a LAS/LAZ file (its scale factors); None for text and
    /// PLY, whose coordinates are decimal or floating point.
    pub scale: Option<[f64; 3]>,
    /// A LAS/LAZ file's coordinate transform per axis, `[scale, offset]` as its header gives
    /// them (sign included): its points are `scale · record + offset`. None for text and PLY.
    pub transform: Option<[[f64; 2]; 3]>,
}

/// A streaming reader of points. Call [`PointReader::fill`] until it returns 0.
pub trait PointReader: Send {
    /// Header information. For text files the count and bounds come from a first pass.
    fn info(&self) -> &CloudInfo;
    /// Clear `buf` and fill it with up to `max` points; returns how many were read (0 = end).
    /// A NaN or infinite coordinate, a truncated or corrupt file is an `Error::Input`.
    fn fill(&mut self, buf: &mut Vec<Point3>, max: usize) -> Result<usize>;
    /// Opened with a class filter ([`open_with`]) on a format that has classes: the points read
    /// so far per class, and those left out. None otherwise (text, PLY, no filter).
    fn class_counts(&self) -> Option<classes::ClassCounts> {
        None
    }
    /// Points the class filter left out so far (what [`PointReader::class_counts`] sums, without
    /// building it: a reader's consumer may ask after every chunk).
    fn left_out(&self) -> u64 {
        0
    }
}

/// [`PointReader::fill`] for readers that decode one point at a time: clear `buf`, then push
/// points from `next` until `max` or its end.
fn fill_from(
    buf: &mut Vec<Point3>,
    max: usize,
    mut next: impl FnMut() -> Result<Option<Point3>>,
) -> Result<usize> {
    buf.clear();
    while buf.len() < max {
        match next()? {
            Some(p) => buf.push(p),
            None => break,
        }
    }
    Ok(buf.len())
}

/// Open any supported point cloud, choosing the reader by content (LAS signature `LASF`, PLY
/// magic `ply`, which may follow a byte order mark like any text) and falling back to text. A
/// missing file, a file that is not a point cloud and a cloud with zero points are errors naming
/// the file.
pub fn open(path: &Path) -> Result<Box<dyn PointReader>> {
    open_with(path, None)
}

/// [`open`], delivering from a LAS/LAZ file only the points of the classes `classes` keeps
/// (text and PLY have no classes: every point). A file this process already decoded whole with
/// the same filter and kept ([`replay`]) is read from that copy.
pub fn open_with(path: &Path, classes: Option<&classes::Classes>) -> Result<Box<dyn PointReader>> {
    if let Some(r) = replay::reader(path, classes)? {
        return Ok(Box::new(r));
    }
    let mut prefix = [0u8; 7];
    let n = read_prefix(path, &mut prefix)?;
    let prefix = &prefix[..n];
    let text = prefix.strip_prefix(BOM.as_bytes()).unwrap_or(prefix);
    if prefix.starts_with(b"LASF") {
        Ok(Box::new(las::LasReader::open_with(path, classes)?))
    } else if text.starts_with(b"ply") && matches!(text.get(3), Some(b'\n' | b'\r')) {
        Ok(Box::new(ply::PlyReader::open(path)?))
    } else {
        Ok(Box::new(text::TextReader::open(path)?))
    }
}

/// [`open_with`] for the points `start..start + count` of the LAS/LAZ file `path` (before the
/// class filter, which applies within them): a part of a survey tiled by several units.
pub fn open_range(
    path: &Path,
    classes: Option<&classes::Classes>,
    start: u64,
    count: u64,
) -> Result<Box<dyn PointReader>> {
    let mut prefix = [0u8; 4];
    let n = read_prefix(path, &mut prefix)?;
    if &prefix[..n] != b"LASF" {
        return Err(Error::input(
            path,
            "is no longer a LAS/LAZ file (the plan read it as one): it changed since the run \
             was planned",
        ));
    }
    Ok(Box::new(las::LasReader::open_range(
        path,
        classes,
        Some((start, count)),
    )?))
}

/// The UTF-8 byte order mark, which text written on Windows may start with (skipped by the text
/// and PLY readers; Unicode 15 §23.8).
const BOM: &str = "\u{feff}";

/// Drop a leading byte order mark from the first line of a text file or PLY header.
fn strip_bom(line: &mut String) {
    if line.starts_with(BOM) {
        line.drain(..BOM.len());
    }
}

/// Read up to `buf.len()` leading bytes of `path`; a missing or unreadable file is an input error.
fn read_prefix(path: &Path, buf: &mut [u8]) -> Result<usize> {
    use std::io::Read;
    let mut f = open_file(path)?;
    let mut n = 0;
    while n < buf.len() {
        match f.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::input(path, format!("cannot read: {e}"))),
        }
    }
    Ok(n)
}

/// Open a file for reading, turning "not found" and friends into one clear input error. Only a
/// regular file is taken: it is opened without blocking (a FIFO with no writer would hang
/// `open` for ever), and a FIFO, pipe (`<(…)`), socket or device is refused at once — talus
/// reads an input several times (header, spacing, tiling), a pipe gives its bytes once.
pub(crate) fn open_file(path: &Path) -> Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    use std::os::unix::io::AsRawFd;
    let opened = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path);
    match opened {
        Ok(f) => {
            let m = f
                .metadata()
                .map_err(|e| Error::input(path, format!("cannot read: {e}")))?;
            if m.is_dir() {
                return Err(Error::input(path, "is a directory, not a point cloud"));
            }
            if !m.is_file() {
                return Err(not_regular(path));
            }
            // Back to blocking reads (no effect on a regular file on Linux; kept plain for any
            // file system that would honour it).
            // SAFETY: fcntl on a descriptor this function owns, with flags read from it.
            unsafe {
                let fd = f.as_raw_fd();
                let flags = libc::fcntl(fd, libc::F_GETFL);
                if flags >= 0 {
                    libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK);
                }
            }
            Ok(f)
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            Err(Error::input(path, "file not found"))
        }
        Err(e) => Err(Error::input(path, format!("cannot open: {e}"))),
    }
}

/// The error for an input that is not a regular file (see `open_file`).
pub(crate) fn not_regular(path: &Path) -> Error {
    Error::input(
        path,
        "not a regular file (a FIFO, pipe, socket or device): talus reads an input more than \
         once; write it to a file first",
    )
}

/// The check every reader applies to every point: a NaN or infinite coordinate is an input
/// error naming the (0-based) point index, because it would poison bounds, tiling and kd-trees.
pub(crate) fn check_finite(path: &Path, index: u64, p: &Point3) -> Result<()> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::input(
            path,
            format!(
                "point {index} has a NaN or infinite coordinate ({}, {}, {})",
                p[0], p[1], p[2]
            ),
        ))
    }
}

/// Read a whole (small) cloud into memory. For tests, core-point files and the viewer; large
/// clouds go through the tiling pass instead.
pub fn read_all(path: &Path) -> Result<(CloudInfo, Vec<Point3>)> {
    let mut r = open(path)?;
    let info = r.info().clone();
    let mut all = Vec::with_capacity(info.point_count.min(1 << 26) as usize);
    let mut buf = Vec::new();
    while r.fill(&mut buf, 1 << 16)? > 0 {
        all.extend_from_slice(&buf);
    }
    Ok((info, all))
}

#[cfg(test)]
mod tests {
    use super::Crs;

    fn wkt(w: &str) -> Crs {
        Crs {
            wkt: Some(w.into()),
            ..Crs::default()
        }
    }

    #[test]
    fn a_compound_crs_is_its_horizontal_part() {
        // The autzen surveys' WKT: NAD83 / Oregon LCC (m) with NAVD88 height in US feet.
        let autzen = r#"COMPD_CS["NAD83 / Oregon LCC (m) + NAVD88 height (ftUS)",PROJCS["NAD83 / Oregon LCC (m)",GEOGCS["NAD83",DATUM["North_American_Datum_1983",SPHEROID["GRS 1980",6378137,298.257222101],AUTHORITY["EPSG","6269"]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AUTHORITY["EPSG","4269"]],PROJECTION["Lambert_Conformal_Conic_2SP"],UNIT["metre",1],AUTHORITY["EPSG","2991"]],VERT_CS["NAVD88 height (ftUS)",VERT_DATUM["North American Vertical Datum 1988",2005],UNIT["US survey foot",0.304800609601219],AUTHORITY["EPSG","6360"]]]"#;
        assert_eq!(wkt(autzen).epsg_code(), Some(2991));
        let utm = r#"PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84",AUTHORITY["EPSG","4326"]],UNIT["metre",1,AUTHORITY["EPSG","9001"]],AUTHORITY["EPSG","32633"]]"#;
        assert_eq!(wkt(utm).epsg_code(), Some(32633));
        let wkt2 = r#"COMPOUNDCRS["ETRS89 / UTM 32N + DHHN2016",PROJCRS["ETRS89 / UTM zone 32N",BASEGEOGCRS["ETRS89",ID["EPSG",4258]],ID["EPSG",25832]],VERTCRS["DHHN2016 height",ID["EPSG",7837]],ID["EPSG",9999]]"#;
        assert_eq!(wkt(wkt2).epsg_code(), Some(25832));
        assert_eq!(wkt(r#"LOCAL_CS["site"]"#).epsg_code(), None);
    }
}
