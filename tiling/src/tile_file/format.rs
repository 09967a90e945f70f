//! Format version 1: the byte layout of a tile file's header (see [`super`]), parsed and
//! checked. A version-1 encoding is also each frame of a framed tile ([`super::framed`]).

use super::Bounds;

/// File signature.
pub const MAGIC: &[u8; 8] = b"TALUSTIL";
/// Current format version.
pub const VERSION: u32 = 1;

/// Column kinds (see the module documentation).
pub(super) const KIND_F64: u8 = 0;
pub(super) const KIND_U32: u8 = 1;
pub(super) const KIND_U8: u8 = 2;
pub(super) const KIND_QUANT: u8 = 3;
pub(super) const KIND_F32: u8 = 4;
/// Flag bit 0: the column's bytes are shuffled.
pub(super) const FLAG_SHUFFLE: u8 = 1;

/// A column as the header describes it.
pub(super) struct ColumnSpec {
    pub(super) name: String,
    pub(super) kind: u8,
    pub(super) flags: u8,
    pub(super) quant: Option<(f64, f64, i64)>,
    pub(super) stored_len: u64,
}

/// A version-1 header, parsed and checked.
pub(super) struct Header {
    pub(super) header_len: usize,
    pub(super) point_count: u64,
    pub(super) bounds: Bounds,
    pub(super) columns: Vec<ColumnSpec>,
    pub(super) payload_len: u64,
    pub(super) payload_crc: u32,
}

/// Bounds-checked little-endian reader; running out of bytes means the file is truncated.
pub(crate) struct Cursor<'a> {
    pub(crate) bytes: &'a [u8],
    pub(crate) pos: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        match end {
            Some(end) => {
                let s = &self.bytes[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err("file is truncated".into()),
        }
    }
    pub(crate) fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub(crate) fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    pub(crate) fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub(crate) fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub(crate) fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.array()?))
    }
}

/// Check a tile file's magic and that its format version is one of `allowed`; the version.
pub(super) fn check_magic_version(fixed: &[u8], allowed: &[u32]) -> Result<u32, String> {
    if fixed.len() < 12 {
        return Err("file is truncated".into());
    }
    if &fixed[..8] != MAGIC {
        return Err("bad magic (not a talus tile file)".into());
    }
    let version = u32::from_le_bytes([fixed[8], fixed[9], fixed[10], fixed[11]]);
    if !allowed.contains(&version) {
        let expected: Vec<String> = allowed.iter().map(|v| v.to_string()).collect();
        return Err(format!(
            "unsupported format version {version} (expected {})",
            expected.join(" or ")
        ));
    }
    Ok(version)
}

/// Parse and CRC-check the header at the start of `bytes`.
pub(super) fn parse_header(bytes: &[u8]) -> Result<Header, String> {
    check_magic_version(bytes, &[VERSION])?;
    let mut c = Cursor { bytes, pos: 12 };
    let header_len = c.u32()? as usize;
    if header_len < 16 + 4 || header_len > bytes.len() {
        return Err("file is truncated or header length is wrong".into());
    }
    let stored_crc = u32::from_le_bytes(
        bytes[header_len - 4..header_len]
            .try_into()
            .map_err(|_| "header length is wrong".to_string())?,
    );
    if crc32fast::hash(&bytes[..header_len - 4]) != stored_crc {
        return Err("header checksum mismatch".into());
    }
    let point_count = c.u64()?;
    let ncols = c.u32()?;
    let mut bounds = Bounds {
        min: [0.0; 3],
        max: [0.0; 3],
    };
    for v in bounds.min.iter_mut().chain(bounds.max.iter_mut()) {
        *v = c.f64()?;
    }
    let mut columns = Vec::new();
    for _ in 0..ncols {
        let name_len = usize::from(c.u16()?);
        let name = String::from_utf8(c.take(name_len)?.to_vec())
            .map_err(|_| "column name is not UTF-8".to_string())?;
        let kind = c.u8()?;
        if kind > KIND_F32 {
            return Err(format!("unknown column kind {kind}"));
        }
        let flags = c.u8()?;
        let quant = if kind == KIND_QUANT {
            Some((c.f64()?, c.f64()?, i64::from_le_bytes(c.array()?)))
        } else {
            None
        };
        let stored_len = c.u64()?;
        columns.push(ColumnSpec {
            name,
            kind,
            flags,
            quant,
            stored_len,
        });
    }
    let payload_len = c.u64()?;
    let payload_crc = c.u32()?;
    if c.pos + 4 != header_len {
        return Err("header length does not match its content".into());
    }
    let names: Vec<&str> = columns.iter().take(3).map(|c| c.name.as_str()).collect();
    if names != ["x", "y", "z"] {
        return Err("the first columns are not x, y, z".into());
    }
    Ok(Header {
        header_len,
        point_count,
        bounds,
        columns,
        payload_len,
        payload_crc,
    })
}

/// The length of the version-1 encoding at the start of `bytes` (its header checked).
pub(crate) fn encoded_len(bytes: &[u8]) -> Result<usize, String> {
    let h = parse_header(bytes)?;
    let len = (h.header_len as u64)
        .checked_add(h.payload_len)
        .ok_or("payload length too large")?;
    if len > bytes.len() as u64 {
        return Err("file is truncated".into());
    }
    Ok(len as usize)
}
