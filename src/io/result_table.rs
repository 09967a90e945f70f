//! Read a LAS/LAZ file with extra-bytes dimensions back into columns, by the names its Extra Bytes
//! VLR gives (LAS 1.4 R15 §2.5.5): how tests, `talus info` users and the viewer export read
//! m3c2.laz without trusting our own writer's layout.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{Error, Result};
use crate::io::Point3;

/// Every point's coordinates and every extra dimension as f64, by name.
#[derive(Debug, Clone, Default)]
pub struct ResultTable {
    pub xyz: Vec<Point3>,
    pub columns: BTreeMap<String, Vec<f64>>,
    /// Dimension names in record order.
    pub names: Vec<String>,
}

impl ResultTable {
    /// A column by name, or an error naming what is missing.
    pub fn column(&self, name: &str) -> Result<&[f64]> {
        self.columns
            .get(name)
            .map(|v| v.as_slice())
            .ok_or_else(|| Error::Internal(format!("no extra dimension named {name}")))
    }
}

struct Descriptor {
    name: String,
    data_type: u8,
    size: usize,
}

fn type_size(t: u8) -> Option<usize> {
    Some(match t {
        1 | 2 => 1,
        3 | 4 => 2,
        5 | 6 | 9 => 4,
        7 | 8 | 10 => 8,
        _ => return None,
    })
}

fn decode(t: u8, b: &[u8]) -> f64 {
    match t {
        1 => b[0] as f64,
        2 => b[0] as i8 as f64,
        3 => u16::from_le_bytes([b[0], b[1]]) as f64,
        4 => i16::from_le_bytes([b[0], b[1]]) as f64,
        5 => u32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
        6 => i32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
        7 => u64::from_le_bytes(b[..8].try_into().unwrap()) as f64,
        8 => i64::from_le_bytes(b[..8].try_into().unwrap()) as f64,
        9 => f32::from_le_bytes(b[..4].try_into().unwrap()) as f64,
        _ => f64::from_le_bytes(b[..8].try_into().unwrap()),
    }
}

/// Read `path` whole (result files hold core points, not full epochs).
pub fn read(path: &Path) -> Result<ResultTable> {
    let bad = |m: String| Error::input(path, m);
    let mut reader = las::Reader::from_path(path).map_err(|e| bad(e.to_string()))?;
    let header = reader.header().clone();
    let vlr = header
        .vlrs()
        .iter()
        .chain(header.evlrs().iter())
        .find(|v| v.user_id == "LASF_Spec" && v.record_id == 4);
    let mut descs = Vec::new();
    if let Some(v) = vlr {
        for d in v.data.chunks_exact(192) {
            let data_type = d[2];
            let name_bytes = &d[4..36];
            let end = name_bytes.iter().position(|&c| c == 0).unwrap_or(32);
            let name = String::from_utf8_lossy(&name_bytes[..end]).to_string();
            let size = type_size(data_type).ok_or_else(|| {
                bad(format!(
                    "extra dimension {name}: unsupported data type {data_type}"
                ))
            })?;
            descs.push(Descriptor {
                name,
                data_type,
                size,
            });
        }
    }
    let mut t = ResultTable {
        names: descs.iter().map(|d| d.name.clone()).collect(),
        ..Default::default()
    };
    for d in &descs {
        t.columns.insert(d.name.clone(), Vec::new());
    }
    let data = reader.read_all().map_err(|e| bad(e.to_string()))?;
    t.xyz = data
        .x()
        .zip(data.y())
        .zip(data.z())
        .map(|((x, y), z)| [x, y, z])
        .collect();
    // The extra bytes close every record, in descriptor order.
    let rec = data.record_len();
    let total: usize = descs.iter().map(|d| d.size).sum();
    if total > rec {
        return Err(bad(
            "point records are shorter than their extra bytes".into()
        ));
    }
    for r in data.raw_bytes().chunks_exact(rec) {
        let mut off = rec - total;
        for d in &descs {
            t.columns
                .get_mut(&d.name)
                .expect("inserted above")
                .push(decode(d.data_type, &r[off..off + d.size]));
            off += d.size;
        }
    }
    Ok(t)
}
