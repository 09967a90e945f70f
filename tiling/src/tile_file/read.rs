//! Reading tile files of either format version: whole ([`read_tile`]), a frame at a time
//! ([`read_tile_frames`], [`TileFrames`]) or only the header ([`read_tile_header`]).

use std::fs::File;
use std::io::{Read, Seek};
use std::path::Path;

use super::codec::{decode, Frame};
use super::format::{check_magic_version, parse_header, Header, VERSION};
use super::{framed, Bounds, TileColumns, TileHeader};
use crate::error::{Error, Result};

/// Read and verify a tile file.
pub fn read_tile(path: &Path) -> Result<TileColumns> {
    let mut bytes = Vec::new();
    File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|e| Error::io(path, e))?;
    let decoded = match check_magic_version(&bytes, &[VERSION, framed::VERSION]) {
        Ok(framed::VERSION) => framed::decode(&bytes),
        Ok(_) => decode(&bytes),
        Err(e) => Err(e),
    };
    decoded.map_err(|reason| Error::corrupt(path, reason))
}

/// The u32 columns `names` of a version-1 tile file, verified as [`read_tile`] verifies it
/// (magic, version, header and payload checksums, length), but only these columns
/// decompressed: a reader after the keys of many small sorted files leaves the rest.
pub fn read_u32_columns(path: &Path, names: &[&str]) -> Result<Vec<Vec<u32>>> {
    let mut bytes = Vec::new();
    File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|e| Error::io(path, e))?;
    let columns = check_magic_version(&bytes, &[VERSION])
        .and_then(|_| Frame::check(&bytes))
        .and_then(|frame| names.iter().map(|n| frame.u32_column(n)).collect());
    columns.map_err(|reason| Error::corrupt(path, reason))
}

/// Read and verify a tile file a frame at a time: `f` gets each frame's columns in order (a
/// version-1 file is one frame), so a reader that keeps only some points holds one frame's
/// worth, not the tile's. Damage anywhere is an error, as with [`read_tile`]; `f` may have seen
/// the frames before the damaged one.
pub fn read_tile_frames(path: &Path, mut f: impl FnMut(TileColumns) -> Result<()>) -> Result<()> {
    let mut frames = TileFrames::open(path)?;
    while let Some(cols) = frames.next_frame()? {
        f(cols)?;
    }
    Ok(())
}

/// A tile file read a frame at a time by a reader that pulls (one that walks another sorted
/// stream beside it); [`read_tile_frames`] is the same for one that is pushed to. Holds one
/// frame's bytes and columns at a time.
#[derive(Debug)]
pub struct TileFrames {
    path: std::path::PathBuf,
    file: File,
    /// A version-1 file: its one frame, until taken.
    whole: Option<TileColumns>,
    /// Every frame given (and a framed file's end checked).
    done: bool,
    /// Frames in the file, and the next to read.
    frames: u32,
    next: u32,
    /// Points read so far, and the header's count.
    points: u64,
    expected: u64,
    bytes: Vec<u8>,
}

impl TileFrames {
    /// Open `path` and read its header.
    pub fn open(path: &Path) -> Result<TileFrames> {
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let mut fixed = [0u8; 16];
        read_exact_or_corrupt(&mut file, &mut fixed, path)?;
        let version = check_magic_version(&fixed, &[VERSION, framed::VERSION])
            .map_err(|r| Error::corrupt(path, r))?;
        let mut frames = TileFrames {
            path: path.to_path_buf(),
            file,
            whole: None,
            done: false,
            frames: 0,
            next: 0,
            points: 0,
            expected: 0,
            bytes: Vec::new(),
        };
        if version == VERSION {
            let whole = read_tile(path)?;
            frames.expected = whole.len() as u64;
            frames.whole = Some(whole);
            return Ok(frames);
        }
        let mut head = fixed.to_vec();
        head.resize(framed::HEADER_LEN, 0);
        read_exact_or_corrupt(&mut frames.file, &mut head[16..], path)?;
        let h = framed::parse_header(&head).map_err(|r| Error::corrupt(path, r))?;
        frames.frames = h.frames;
        frames.expected = h.point_count;
        Ok(frames)
    }

    /// Points in the file (the header's count).
    pub fn point_count(&self) -> u64 {
        self.expected
    }

    /// The next frame's columns; None after the last (the file's length and count checked).
    pub fn next_frame(&mut self) -> Result<Option<TileColumns>> {
        self.next_frame_where(&|_| true)
    }

    /// The next frame whose bounds `want` accepts; the frames before it that it does not accept
    /// are passed over unread (their points counted from their headers, their payloads neither
    /// decoded nor checked). A version-1 file's one frame is always given. A reader that needs
    /// only the points in some boxes reads only the frames that reach them: a tile's frames hold
    /// its points in the survey's order, which on real and synthetic files alike is a scan's
    /// or a grid's, so a frame covers a strip of the tile, not all of it.
    pub fn next_frame_where(
        &mut self,
        want: &dyn Fn(&Bounds) -> bool,
    ) -> Result<Option<TileColumns>> {
        if let Some(whole) = self.whole.take() {
            self.done = true;
            return Ok(Some(whole));
        }
        loop {
            if self.done {
                return Ok(None);
            }
            if self.next == self.frames {
                self.done = true;
                return self.check_end().map(|()| None);
            }
            let mut fixed = [0u8; 16];
            read_exact_or_corrupt(&mut self.file, &mut fixed, &self.path)?;
            let fh = read_v1_header(&mut self.file, &self.path, fixed)?;
            if want(&fh.bounds) {
                return self.rest_of_frame(fixed, &fh).map(Some);
            }
            let skip = i64::try_from(fh.payload_len).map_err(|_| {
                Error::corrupt(
                    &self.path,
                    format!("frame {}: payload too large", self.next),
                )
            })?;
            self.file
                .seek(std::io::SeekFrom::Current(skip))
                .map_err(|e| Error::io(&self.path, e))?;
            self.points += fh.point_count;
            self.next += 1;
        }
    }

    /// The frame whose first 16 bytes are `fixed` and header `fh` (read, the file just past it).
    fn rest_of_frame(&mut self, fixed: [u8; 16], fh: &Header) -> Result<TileColumns> {
        let path = self.path.as_path();
        let k = self.next;
        let len = (fh.header_len as u64)
            .checked_add(fh.payload_len)
            .and_then(|l| usize::try_from(l).ok())
            .ok_or_else(|| Error::corrupt(path, format!("frame {k}: payload length too large")))?;
        self.bytes.clear();
        self.bytes.extend_from_slice(&fixed);
        self.bytes.resize(len, 0);
        // Back to the frame's start (the header was read to learn the length), then all of it.
        self.file
            .seek(std::io::SeekFrom::Current(-(fh.header_len as i64 - 16)))
            .map_err(|e| Error::io(path, e))?;
        read_exact_or_corrupt(&mut self.file, &mut self.bytes[16..], path)?;
        let cols =
            decode(&self.bytes).map_err(|r| Error::corrupt(path, format!("frame {k}: {r}")))?;
        self.points += cols.len() as u64;
        self.next += 1;
        Ok(cols)
    }

    /// After the last frame of a framed file: nothing beyond it, and the header's count read
    /// (a version-1 file was checked whole when read, and never gets here).
    fn check_end(&mut self) -> Result<()> {
        let path = self.path.as_path();
        // Where the frames end against the file's length: frames passed over were sought
        // past, not read, so a cut in one shows only here.
        let at = self
            .file
            .stream_position()
            .map_err(|e| Error::io(path, e))?;
        let len = self.file.metadata().map_err(|e| Error::io(path, e))?.len();
        if at != len {
            return Err(Error::corrupt(
                path,
                if at > len {
                    "file is truncated"
                } else {
                    "file is longer than its frames"
                },
            ));
        }
        if self.points != self.expected {
            return Err(Error::corrupt(
                path,
                format!(
                    "frames hold {} points, the header says {}",
                    self.points, self.expected
                ),
            ));
        }
        Ok(())
    }
}

/// Read and verify only a tile file's header (count, bounds, column names).
pub fn read_tile_header(path: &Path) -> Result<TileHeader> {
    let mut f = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut fixed = [0u8; 16];
    read_exact_or_corrupt(&mut f, &mut fixed, path)?;
    let version = check_magic_version(&fixed, &[VERSION, framed::VERSION])
        .map_err(|r| Error::corrupt(path, r))?;
    if version == VERSION {
        let h = read_v1_header(&mut f, path, fixed)?;
        return Ok(TileHeader {
            version,
            point_count: h.point_count,
            bounds: h.bounds,
            columns: h.columns.into_iter().map(|c| c.name).collect(),
        });
    }
    // The framed header, then its first frame's (a version-1 header) for the column names.
    let mut head = fixed.to_vec();
    head.resize(framed::HEADER_LEN, 0);
    read_exact_or_corrupt(&mut f, &mut head[16..], path)?;
    let h = framed::parse_header(&head).map_err(|r| Error::corrupt(path, r))?;
    read_exact_or_corrupt(&mut f, &mut fixed, path)?;
    let first = read_v1_header(&mut f, path, fixed)?;
    Ok(TileHeader {
        version,
        point_count: h.point_count,
        bounds: h.bounds,
        columns: first.columns.into_iter().map(|c| c.name).collect(),
    })
}

/// The version-1 header whose first 16 bytes are `fixed`, the rest read from `f`.
fn read_v1_header(f: &mut File, path: &Path, fixed: [u8; 16]) -> Result<Header> {
    let header_len = u32::from_le_bytes([fixed[12], fixed[13], fixed[14], fixed[15]]) as usize;
    if !(16..=1 << 24).contains(&header_len) {
        return Err(Error::corrupt(
            path,
            format!("implausible header length {header_len}"),
        ));
    }
    let mut head = fixed.to_vec();
    head.resize(header_len, 0);
    read_exact_or_corrupt(f, &mut head[16..], path)?;
    parse_header(&head).map_err(|r| Error::corrupt(path, r))
}

fn read_exact_or_corrupt(f: &mut File, buf: &mut [u8], path: &Path) -> Result<()> {
    f.read_exact(buf).map_err(|e| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            Error::corrupt(path, "file is truncated")
        } else {
            Error::io(path, e)
        }
    })
}
