//! PLY point clouds (Turk 1994, "The PLY Polygon File Format"; the format as written by
//! CloudCompare, MeshLab, Open3D, PDAL's writers.ply): `ascii`, `binary_little_endian` and
//! `binary_big_endian`, the `vertex` element with `x`, `y`, `z` of any numeric type; other
//! vertex properties (also list properties), and other elements before or after the vertices
//! (faces, edges, ...) are skipped.
//!
//! A small parser of our own rather than a PLY crate: the crates we looked at (ply-rs and its
//! forks) read the whole body into memory as maps of property values, which does not scale to
//! 100M vertices. This one streams: the header is parsed once, the elements before `vertex` are
//! skipped record by record, and vertices are decoded one record at a time from a buffered
//! reader. PLY has a count but no bounds, so [`PlyReader::open`] streams the vertices once for
//! the bounds (and to find a truncated or bad file early) and [`PointReader::fill`] streams
//! them again.

use std::fs::File;
use std::io::{BufRead, BufReader, ErrorKind, Read};
use std::path::{Path, PathBuf};

use super::{check_finite, open_file, Bounds, CloudFormat, CloudInfo, Crs, Point3, PointReader};
use crate::error::{Error, Result};

/// A header longer than this is not a PLY header (guards against reading a huge file as one).
const MAX_HEADER_BYTES: u64 = 1 << 20;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Encoding {
    Ascii,
    LittleEndian,
    BigEndian,
}

/// The scalar property types of the PLY spec, with their alternative names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    /// Read one binary value of this type from `r`.
    pub(crate) fn read(self, r: &mut impl Read, enc: Encoding) -> std::io::Result<f64> {
        let mut b = [0u8; 8];
        r.read_exact(&mut b[..self.size()])?;
        Ok(self.decode(&b, enc))
    }

    pub(crate) fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// Decode from exactly `size()` bytes.
    pub(crate) fn decode(self, b: &[u8], enc: Encoding) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if enc == Encoding::BigEndian {
                    <$t>::from_be_bytes(a) as f64
                } else {
                    <$t>::from_le_bytes(a) as f64
                }
            }};
        }
        match self {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => num!(i16, 2),
            Scalar::U16 => num!(u16, 2),
            Scalar::I32 => num!(i32, 4),
            Scalar::U32 => num!(u32, 4),
            Scalar::F32 => num!(f32, 4),
            Scalar::F64 => num!(f64, 8),
        }
    }
}

#[derive(Debug, Clone, Copy)]
pub(crate) enum Property {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
pub(crate) struct Element {
    pub(crate) name: String,
    pub(crate) count: u64,
    pub(crate) props: Vec<(String, Property)>,
}

impl Element {
    /// Record size when every property is a scalar.
    fn fixed_size(&self) -> Option<usize> {
        self.props
            .iter()
            .map(|(_, p)| match p {
                Property::Scalar(s) => Some(s.size()),
                Property::List { .. } => None,
            })
            .sum()
    }
}

#[derive(Debug, Clone)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Index of the `vertex` element and of its x, y, z properties.
    vertex: usize,
    xyz: [usize; 3],
    /// The types of x, y, z.
    xyz_ty: [Scalar; 3],
}

/// Read a PLY header up to `end_header`: the encoding and the elements with their properties.
/// Shared by the point reader and the mesh reader ([`super::mesh_ply::read_ply_mesh`]).
pub(crate) fn parse_elements(
    path: &Path,
    r: &mut BufReader<File>,
) -> Result<(Encoding, Vec<Element>)> {
    let bad = |msg: String| Error::input(path, format!("unreadable PLY header: {msg}"));
    let mut line = String::new();
    let mut read = 0u64;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut line_no = 0;
    loop {
        line.clear();
        let n = r
            .read_line(&mut line)
            .map_err(|e| bad(format!("line {}: {e}", line_no + 1)))?;
        line_no += 1;
        read += n as u64;
        if line_no == 1 {
            super::strip_bom(&mut line);
        }
        if n == 0 {
            return Err(bad("no end_header line".into()));
        }
        if read > MAX_HEADER_BYTES {
            return Err(bad("no end_header line in the first megabyte".into()));
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["ply"] if line_no == 1 => {}
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", fmt, _version] => {
                encoding = Some(match *fmt {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::LittleEndian,
                    "binary_big_endian" => Encoding::BigEndian,
                    other => return Err(bad(format!("unknown format '{other}'"))),
                })
            }
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| bad(format!("line {line_no}: bad element count '{count}'")))?,
                props: Vec::new(),
            }),
            ["property", "list", count, item, name] => {
                let (Some(count), Some(item)) = (Scalar::parse(count), Scalar::parse(item)) else {
                    return Err(bad(format!("line {line_no}: unknown list property types")));
                };
                let el = elements
                    .last_mut()
                    .ok_or_else(|| bad(format!("line {line_no}: property before any element")))?;
                el.props
                    .push((name.to_string(), Property::List { count, item }));
            }
            ["property", ty, name] => {
                let ty = Scalar::parse(ty)
                    .ok_or_else(|| bad(format!("line {line_no}: unknown property type '{ty}'")))?;
                let el = elements
                    .last_mut()
                    .ok_or_else(|| bad(format!("line {line_no}: property before any element")))?;
                el.props.push((name.to_string(), Property::Scalar(ty)));
            }
            ["end_header"] => break,
            _ => {
                return Err(bad(format!(
                    "line {line_no}: unexpected '{}'",
                    line.trim_end()
                )))
            }
        }
    }
    let encoding = encoding.ok_or_else(|| bad("no format line".into()))?;
    Ok((encoding, elements))
}

fn parse_header(path: &Path, r: &mut BufReader<File>) -> Result<Header> {
    let (encoding, elements) = parse_elements(path, r)?;
    let vertex = elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| Error::input(path, "PLY file has no vertex element: not a point cloud"))?;
    let find = |name: &str| {
        elements[vertex]
            .props
            .iter()
            .enumerate()
            .find_map(|(i, (n, p))| match p {
                Property::Scalar(s) if n == name => Some((i, *s)),
                _ => None,
            })
    };
    let (Some((x, tx)), Some((y, ty)), Some((z, tz))) = (find("x"), find("y"), find("z")) else {
        return Err(Error::input(
            path,
            "PLY vertex element has no numeric x, y, z properties",
        ));
    };
    Ok(Header {
        encoding,
        elements,
        vertex,
        xyz: [x, y, z],
        xyz_ty: [tx, ty, tz],
    })
}

/// One pass over the vertices.
struct Pass {
    path: PathBuf,
    r: BufReader<File>,
    header: Header,
    /// Vertices read so far.
    index: u64,
    line: String,
    record: Vec<u8>,
    /// Byte offsets of x, y, z in a fixed-size binary vertex record.
    offsets: Option<[usize; 3]>,
    /// The vertex properties, for the general (ascii or list-bearing) decoder.
    vprops: Vec<Property>,
}

impl Pass {
    fn start(path: &Path) -> Result<Pass> {
        let mut r = BufReader::with_capacity(1 << 20, open_file(path)?);
        let header = parse_header(path, &mut r)?;
        let vertex = &header.elements[header.vertex];
        let offsets = match (header.encoding, vertex.fixed_size()) {
            (Encoding::Ascii, _) | (_, None) => None,
            (_, Some(_)) => {
                let mut starts = Vec::with_capacity(vertex.props.len());
                let mut at = 0;
                for (_, p) in &vertex.props {
                    starts.push(at);
                    if let Property::Scalar(s) = p {
                        at += s.size();
                    }
                }
                Some(header.xyz.map(|i| starts[i]))
            }
        };
        let record = vec![0u8; vertex.fixed_size().unwrap_or(0)];
        let vprops = vertex.props.iter().map(|(_, p)| *p).collect();
        let mut pass = Pass {
            path: path.to_path_buf(),
            r,
            header,
            index: 0,
            line: String::new(),
            record,
            offsets,
            vprops,
        };
        for e in 0..pass.header.vertex {
            let el = pass.header.elements[e].clone();
            for i in 0..el.count {
                pass.skip_record(&el).map_err(|err| {
                    pass.eof_error(err, format!("element '{}' {i} of {}", el.name, el.count))
                })?;
            }
        }
        Ok(pass)
    }

    /// After the last vertex, when the header declares no element after the vertices: the file
    /// must end (whitespace aside). More rows mean the header's count disagrees with the data
    /// (a header saying 10 vertices over 829 rows would be read as 10 points): refused.
    fn check_nothing_after(&mut self) -> Result<()> {
        if self.header.vertex + 1 != self.header.elements.len() {
            return Ok(());
        }
        let mut rest = Vec::new();
        (&mut self.r)
            .take(1 << 20)
            .read_to_end(&mut rest)
            .map_err(|e| Error::input(&self.path, format!("cannot read: {e}")))?;
        let extra = match self.header.encoding {
            Encoding::Ascii => rest.iter().any(|b| !b.is_ascii_whitespace()),
            _ => !rest.is_empty(),
        };
        if extra {
            let what = match self.header.encoding {
                Encoding::Ascii => format!(
                    "{} more row(s)",
                    rest.split(|&b| b == b'\n')
                        .filter(|l| l.iter().any(|b| !b.is_ascii_whitespace()))
                        .count()
                ),
                _ => format!("{} more byte(s)", rest.len()),
            };
            return Err(Error::input(
                &self.path,
                format!(
                    "PLY header disagrees with its data: it declares {} vertices but {what} \
                     follow them (counted up to 1 MiB); corrupt header",
                    self.vertex_count()
                ),
            ));
        }
        Ok(())
    }

    fn vertex_count(&self) -> u64 {
        self.header.elements[self.header.vertex].count
    }

    fn eof_error(&self, e: std::io::Error, what: String) -> Error {
        if e.kind() == ErrorKind::UnexpectedEof {
            Error::input(
                &self.path,
                format!("truncated PLY file: it ends inside {what}"),
            )
        } else if e.kind() == ErrorKind::InvalidData {
            Error::input(&self.path, format!("corrupt PLY data in {what}: {e}"))
        } else {
            Error::input(&self.path, format!("cannot read: {e}"))
        }
    }

    /// Skip one record of an element that is not the vertex element.
    fn skip_record(&mut self, el: &Element) -> std::io::Result<()> {
        match self.header.encoding {
            Encoding::Ascii => {
                self.read_ascii_line()?;
            }
            enc => {
                for (_, p) in &el.props {
                    match p {
                        Property::Scalar(s) => self.skip_bytes(s.size())?,
                        Property::List { count, item } => {
                            let n = self.read_binary_scalar(*count, enc)?;
                            if !(0.0..=1e9).contains(&n) {
                                return Err(invalid(format!("list length {n}")));
                            }
                            self.skip_bytes(n as usize * item.size())?;
                        }
                    }
                }
            }
        }
        Ok(())
    }

    fn skip_bytes(&mut self, mut n: usize) -> std::io::Result<()> {
        let mut scratch = [0u8; 64];
        while n > 0 {
            let k = n.min(scratch.len());
            self.r.read_exact(&mut scratch[..k])?;
            n -= k;
        }
        Ok(())
    }

    fn read_binary_scalar(&mut self, s: Scalar, enc: Encoding) -> std::io::Result<f64> {
        s.read(&mut self.r, enc)
    }

    fn read_ascii_line(&mut self) -> std::io::Result<()> {
        loop {
            self.line.clear();
            if self.r.read_line(&mut self.line)? == 0 {
                return Err(ErrorKind::UnexpectedEof.into());
            }
            if !self.line.trim().is_empty() {
                return Ok(());
            }
        }
    }

    /// Decode one vertex record.
    fn read_vertex(&mut self) -> std::io::Result<Point3> {
        let enc = self.header.encoding;
        if let Some(off) = self.offsets {
            // Fast path: fixed-size binary records.
            self.r.read_exact(&mut self.record)?;
            let t = self.header.xyz_ty;
            return Ok([0, 1, 2].map(|k| t[k].decode(&self.record[off[k]..], enc)));
        }
        // The property list is taken out for the call so that decoding may borrow `self`.
        let props = std::mem::take(&mut self.vprops);
        let p = if enc == Encoding::Ascii {
            self.decode_ascii(&props)
        } else {
            self.decode_binary(&props, enc)
        };
        self.vprops = props;
        p
    }

    fn decode_ascii(&mut self, props: &[Property]) -> std::io::Result<Point3> {
        let [ix, iy, iz] = self.header.xyz;
        let mut p = [0.0; 3];
        self.read_ascii_line()?;
        let mut tokens = self.line.split_whitespace();
        let mut next = || {
            tokens
                .next()
                .ok_or_else(|| invalid("too few values on the line".into()))
                .and_then(|t| {
                    t.parse::<f64>()
                        .map_err(|_| invalid(format!("'{t}' is not a number")))
                })
        };
        for (i, prop) in props.iter().enumerate() {
            match prop {
                Property::Scalar(_) => {
                    let v = next()?;
                    for (k, want) in [ix, iy, iz].into_iter().enumerate() {
                        if want == i {
                            p[k] = v;
                        }
                    }
                }
                Property::List { .. } => {
                    let n = next()?;
                    if !(0.0..=1e9).contains(&n) {
                        return Err(invalid(format!("list length {n}")));
                    }
                    for _ in 0..n as usize {
                        next()?;
                    }
                }
            }
        }
        Ok(p)
    }

    fn decode_binary(&mut self, props: &[Property], enc: Encoding) -> std::io::Result<Point3> {
        let [ix, iy, iz] = self.header.xyz;
        let mut p = [0.0; 3];
        for (i, prop) in props.iter().enumerate() {
            match prop {
                Property::Scalar(s) => {
                    let v = self.read_binary_scalar(*s, enc)?;
                    for (k, want) in [ix, iy, iz].into_iter().enumerate() {
                        if want == i {
                            p[k] = v;
                        }
                    }
                }
                Property::List { count, item } => {
                    let n = self.read_binary_scalar(*count, enc)?;
                    if !(0.0..=1e9).contains(&n) {
                        return Err(invalid(format!("list length {n}")));
                    }
                    self.skip_bytes(n as usize * item.size())?;
                }
            }
        }
        Ok(p)
    }

    fn next_point(&mut self) -> Result<Option<Point3>> {
        if self.index == self.vertex_count() {
            return Ok(None);
        }
        let p = self.read_vertex().map_err(|e| {
            let what = format!(
                "vertex {} (the header promises {})",
                self.index,
                self.vertex_count()
            );
            self.eof_error(e, what)
        })?;
        check_finite(&self.path, self.index, &p)?;
        self.index += 1;
        Ok(Some(p))
    }
}

fn invalid(msg: String) -> std::io::Error {
    std::io::Error::new(ErrorKind::InvalidData, msg)
}

/// A streaming PLY reader; see the module doc.
pub(crate) struct PlyReader {
    info: CloudInfo,
    pass: Pass,
}

impl PlyReader {
    /// Open `path` (which starts with `ply`), parse its header and scan the vertices once for
    /// the bounds.
    pub(crate) fn open(path: &Path) -> Result<Self> {
        let mut scan = Pass::start(path)?;
        let count = scan.vertex_count();
        if count == 0 {
            return Err(Error::input(path, "contains no points"));
        }
        let mut bounds = Bounds::empty();
        while let Some(p) = scan.next_point()? {
            bounds.grow(&p);
        }
        scan.check_nothing_after()?;
        let encoding = match scan.header.encoding {
            Encoding::Ascii => "ascii",
            Encoding::LittleEndian => "binary_little_endian",
            Encoding::BigEndian => "binary_big_endian",
        };
        let info = CloudInfo {
            path: path.to_path_buf(),
            format: CloudFormat::Ply,
            format_detail: format!("PLY {encoding}"),
            point_count: count,
            bounds,
            crs: Crs::default(),
            scale: None,
            transform: None,
        };
        Ok(PlyReader {
            info,
            pass: Pass::start(path)?,
        })
    }
}

impl PointReader for PlyReader {
    fn info(&self) -> &CloudInfo {
        &self.info
    }

    fn fill(&mut self, buf: &mut Vec<Point3>, max: usize) -> Result<usize> {
        super::fill_from(buf, max, || self.pass.next_point())
    }
}
