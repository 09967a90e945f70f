//! Writing an epoch's chunks as LAS 1.4 / LAZ (point format 6) with a WKT CRS, atomically.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use las::{Builder, Transform, Vector, Version, Writer, WriterOptions};

use super::surface::V3;
use talus_base::{Error, Result};

/// OGC WKT 1 of WGS 84 / UTM zone 33N (EPSG:32633), as GDAL/PROJ export it.
pub const UTM33N_WKT: &str = concat!(
    r#"PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84",DATUM["WGS_1984","#,
    r#"SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],"#,
    r#"AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],"#,
    r#"UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],AUTHORITY["EPSG","4326"]],"#,
    r#"PROJECTION["Transverse_Mercator"],PARAMETER["latitude_of_origin",0],"#,
    r#"PARAMETER["central_meridian",15],PARAMETER["scale_factor",0.9996],"#,
    r#"PARAMETER["false_easting",500000],PARAMETER["false_northing",0],"#,
    r#"UNIT["metre",1,AUTHORITY["EPSG","9001"]],AXIS["Easting",EAST],AXIS["Northing",NORTH],"#,
    r#"AUTHORITY["EPSG","32633"]]"#
);

/// LAS scale (1 mm) and offsets: the offsets are the scene origin, so raw integers stay small.
pub(crate) const SCALE: f64 = 0.001;

/// Point format 6 record length.
const RECORD_LEN: usize = 30;

fn las_err(path: &Path, e: las::Error) -> Error {
    Error::output(path, std::io::Error::other(e))
}

/// Write `chunks` (points with their LAS class) to `path` (LAZ when `laz`), through `path`.tmp
/// renamed at the end; returns the number of points written. The temporary file is removed on
/// failure.
pub(crate) fn write_epoch(
    path: &Path,
    chunks: impl Iterator<Item = (Vec<V3>, u8)>,
    origin: V3,
    epoch: u16,
    laz: bool,
) -> Result<u64> {
    let file = talus_tiling::AtomicFile::new(path);
    let n = write_to(file.tmp(), chunks, origin, epoch, laz)?;
    file.commit()?;
    Ok(n)
}

fn write_to(
    path: &Path,
    chunks: impl Iterator<Item = (Vec<V3>, u8)>,
    origin: V3,
    epoch: u16,
    laz: bool,
) -> Result<u64> {
    let mut builder = Builder::from(Version::new(1, 4));
    builder.point_format = las::point::Format::new(6).map_err(|e| las_err(path, e))?;
    builder.point_format.is_compressed = laz;
    builder.generating_software = "talus synth".into();
    builder.system_identifier = "talus synthetic scene".into();
    // No creation date: identical inputs must give identical bytes.
    builder.date = None;
    builder.transforms = Vector {
        x: Transform {
            scale: SCALE,
            offset: origin[0],
        },
        y: Transform {
            scale: SCALE,
            offset: origin[1],
        },
        z: Transform {
            scale: SCALE,
            offset: origin[2],
        },
    };
    let mut header = builder.into_header().map_err(|e| las_err(path, e))?;
    // LAS 1.4 R15 §2.5: the WKT string is null-terminated.
    let mut wkt = UTM33N_WKT.as_bytes().to_vec();
    wkt.push(0);
    header.set_wkt_crs(wkt).map_err(|e| las_err(path, e))?;

    let file = File::create(path).map_err(|e| Error::output(path, e))?;
    // Parallel LAZ compression (laz-parallel): each chunk goes to the compressor in one
    // `compress_many` call, which compresses its LASzip chunks on the rayon pool.
    let mut writer = Writer::with_options(BufWriter::new(file), header, WriterOptions::default())
        .map_err(|e| las_err(path, e))?;
    let transforms = *writer.header().transforms();
    let format = *writer.header().point_format();
    // One chunk at a time: its points and their encoded records are dropped before the
    // iterator generates the next chunk.
    let write_all = || -> las::Result<u64> {
        let mut written = 0u64;
        for (chunk, class) in chunks {
            let mut bytes = Vec::with_capacity(chunk.len() * RECORD_LEN);
            for p in &chunk {
                encode(&mut bytes, p, &transforms, epoch, class);
            }
            let data = las::PointDataBuilder::new()
                .with_format(format)
                .with_transforms(transforms)
                .build_from_bytes(bytes)?;
            writer.write_points(&data)?;
            written += chunk.len() as u64;
        }
        writer.close()?;
        Ok(written)
    };
    match write_all() {
        Ok(n) => Ok(n),
        Err(e) => {
            // las-rs closes an unclosed writer in Drop and panics if that fails (disk full...):
            // on this error path, leak the writer instead; the caller removes the file.
            std::mem::forget(writer);
            Err(las_err(path, e))
        }
    }
}

/// One point format 6 record (LAS 1.4 R15 Table 13): X, Y, Z as scaled i32; intensity 0; return 1
/// of 1; no flags; class `class` (2, ground, for the surfaces of every scene but an unclassified
/// delivery's); user data 0; scan angle 0; point source id = epoch (1 or 2); GPS time 0.
fn encode(out: &mut Vec<u8>, p: &V3, t: &Vector<Transform>, epoch: u16, class: u8) {
    let raw = |v: f64, tr: &Transform| ((v - tr.offset) / tr.scale).round() as i32;
    out.extend_from_slice(&raw(p[0], &t.x).to_le_bytes());
    out.extend_from_slice(&raw(p[1], &t.y).to_le_bytes());
    out.extend_from_slice(&raw(p[2], &t.z).to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes()); // intensity
    out.push(0x11); // return number 1 (bits 0-3), number of returns 1 (bits 4-7)
    out.push(0); // classification flags, scanner channel, scan direction, edge of flight line
    out.push(class); // classification
    out.push(0); // user data
    out.extend_from_slice(&0i16.to_le_bytes()); // scan angle
    out.extend_from_slice(&epoch.to_le_bytes()); // point source id
    out.extend_from_slice(&0f64.to_le_bytes()); // GPS time
}
