//! Framed tile files (format version 2): a tile written while its points arrive, in frames of a
//! fixed number of points.
//!
//! ```text
//! magic        8 bytes  "TALUSTIL"
//! version      u32      2
//! header_len   u32      84
//! point_count  u64      points of all frames
//! frame_count  u32
//! reserved     u32      0
//! bounds       6 × f64  min x, y, z, max x, y, z of the points (+inf/-inf when empty)
//! header_crc   u32      CRC-32 of every header byte before it
//! frames       frame_count complete version-1 tile encodings (each with its own header,
//!              column lengths and CRCs), one after the other, in point order
//! ```
//!
//! The splitter appends a frame to a tile's file whenever the tile has gathered a frame's worth
//! of points, and writes the header over the placeholder at the start when the split ends. A
//! tile is then encoded once: the version-1 splitter flushed buffers to segment files, read them
//! back and encoded every tile a second time (a third of pass 1 on the 120M-point pair). Frames
//! also decode in parallel. The frame size is the writer's (the splitter derives it from its
//! memory budget and the grid), so the bytes of a tile depend on it; its points never do.

use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::atomic::{publish, tmp_path};
use crate::error::{Error, Result};
use crate::tile_file::{self, Bounds, FileDigest, Frame, TileColumns, WriteOptions};

/// The format version of framed tile files.
pub const VERSION: u32 = 2;
/// Bytes of the header.
pub const HEADER_LEN: usize = 84;

/// A framed tile file being written at `path` (through `<path>.tmp` until [`Framed::finish`]).
#[derive(Debug)]
pub struct Framed {
    path: PathBuf,
    frames: u32,
    points: u64,
    bounds: Bounds,
    /// CRC-32 and length of the frames written.
    crc: crc32fast::Hasher,
    len: u64,
}

impl Framed {
    /// A tile file to be written at `path`; nothing is written before the first frame.
    pub fn new(path: &Path) -> Self {
        Framed {
            path: path.to_path_buf(),
            frames: 0,
            points: 0,
            bounds: Bounds {
                min: [f64::INFINITY; 3],
                max: [f64::NEG_INFINITY; 3],
            },
            crc: crc32fast::Hasher::new(),
            len: 0,
        }
    }

    /// Points written so far.
    pub fn points(&self) -> u64 {
        self.points
    }

    /// Append `cols` as one frame (opened for each frame, so that a split over thousands of
    /// tiles holds no file open between frames).
    pub fn append(&mut self, cols: &TileColumns, opts: &WriteOptions) -> Result<()> {
        let tmp = tmp_path(&self.path);
        let (bytes, b) =
            tile_file::encode_with_bounds(cols, opts).map_err(|p| Error::invalid(&tmp, p))?;
        let mut f = if self.frames == 0 {
            let mut f = File::create(&tmp).map_err(|e| Error::io(&tmp, e))?;
            f.write_all(&[0; HEADER_LEN])
                .map_err(|e| Error::io(&tmp, e))?;
            f
        } else {
            OpenOptions::new()
                .append(true)
                .open(&tmp)
                .map_err(|e| Error::io(&tmp, e))?
        };
        f.write_all(&bytes).map_err(|e| Error::io(&tmp, e))?;
        self.crc.update(&bytes);
        self.len += bytes.len() as u64;
        self.frames += 1;
        self.points += cols.len() as u64;
        for a in 0..3 {
            self.bounds.min[a] = self.bounds.min[a].min(b.min[a]);
            self.bounds.max[a] = self.bounds.max[a].max(b.max[a]);
        }
        Ok(())
    }

    /// Write the header, make the file durable and give it its name; the file's digest. At
    /// least one frame must have been appended.
    pub fn finish(self) -> Result<FileDigest> {
        let tmp = tmp_path(&self.path);
        if self.frames == 0 {
            return Err(Error::invalid(&self.path, "a framed tile without a frame"));
        }
        let header = header_bytes(self.points, self.frames, &self.bounds);
        let mut f = OpenOptions::new()
            .write(true)
            .open(&tmp)
            .map_err(|e| Error::io(&tmp, e))?;
        f.seek(SeekFrom::Start(0))
            .and_then(|_| f.write_all(&header))
            .and_then(|()| f.sync_all())
            .map_err(|e| Error::io(&tmp, e))?;
        drop(f);
        publish(&tmp, &self.path)?;
        let mut crc = crc32fast::Hasher::new();
        crc.update(&header);
        crc.combine(&self.crc);
        Ok(FileDigest {
            size: HEADER_LEN as u64 + self.len,
            crc32: crc.finalize(),
        })
    }
}

/// The header of a framed tile.
fn header_bytes(points: u64, frames: u32, bounds: &Bounds) -> [u8; HEADER_LEN] {
    let mut h = Vec::with_capacity(HEADER_LEN);
    h.extend_from_slice(tile_file::MAGIC);
    h.extend_from_slice(&VERSION.to_le_bytes());
    h.extend_from_slice(&(HEADER_LEN as u32).to_le_bytes());
    h.extend_from_slice(&points.to_le_bytes());
    h.extend_from_slice(&frames.to_le_bytes());
    h.extend_from_slice(&0u32.to_le_bytes());
    for v in bounds.min.iter().chain(&bounds.max) {
        h.extend_from_slice(&v.to_le_bytes());
    }
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    let mut out = [0; HEADER_LEN];
    out.copy_from_slice(&h);
    out
}

/// What a framed tile's header says: point count, frame count, bounds.
pub(crate) struct Header {
    pub point_count: u64,
    pub frames: u32,
    pub bounds: Bounds,
}

/// Parse and check the header at the start of `bytes` (at least [`HEADER_LEN`] of them).
pub(crate) fn parse_header(bytes: &[u8]) -> Result<Header, String> {
    if bytes.len() < HEADER_LEN {
        return Err("file is truncated".into());
    }
    let mut c = tile_file::Cursor { bytes, pos: 8 };
    if &bytes[..8] != tile_file::MAGIC || c.u32()? != VERSION {
        return Err("not a framed tile file".into());
    }
    if c.u32()? as usize != HEADER_LEN {
        return Err("header length is wrong".into());
    }
    let stored_crc = tile_file::Cursor {
        bytes,
        pos: HEADER_LEN - 4,
    }
    .u32()?;
    if crc32fast::hash(&bytes[..HEADER_LEN - 4]) != stored_crc {
        return Err("header checksum mismatch".into());
    }
    let point_count = c.u64()?;
    let frames = c.u32()?;
    c.pos = 32;
    let mut corner = || -> Result<[f64; 3], String> { Ok([c.f64()?, c.f64()?, c.f64()?]) };
    Ok(Header {
        point_count,
        frames,
        bounds: Bounds {
            min: corner()?,
            max: corner()?,
        },
    })
}

/// The frames of a framed tile held in `bytes`, each a version-1 encoding, checked to fill the
/// file exactly.
fn frames<'a>(bytes: &'a [u8], h: &Header) -> Result<Vec<&'a [u8]>, String> {
    let mut out = Vec::with_capacity(h.frames as usize);
    let mut pos = HEADER_LEN;
    for k in 0..h.frames {
        let len = tile_file::encoded_len(&bytes[pos..]).map_err(|e| format!("frame {k}: {e}"))?;
        out.push(&bytes[pos..pos + len]);
        pos += len;
    }
    if pos != bytes.len() {
        return Err("file is longer than its frames".into());
    }
    Ok(out)
}

/// Decode and verify a whole framed tile held in memory: every frame checked, then each decoded
/// (in parallel) straight into its range of the tile's columns.
pub(crate) fn decode(bytes: &[u8]) -> Result<TileColumns, String> {
    use rayon::prelude::*;
    let h = parse_header(bytes)?;
    // Checked in parallel, the first damaged frame reported (rayon's own collect into a Result
    // would report any one of several).
    let checked: Vec<Result<Frame, String>> = (frames(bytes, &h)?.into_par_iter().enumerate())
        .map(|(k, f)| Frame::check(f).map_err(|e| format!("frame {k}: {e}")))
        .collect();
    let frames = checked
        .into_iter()
        .collect::<Result<Vec<Frame>, String>>()?;
    let first = frames.first().ok_or("a framed tile without a frame")?;
    if !frames.iter().all(|f| f.same_columns(first)) {
        return Err("frames hold different columns".into());
    }
    let n: usize = frames.iter().map(Frame::len).sum();
    if n as u64 != h.point_count {
        return Err(format!(
            "frames hold {n} points, the header says {}",
            h.point_count
        ));
    }
    let mut out = first.empty_columns(n);
    let mut rest = out.slices();
    let mut parts = Vec::with_capacity(frames.len());
    for f in &frames {
        let (part, tail) = rest.split_at(f.len());
        parts.push(part);
        rest = tail;
    }
    let decoded: Vec<Result<(), String>> = (frames.par_iter().zip(parts))
        .map(|(f, mut part)| f.decode_into(&mut part))
        .collect();
    decoded.into_iter().collect::<Result<(), String>>()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tile_file::{read_tile, read_tile_header, Column, ColumnData, Quantisation};

    /// `frame`'s points after `cols`'s (the reference the decoding is checked against).
    fn append(cols: &mut TileColumns, frame: TileColumns) -> Result<(), String> {
        cols.x.extend_from_slice(&frame.x);
        cols.y.extend_from_slice(&frame.y);
        cols.z.extend_from_slice(&frame.z);
        for (c, f) in cols.extra.iter_mut().zip(frame.extra) {
            match (&mut c.data, f.data) {
                (ColumnData::F64(a), ColumnData::F64(b)) => a.extend_from_slice(&b),
                (ColumnData::F32(a), ColumnData::F32(b)) => a.extend_from_slice(&b),
                (ColumnData::U32(a), ColumnData::U32(b)) => a.extend_from_slice(&b),
                (ColumnData::U8(a), ColumnData::U8(b)) => a.extend_from_slice(&b),
                _ => return Err(format!("column {:?} changes kind", c.name)),
            }
        }
        Ok(())
    }

    fn frame(start: usize, n: usize) -> TileColumns {
        let f =
            |i: usize, k: usize| 500_000.0 + 0.001 * ((i * 7919 + k * 104_729) % 100_000) as f64;
        TileColumns {
            x: (start..start + n).map(|i| f(i, 0)).collect(),
            y: (start..start + n).map(|i| f(i, 1)).collect(),
            z: (start..start + n).map(|i| f(i, 2) - 499_900.0).collect(),
            extra: vec![Column {
                name: "owned".into(),
                data: ColumnData::U8((start..start + n).map(|i| (i % 3 == 0) as u8).collect()),
            }],
        }
    }

    /// Frames stored differently (coordinates quantised in some, raw where off the lattice; f64,
    /// u32 and u8 extra columns) are each decoded into their place: the tile reads back as the
    /// frames' points in order. Frames with different columns are damage.
    #[test]
    fn frames_stored_differently_read_back_in_place() {
        let dir = tempfile::tempdir().unwrap();
        let opts = WriteOptions {
            quantise: Some(Quantisation {
                scale: [0.001; 3],
                offset: [0.0; 3],
            }),
            ..WriteOptions::default()
        };
        let with_extras = |start: usize, n: usize, off_lattice: bool| {
            let mut f = frame(start, n);
            if off_lattice {
                f.x.iter_mut().for_each(|x| *x += 1e-7);
            }
            f.extra.push(Column {
                name: "id".into(),
                data: ColumnData::U32(
                    (start..start + n)
                        .map(|i| (i * 2_654_435_761) as u32)
                        .collect(),
                ),
            });
            f.extra.push(Column {
                name: "d".into(),
                data: ColumnData::F64((start..start + n).map(|i| (i as f64).sin()).collect()),
            });
            f
        };
        let path = dir.path().join("t.tile");
        let mut w = Framed::new(&path);
        let mut all: Option<TileColumns> = None;
        let mut start = 0;
        for (n, off) in [
            (700, false),
            (1300, true),
            (1, false),
            (900, true),
            (64, false),
        ] {
            let f = with_extras(start, n, off);
            w.append(&f, &opts).unwrap();
            match &mut all {
                None => all = Some(f),
                Some(a) => append(a, f).unwrap(),
            }
            start += n;
        }
        w.finish().unwrap();
        assert_eq!(read_tile(&path).unwrap(), all.unwrap());

        // Two damaged frames (a byte of the payload of the second and of the fourth): the
        // first of them is named, every time.
        let mut damaged = std::fs::read(&path).unwrap();
        let mut starts = vec![HEADER_LEN];
        while *starts.last().unwrap() < damaged.len() {
            let at = *starts.last().unwrap();
            starts.push(at + tile_file::encoded_len(&damaged[at..]).unwrap());
        }
        damaged[starts[2] - 10] ^= 0x40;
        damaged[starts[4] - 10] ^= 0x40;
        let twice = dir.path().join("twice.tile");
        std::fs::write(&twice, &damaged).unwrap();
        for _ in 0..20 {
            match read_tile(&twice) {
                Err(Error::Corrupt { reason, .. }) => {
                    assert!(reason.starts_with("frame 1:"), "{reason}")
                }
                other => panic!("{other:?}"),
            }
        }

        let mixed = dir.path().join("m.tile");
        let mut w = Framed::new(&mixed);
        w.append(&with_extras(0, 100, false), &opts).unwrap();
        w.append(&frame(100, 100), &opts).unwrap();
        w.finish().unwrap();
        match read_tile(&mixed) {
            Err(Error::Corrupt { reason, .. }) => assert!(reason.contains("different columns")),
            other => panic!("{other:?}"),
        }
    }

    /// A tile written in frames reads back as its points in order, with the header's count and
    /// bounds; the digest the writer reports is the file's; any damage is found.
    #[test]
    fn frames_read_back_whole_and_damage_is_found() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t_0000_0000.tile");
        let opts = WriteOptions {
            quantise: Some(Quantisation {
                scale: [0.001; 3],
                offset: [0.0; 3],
            }),
            ..WriteOptions::default()
        };
        let mut w = Framed::new(&path);
        let mut all = TileColumns::default();
        let mut start = 0;
        for n in [1000, 1000, 1000, 1000, 1000, 1000, 1000, 1000, 1000, 17] {
            let f = frame(start, n);
            w.append(&f, &opts).unwrap();
            if start == 0 {
                all = f;
            } else {
                append(&mut all, f).unwrap();
            }
            start += n;
        }
        assert!(!path.exists(), "nothing under the final name before finish");
        let digest = w.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(digest, FileDigest::of(&bytes));
        assert_eq!(read_tile(&path).unwrap(), all);
        // A frame at a time, the same points in the same order.
        let mut streamed: Option<TileColumns> = None;
        let mut sizes = Vec::new();
        crate::tile_file::read_tile_frames(&path, |f| {
            sizes.push(f.len());
            match &mut streamed {
                None => streamed = Some(f),
                Some(s) => append(s, f).unwrap(),
            }
            Ok(())
        })
        .unwrap();
        assert_eq!(streamed.unwrap(), all);
        assert_eq!(sizes.len(), 10);
        // Pulled a frame at a time: the header's count first, the same frames, then nothing.
        let mut pulled = crate::tile_file::TileFrames::open(&path).unwrap();
        assert_eq!(pulled.point_count(), start as u64);
        let mut pulled_sizes = Vec::new();
        while let Some(f) = pulled.next_frame().unwrap() {
            pulled_sizes.push(f.len());
        }
        assert_eq!(pulled_sizes, sizes);
        assert!(pulled.next_frame().unwrap().is_none());
        let h = read_tile_header(&path).unwrap();
        assert_eq!((h.version, h.point_count), (VERSION, start as u64));
        assert_eq!(h.bounds, all.bounds());
        assert_eq!(h.columns, ["x", "y", "z", "owned"]);

        let damaged = dir.path().join("d.tile");
        for at in [3, 20, HEADER_LEN + 5, bytes.len() / 2, bytes.len() - 1] {
            let mut b = bytes.clone();
            b[at] ^= 0x10;
            std::fs::write(&damaged, &b).unwrap();
            assert!(
                matches!(read_tile(&damaged), Err(Error::Corrupt { .. })),
                "a flipped byte at {at}"
            );
            assert!(
                matches!(
                    crate::tile_file::read_tile_frames(&damaged, |_| Ok(())),
                    Err(Error::Corrupt { .. })
                ),
                "a flipped byte at {at}, read a frame at a time"
            );
        }
        for len in [10, HEADER_LEN, bytes.len() / 3, bytes.len() - 1] {
            std::fs::write(&damaged, &bytes[..len]).unwrap();
            assert!(
                matches!(read_tile(&damaged), Err(Error::Corrupt { .. })),
                "cut at {len}"
            );
            assert!(
                matches!(
                    crate::tile_file::read_tile_frames(&damaged, |_| Ok(())),
                    Err(Error::Corrupt { .. })
                ),
                "cut at {len}, read a frame at a time"
            );
        }
        let mut longer = bytes.clone();
        longer.push(0);
        std::fs::write(&damaged, &longer).unwrap();
        assert!(matches!(read_tile(&damaged), Err(Error::Corrupt { .. })));
        assert!(matches!(
            crate::tile_file::read_tile_frames(&damaged, |_| Ok(())),
            Err(Error::Corrupt { .. })
        ));
    }

    /// Frames a reader does not want are passed over: it gets exactly the frames whose bounds it
    /// accepts, in order; a cut in a frame passed over is still found.
    #[test]
    fn frames_not_wanted_are_passed_over() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("strips.tile");
        let mut w = Framed::new(&path);
        // Five strips of 100 points, strip k with x in [10k, 10k + 1).
        let strip = |k: usize| TileColumns {
            x: (0..100)
                .map(|i| 10.0 * k as f64 + 0.01 * i as f64)
                .collect(),
            y: vec![0.0; 100],
            z: vec![0.0; 100],
            extra: Vec::new(),
        };
        for k in 0..5 {
            w.append(&strip(k), &WriteOptions::default()).unwrap();
        }
        w.finish().unwrap();
        let wanted = |b: &Bounds| b.max[0] >= 15.0 && b.min[0] <= 35.0;
        let mut frames = crate::tile_file::TileFrames::open(&path).unwrap();
        let mut got = Vec::new();
        while let Some(f) = frames.next_frame_where(&wanted).unwrap() {
            got.push(f);
        }
        assert_eq!(got, vec![strip(2), strip(3)]);
        // The last strip cut short: found though it is never read.
        let bytes = std::fs::read(&path).unwrap();
        let cut = dir.path().join("cut.tile");
        std::fs::write(&cut, &bytes[..bytes.len() - 3]).unwrap();
        let mut frames = crate::tile_file::TileFrames::open(&cut).unwrap();
        let found = loop {
            match frames.next_frame_where(&wanted) {
                Ok(Some(_)) => continue,
                Ok(None) => break None,
                Err(e) => break Some(e),
            }
        };
        assert!(matches!(found, Some(Error::Corrupt { .. })), "{found:?}");
    }
}
