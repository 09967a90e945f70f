//! A cloud decoded once in this process, replayed from disk instead of decoded again.
//!
//! A comparison reads the before survey twice: the spacing pass ([`crate::sampling`]) reads
//! every point (the density grid the tiles are sized by), then its tiling unit reads them all
//! again. Decoding LAZ is most of both (on the 120M-point pair 20 s of the spacing pass, the
//! same again in the tiling). So the spacing pass may keep what it decodes ([`Recorder`]): the
//! points as the reader delivered them in a scratch file, as the LAS integers they were decoded
//! from (12 bytes a point: each is checked to give back the reader's value bit for bit through
//! the file's own transform, else the copy is given up) or, for a file without a transform, as
//! raw `f64` triples (24 bytes). Once the pass has
//! read the whole file, [`Recorder::finish`] registers the copy in this process ([`Replay`],
//! removed with its file when dropped), and [`super::open_with`] of the same file with the same
//! class filter reads the copy (`ReplayReader`) instead: the same points in the same order,
//! the same header information and class counts, at the speed of reading a file.
//!
//! A copy is read once: removed as soon as a reader has read it whole (the tiling).
//!
//! Only what this process recorded is replayed (another process, e.g. a Slurm worker, decodes
//! the file itself); a file whose size or modification time changed since it was recorded is
//! decoded again. The copy's CRC-32 is checked as it is read back: a damaged copy is an error,
//! never other points. A copy that cannot be written (a full disk) is given up, not an error:
//! the file is then simply decoded again.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::SystemTime;

use super::classes::{ClassCounts, Classes};
use super::{CloudInfo, Point3, PointReader};
use crate::error::{Error, Result};

/// How a copy stores a point.
#[derive(Clone, Copy)]
enum Layout {
    /// The LAS record's integers, given back through these transforms (`las`'s, as the reader).
    Quantised([las::Transform; 3], [f64; 3]),
    /// The `f64` values.
    Raw,
}

impl Layout {
    fn of(transform: Option<[[f64; 2]; 3]>) -> Layout {
        match transform {
            Some(t) => Layout::Quantised(
                t.map(|[scale, offset]| las::Transform { scale, offset }),
                t.map(|[scale, _]| 1.0 / scale),
            ),
            None => Layout::Raw,
        }
    }

    /// Bytes of one point.
    fn bytes(self) -> usize {
        match self {
            Layout::Quantised(..) => 12,
            Layout::Raw => 24,
        }
    }

    /// Append `p`'s bytes to `out`; false when its integers would not give it back exactly.
    fn put(self, p: &Point3, out: &mut Vec<u8>) -> bool {
        match self {
            Layout::Quantised(t, inverse) => {
                for k in 0..3 {
                    // The integer nearest (or next to it: whether it gives the value back is
                    // checked below), rounded by a cast (`f64::round` is a call to libm).
                    let y = (p[k] - t[k].offset) * inverse[k];
                    let n = (y + 0.5f64.copysign(y)) as i64;
                    let Ok(n) = i32::try_from(n) else {
                        return false;
                    };
                    if t[k].direct(n).to_bits() != p[k].to_bits() {
                        return false;
                    }
                    out.extend_from_slice(&n.to_le_bytes());
                }
            }
            Layout::Raw => {
                for v in p {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        true
    }

    /// The point of `b` (its [`Layout::bytes`] bytes).
    fn get(self, b: &[u8]) -> Point3 {
        match self {
            Layout::Quantised(t, _) => {
                let n = |k: usize| i32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
                [t[0].direct(n(0)), t[1].direct(n(4)), t[2].direct(n(8))]
            }
            Layout::Raw => {
                let v = |k: usize| f64::from_le_bytes(b[k..k + 8].try_into().unwrap_or([0; 8]));
                [v(0), v(8), v(16)]
            }
        }
    }
}
/// Bytes buffered by a copy's writer and reader.
pub(crate) const BUFFER: usize = 1 << 20;

/// What identifies a recorded file and the way it was read.
#[derive(Clone, PartialEq)]
struct Source {
    /// Canonical path.
    path: PathBuf,
    size: u64,
    modified: Option<SystemTime>,
    classes: Option<Classes>,
}

impl Source {
    fn of(path: &Path, classes: Option<&Classes>) -> Option<Source> {
        let path = std::fs::canonicalize(path).ok()?;
        let meta = std::fs::metadata(&path).ok()?;
        Some(Source {
            path,
            size: meta.len(),
            modified: meta.modified().ok(),
            classes: classes.cloned(),
        })
    }
}

/// A finished copy: where it is and what the reader told about the file.
#[derive(Clone)]
struct Recorded {
    source: Source,
    file: PathBuf,
    layout: Layout,
    points: u64,
    crc32: u32,
    info: CloudInfo,
    classes: Option<ClassCounts>,
}

/// The copies of this process.
static COPIES: Mutex<Vec<Recorded>> = Mutex::new(Vec::new());

fn copies() -> std::sync::MutexGuard<'static, Vec<Recorded>> {
    COPIES.lock().unwrap_or_else(|e| e.into_inner())
}

/// The copy of `path` read with `classes`, when this process recorded one of the file as it is.
fn find(path: &Path, classes: Option<&Classes>) -> Option<Recorded> {
    let source = Source::of(path, classes)?;
    copies().iter().find(|c| c.source == source).cloned()
}

/// [`super::open_with`]'s reader of a recorded file, when there is one.
pub(super) fn reader(path: &Path, classes: Option<&Classes>) -> Result<Option<ReplayReader>> {
    let Some(copy) = find(path, classes) else {
        return Ok(None);
    };
    let f = File::open(&copy.file)
        .map_err(|e| Error::input(&copy.file, format!("cannot read: {e}")))?;
    Ok(Some(ReplayReader {
        file: BufReader::with_capacity(BUFFER, f),
        bytes: Vec::new(),
        read: 0,
        crc: crc32fast::Hasher::new(),
        copy,
    }))
}

/// Points being recorded as a reader delivers them.
pub struct Recorder {
    source: Option<Source>,
    file: PathBuf,
    layout: Layout,
    out: Option<BufWriter<File>>,
    /// The bytes of the points being pushed (kept between pushes).
    bytes: Vec<u8>,
    points: u64,
    crc: crc32fast::Hasher,
}

impl Recorder {
    /// Record what is read of `path` with `classes` into the new file `copy` (a scratch name the
    /// caller owns; removed unless [`Recorder::finish`] hands it to a [`Replay`]); `transform`
    /// is the file's ([`CloudInfo::transform`]). A copy that cannot be created is given up: the
    /// recorder then keeps nothing.
    pub fn create(
        path: &Path,
        classes: Option<&Classes>,
        transform: Option<[[f64; 2]; 3]>,
        copy: PathBuf,
    ) -> Recorder {
        let source = Source::of(path, classes);
        let out = source
            .as_ref()
            .and_then(|_| File::create_new(&copy).ok())
            .map(|f| BufWriter::with_capacity(BUFFER, f));
        Recorder {
            source,
            file: copy,
            layout: Layout::of(transform),
            out,
            bytes: Vec::new(),
            points: 0,
            crc: crc32fast::Hasher::new(),
        }
    }

    /// Keep `points` (the next ones the reader delivered). A point its integers would not give
    /// back, or a failed write, gives the copy up.
    pub fn push(&mut self, points: &[Point3]) {
        let Some(out) = self.out.as_mut() else {
            return;
        };
        self.bytes.clear();
        let layout = self.layout;
        let exact = points.iter().all(|p| layout.put(p, &mut self.bytes));
        self.crc.update(&self.bytes);
        self.points += points.len() as u64;
        if !exact || out.write_all(&self.bytes).is_err() {
            self.give_up();
        }
    }

    fn give_up(&mut self) {
        if self.out.take().is_some() {
            let _ = std::fs::remove_file(&self.file);
        }
    }

    /// The whole file was read, delivering `info`'s points and, with a class filter, `classes`
    /// counts: register the copy for this process's readers of the file. None when the copy was
    /// given up, or the file changed while it was read.
    pub fn finish(mut self, info: &CloudInfo, classes: Option<ClassCounts>) -> Option<Replay> {
        let out = self.out.take()?;
        let source = self.source.take()?;
        // Flushed, not synced: the copy lives as long as this process and is checked against its
        // CRC as it is read back, so nothing is gained by waiting for the disk (forcing 1.4 GB
        // out at the end of the 120M-point pair's spacing pass held both cores for ≈ 2 s).
        let done = out.into_inner().ok();
        if done.is_none()
            || Source::of(&source.path, source.classes.as_ref()) != Some(source.clone())
        {
            let _ = std::fs::remove_file(&self.file);
            return None;
        }
        let copy = Recorded {
            source,
            file: std::mem::take(&mut self.file),
            layout: self.layout,
            points: self.points,
            crc32: self.crc.clone().finalize(),
            info: info.clone(),
            classes,
        };
        copies().push(copy.clone());
        Some(Replay { file: copy.file })
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.give_up();
    }
}

/// A registered copy: readers of its file read it until this is dropped, which removes it.
pub struct Replay {
    file: PathBuf,
}

impl Replay {
    /// The copy's file.
    pub fn file(&self) -> &Path {
        &self.file
    }
}

impl Drop for Replay {
    fn drop(&mut self) {
        copies().retain(|c| c.file != self.file);
        let _ = std::fs::remove_file(&self.file);
    }
}

/// Reads a copy back: the points, header and class counts the file's own reader gave.
pub(crate) struct ReplayReader {
    copy: Recorded,
    file: BufReader<File>,
    bytes: Vec<u8>,
    read: u64,
    crc: crc32fast::Hasher,
}

impl ReplayReader {
    /// The copy does not read back as recorded: it is given up (this process's readers decode
    /// the file again) and the unit reading it fails.
    fn damaged(&self, what: &str) -> Error {
        copies().retain(|c| c.file != self.copy.file);
        Error::Damaged {
            path: self.copy.file.clone(),
            problem: format!(
                "the decoded copy of {} {what}; run again",
                self.copy.source.path.display()
            ),
        }
    }
}

impl PointReader for ReplayReader {
    fn info(&self) -> &CloudInfo {
        &self.copy.info
    }

    fn fill(&mut self, buf: &mut Vec<Point3>, max: usize) -> Result<usize> {
        buf.clear();
        let n = (self.copy.points - self.read).min(max as u64) as usize;
        if n == 0 {
            let mut rest = [0u8; 1];
            let longer = !matches!(self.file.read(&mut rest), Ok(0));
            if longer {
                return Err(self.damaged("is longer than recorded"));
            }
            if self.crc.clone().finalize() != self.copy.crc32 {
                return Err(self.damaged("does not match its checksum"));
            }
            // Read whole once: its one reader (the survey's tiling) is done with it. Removed now,
            // not when the run ends, so that the run's peak on disk does not hold a copy of the
            // survey beside its tiles; a later reader decodes the file.
            copies().retain(|c| c.file != self.copy.file);
            let _ = std::fs::remove_file(&self.copy.file);
            return Ok(0);
        }
        let layout = self.copy.layout;
        self.bytes.resize(n * layout.bytes(), 0);
        if self.file.read_exact(&mut self.bytes).is_err() {
            return Err(self.damaged("is shorter than recorded"));
        }
        self.crc.update(&self.bytes);
        buf.extend(
            self.bytes
                .chunks_exact(layout.bytes())
                .map(|b| layout.get(b)),
        );
        self.read += n as u64;
        Ok(n)
    }

    fn class_counts(&self) -> Option<ClassCounts> {
        self.copy.classes.clone()
    }

    /// The points left out are known only as a whole: reported once every point was read.
    fn left_out(&self) -> u64 {
        match (&self.copy.classes, self.read == self.copy.points) {
            (Some(c), true) => c.left_out(),
            _ => 0,
        }
    }
}
