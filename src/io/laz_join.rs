//! LAZ files written in parts joined into one, without decompressing a point (issue 47: a large
//! pair's m3c2.laz written by several Slurm tasks).
//!
//! A LASzip file (LASzip's `laszip_dll.cpp`; `laz` 0.13's `ParLasZipCompressor`) is the LAS
//! header and its VLRs (one the LASzip VLR: the items and the chunk size), then at the start of
//! the point data the 8-byte offset of the chunk table, the chunks — each compressed on its own,
//! the coder reset at its start — the chunk table (each chunk's byte count, integer-compressed)
//! and the EVLRs. Chunks concatenate: parts that share the header's every field but the counts
//! and bounds, the VLRs, the EVLRs and the chunk size, every part but the last made of whole
//! chunks, join into the file one writer would have written from their points one after the
//! other, byte for byte: its header is the parts' with the counts summed and the bounds
//! widened (the bounds are rounded outward onto the coordinate grid point by point, so the
//! bounds of the whole are those of the parts'), its chunks theirs in order, its chunk table
//! theirs one after the other (written with `laz`'s own encoder), its EVLRs theirs, at the
//! new position the header points to.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// What a part holds, read from its header and chunk table.
struct Part {
    path: PathBuf,
    raw: las::raw::Header,
    /// The VLRs' bytes (after the header, up to the point data).
    vlrs: Vec<u8>,
    /// The EVLRs' bytes (after the chunk table, to the end).
    evlrs: Vec<u8>,
    /// Where the chunks start (after the chunk table's offset) and their byte counts.
    chunks_at: u64,
    table: laz::laszip::ChunkTable,
    laz: laz::LazVlr,
    points: u64,
}

fn damaged(path: &Path, problem: impl std::fmt::Display) -> Error {
    Error::Damaged {
        path: path.to_path_buf(),
        problem: problem.to_string(),
    }
}

/// The points a raw header counts.
fn points_of(raw: &las::raw::Header) -> u64 {
    raw.large_file
        .map_or(u64::from(raw.number_of_point_records), |l| {
            l.number_of_point_records
        })
}

fn read_part(path: &Path) -> Result<Part> {
    let bad = |e: &dyn std::fmt::Display| damaged(path, format!("a LAZ part: {e}"));
    let mut f = File::open(path).map_err(|e| damaged(path, e))?;
    let len = f.metadata().map_err(|e| damaged(path, e))?.len();
    let raw = las::raw::Header::read_from(&mut f).map_err(|e| bad(&e))?;
    let start = u64::from(raw.header_size);
    let data = u64::from(raw.offset_to_point_data);
    if data < start || data + 8 > len {
        return Err(bad(&"its point data lies outside the file"));
    }
    let mut vlrs = vec![0u8; (data - start) as usize];
    f.seek(SeekFrom::Start(start))
        .and_then(|_| f.read_exact(&mut vlrs))
        .map_err(|e| damaged(path, e))?;
    let mut laz = None;
    let mut cursor = std::io::Cursor::new(&vlrs[..]);
    for _ in 0..raw.number_of_variable_length_records {
        let v = las::raw::Vlr::read_from(&mut cursor, false).map_err(|e| bad(&e))?;
        let user = v.user_id.split(|&b| b == 0).next().unwrap_or(&[]);
        if user == laz::LazVlr::USER_ID.as_bytes() && v.record_id == laz::LazVlr::RECORD_ID {
            laz = Some(laz::LazVlr::read_from(&v.data[..]).map_err(|e| bad(&e))?);
        }
    }
    let laz = laz.ok_or_else(|| bad(&"no LASzip VLR"))?;
    if laz.uses_variable_size_chunks() {
        return Err(bad(&"chunks of variable size"));
    }
    f.seek(SeekFrom::Start(data))
        .map_err(|e| damaged(path, e))?;
    let table = laz::laszip::ChunkTable::read_from(&mut f, &laz).map_err(|e| bad(&e))?;
    let bytes: u64 = table.as_ref().iter().map(|c| c.byte_count).sum();
    let evlr_at = match raw.evlr {
        Some(e) if e.number_of_evlrs > 0 => e.start_of_first_evlr,
        _ => len,
    };
    if evlr_at > len || evlr_at < data + 8 + bytes {
        return Err(bad(&"its EVLRs overlap its chunks"));
    }
    let mut evlrs = vec![0u8; (len - evlr_at) as usize];
    f.seek(SeekFrom::Start(evlr_at))
        .and_then(|_| f.read_exact(&mut evlrs))
        .map_err(|e| damaged(path, e))?;
    let points = points_of(&raw);
    Ok(Part {
        path: path.to_path_buf(),
        raw,
        vlrs,
        evlrs,
        chunks_at: data + 8,
        table,
        laz,
        points,
    })
}

/// The header of the joined file: the first part's with the parts' counts summed and bounds
/// widened. Fails where the parts differ in anything else.
fn joined_header(parts: &[Part]) -> Result<las::raw::Header> {
    let first = &parts[0];
    let mut raw = first.raw.clone();
    let mut points_by_return = [0u64; 15];
    let mut legacy = (0u64, [0u64; 5]);
    let mut bounds: Option<[f64; 6]> = None;
    for p in parts {
        let mut same = p.raw.clone();
        // Everything but the counts, the bounds and the EVLRs' place must be the first part's.
        same.number_of_point_records = raw.number_of_point_records;
        same.number_of_points_by_return = raw.number_of_points_by_return;
        same.large_file = raw.large_file;
        (same.min_x, same.min_y, same.min_z) = (raw.min_x, raw.min_y, raw.min_z);
        (same.max_x, same.max_y, same.max_z) = (raw.max_x, raw.max_y, raw.max_z);
        same.evlr = raw.evlr;
        if same != raw || p.vlrs != first.vlrs || p.evlrs != first.evlrs {
            return Err(Error::Internal(format!(
                "{}: its header, VLRs or EVLRs are not those of {}: the parts of one file differ",
                p.path.display(),
                first.path.display()
            )));
        }
        legacy.0 += u64::from(p.raw.number_of_point_records);
        for (t, v) in legacy.1.iter_mut().zip(p.raw.number_of_points_by_return) {
            *t += u64::from(v);
        }
        if let Some(l) = p.raw.large_file {
            for (t, v) in points_by_return
                .iter_mut()
                .zip(l.number_of_points_by_return)
            {
                *t += v;
            }
        }
        if p.points > 0 {
            let r = &p.raw;
            let b = bounds.get_or_insert([r.min_x, r.min_y, r.min_z, r.max_x, r.max_y, r.max_z]);
            b[0] = b[0].min(r.min_x);
            b[1] = b[1].min(r.min_y);
            b[2] = b[2].min(r.min_z);
            b[3] = b[3].max(r.max_x);
            b[4] = b[4].max(r.max_y);
            b[5] = b[5].max(r.max_z);
        }
    }
    // The legacy u32 counts: 0 where a LAS 1.4 file's count does not fit them (as las writes
    // it; the u64 counts hold it), an error where there is nothing else to hold it.
    let legacy_of = |v: u64| match (u32::try_from(v), raw.large_file.is_some()) {
        (Ok(v), _) => Ok(v),
        (Err(_), true) => Ok(0),
        (Err(_), false) => Err(Error::Internal(
            "the joined parts count more points than LAS holds".into(),
        )),
    };
    raw.number_of_point_records = legacy_of(legacy.0)?;
    for (t, v) in raw.number_of_points_by_return.iter_mut().zip(legacy.1) {
        *t = legacy_of(v)?;
    }
    if let Some(l) = raw.large_file.as_mut() {
        l.number_of_point_records = parts.iter().map(|p| p.points).sum();
        l.number_of_points_by_return = points_by_return;
    }
    if let Some(b) = bounds {
        (raw.min_x, raw.min_y, raw.min_z) = (b[0], b[1], b[2]);
        (raw.max_x, raw.max_y, raw.max_z) = (b[3], b[4], b[5]);
    }
    Ok(raw)
}

/// Join the LAZ files `parts` (in order) into `path`, written under a temporary name and
/// renamed into place; returns the points written. Every part but the last must be made of
/// whole chunks, and the parts must share everything but their points.
pub(crate) fn join_laz(parts: &[PathBuf], path: &Path) -> Result<u64> {
    if parts.is_empty() {
        return Err(Error::Internal("no LAZ parts to join".into()));
    }
    let parts: Vec<Part> = parts.iter().map(|p| read_part(p)).collect::<Result<_>>()?;
    let chunk = u64::from(parts[0].laz.chunk_size());
    for p in &parts[..parts.len() - 1] {
        if p.points != p.table.len() as u64 * chunk {
            return Err(Error::Internal(format!(
                "{}: {} points, not whole chunks of {chunk}: it cannot be followed by another part",
                p.path.display(),
                p.points
            )));
        }
    }
    let mut raw = joined_header(&parts)?;
    let atomic = talus_tiling::AtomicFile::new(path);
    let out_err = |e: std::io::Error| Error::output(path, e);
    let mut out = File::create(atomic.tmp()).map_err(out_err)?;
    let mut table = laz::laszip::ChunkTable::default();
    let mut io = |out: &mut File| -> std::io::Result<()> {
        // The header again at the end, with the EVLRs' place.
        let mut head = Vec::new();
        raw.write_to(&mut head).map_err(std::io::Error::other)?;
        out.write_all(&head)?;
        out.write_all(&parts[0].vlrs)?;
        let offset_at = out.stream_position()?;
        out.write_all(&0i64.to_le_bytes())?;
        for p in &parts {
            let bytes: u64 = p.table.as_ref().iter().map(|c| c.byte_count).sum();
            let mut f = File::open(&p.path)?;
            f.seek(SeekFrom::Start(p.chunks_at))?;
            // File to file: the kernel copies (copy_file_range), no buffer of ours.
            let copied = std::io::copy(&mut f.take(bytes), out)?;
            if copied != bytes {
                return Err(std::io::Error::other(format!(
                    "{}: {copied} of its {bytes} chunk bytes",
                    p.path.display()
                )));
            }
            table.extend(&p.table);
        }
        let table_at = out.stream_position()?;
        let mut encoded = Vec::new();
        table.write_to(&mut encoded, &parts[0].laz)?;
        out.write_all(&encoded)?;
        let evlr_at = out.stream_position()?;
        out.write_all(&parts[0].evlrs)?;
        out.seek(SeekFrom::Start(offset_at))?;
        out.write_all(&(table_at as i64).to_le_bytes())?;
        if let Some(e) = raw.evlr.as_mut() {
            e.start_of_first_evlr = evlr_at;
        }
        head.clear();
        raw.write_to(&mut head).map_err(std::io::Error::other)?;
        out.seek(SeekFrom::Start(0))?;
        out.write_all(&head)?;
        out.sync_all()
    };
    io(&mut out).map_err(out_err)?;
    drop(out);
    atomic.commit()?;
    Ok(parts.iter().map(|p| p.points).sum())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::las_out::{laz_chunk_size, CoordinateGrid, ExtraDim, ExtraType, ResultWriter};
    use crate::io::Crs;

    const DIMS: &[ExtraDim] = &[
        ExtraDim {
            name: std::borrow::Cow::Borrowed("distance"),
            ty: ExtraType::F64,
            description: "d",
        },
        ExtraDim {
            name: std::borrow::Cow::Borrowed("flag"),
            ty: ExtraType::U8,
            description: "f",
        },
    ];

    /// Point `i` of a scene whose parts have bounds of their own.
    fn point(i: u64) -> ([f64; 3], [f64; 2]) {
        let t = i as f64;
        let xyz = [
            1000.0 + (t * 0.37).sin() * 50.0 + t * 1e-3,
            2000.0 + (t * 0.11).cos() * 20.0,
            (t * 7.3e-4).sin() * 300.0,
        ];
        (xyz, [(t * 0.01).sin(), (i % 2) as f64])
    }

    fn write(path: &Path, crs: &Crs, range: std::ops::Range<u64>, total: u64) {
        let grid = CoordinateGrid::millimetre([1000.0, 2000.0, 0.0]);
        let mut w = ResultWriter::create_on_grid(path, crs, DIMS, grid, Some(total)).unwrap();
        for i in range {
            let (xyz, extra) = point(i);
            w.write(xyz, &extra).unwrap();
        }
        w.finish().unwrap();
    }

    /// Parts of whole chunks joined are the file one writer writes, byte for byte, for a WKT
    /// CRS (point format 6, LAS 1.4 counts) and none, with an empty part among them.
    #[test]
    fn joined_parts_are_the_whole_file() {
        let dir = tempfile::tempdir().unwrap();
        let wkt = Crs {
            wkt: Some("LOCAL_CS[\"test\"]".into()),
            ..Default::default()
        };
        for crs in [Crs::default(), wkt] {
            let total = 230_011u64;
            let chunk = u64::from(laz_chunk_size(Some(total)));
            let whole = dir.path().join("whole.laz");
            write(&whole, &crs, 0..total, total);
            // Cuts on chunk boundaries, one part empty.
            let cuts = [0, chunk, 3 * chunk, 3 * chunk, total];
            let mut parts = Vec::new();
            for (k, w) in cuts.windows(2).enumerate() {
                let p = dir.path().join(format!("p{k}.laz"));
                write(&p, &crs, w[0]..w[1], total);
                parts.push(p);
            }
            let joined = dir.path().join("joined.laz");
            assert_eq!(join_laz(&parts, &joined).unwrap(), total);
            let (a, b) = (
                std::fs::read(&whole).unwrap(),
                std::fs::read(&joined).unwrap(),
            );
            assert_eq!(a.len(), b.len());
            assert!(a == b, "the joined file differs from the whole one");
            // A part that ends inside a chunk cannot be followed.
            let odd = dir.path().join("odd.laz");
            write(&odd, &crs, 0..chunk + 1, total);
            let e = join_laz(&[odd, parts[1].clone()], &joined).unwrap_err();
            assert!(e.to_string().contains("whole chunks"), "{e}");
        }
    }
}
