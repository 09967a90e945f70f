//! Triangle meshes in PLY (Turk 1994, "The PLY polygon file format"): writing the event
//! solids, reading the user's surfaces, and checking that a solid is closed.
//!
//! Written: `binary_little_endian 1.0`, `element vertex` with `double x, y, z`,
//! `element face` with `list uchar int vertex_indices`; to a temporary name, then renamed, so
//! nothing half-written is left under the final name.
//!
//! Read: ascii, binary_little_endian and binary_big_endian; any scalar types; x, y, z taken
//! from the vertex element (other properties and elements skipped); faces from a list
//! property named `vertex_indices` or `vertex_index`, polygons fan-triangulated.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::Path;

pub use super::solid::Mesh;
use crate::error::{Error, Result};

/// Write a mesh as binary little-endian PLY (atomic: temporary file + rename).
pub fn write_ply(path: &Path, mesh: &Mesh) -> Result<()> {
    let tmp = path.with_file_name(format!(
        ".{}.tmp",
        path.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "mesh.ply".into())
    ));
    let write = || -> std::io::Result<()> {
        let f = std::fs::File::create(&tmp)?;
        let mut w = std::io::BufWriter::new(f);
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment talus event solid\n\
             element vertex {}\nproperty double x\nproperty double y\nproperty double z\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            mesh.vertices.len(),
            mesh.faces.len()
        )?;
        for p in &mesh.vertices {
            for c in p {
                w.write_all(&c.to_le_bytes())?;
            }
        }
        for f in &mesh.faces {
            w.write_all(&[3u8])?;
            for &i in f {
                w.write_all(&(i as i32).to_le_bytes())?;
            }
        }
        let f = w.into_inner().map_err(|e| e.into_error())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::output(path, e)
    })
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
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
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
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
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    fn decode(self, b: &[u8], le: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                (if le {
                    <$t>::from_le_bytes(a)
                } else {
                    <$t>::from_be_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => num!(i16, 2),
            Scalar::U16 => num!(u16, 2),
            Scalar::I32 => num!(i32, 4),
            Scalar::U32 => num!(u32, 4),
            Scalar::F32 => num!(f32, 4),
            Scalar::F64 => num!(f64, 8),
        }
    }
}

#[derive(Debug, Clone)]
enum Prop {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

/// Read a triangle mesh (global coordinates) from a PLY file.
pub fn read_ply_mesh(path: &Path) -> Result<Mesh> {
    let bad = |m: String| Error::input(path, m);
    let f = std::fs::File::open(path).map_err(|e| bad(format!("cannot open: {e}")))?;
    let mut r = BufReader::new(f);
    let mut line = String::new();
    let read_line = |r: &mut BufReader<std::fs::File>, line: &mut String| -> Result<()> {
        line.clear();
        let n = r
            .read_line(line)
            .map_err(|e| bad(format!("cannot read PLY header: {e}")))?;
        if n == 0 {
            return Err(bad("PLY header ends before end_header".into()));
        }
        Ok(())
    };
    read_line(&mut r, &mut line)?;
    if line.trim_end() != "ply" {
        return Err(bad("not a PLY file (no 'ply' magic)".into()));
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        read_line(&mut r, &mut line)?;
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.as_slice() {
            ["end_header"] => break,
            ["format", f, _] => format = Some(f.to_string()),
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count
                    .parse()
                    .map_err(|_| bad(format!("bad element count '{count}'")))?,
                props: Vec::new(),
            }),
            ["property", "list", c, i, name] => {
                let (c, i) = (Scalar::parse(c), Scalar::parse(i));
                let (Some(c), Some(i)) = (c, i) else {
                    return Err(bad(format!("bad list property type in '{}'", line.trim())));
                };
                elements
                    .last_mut()
                    .ok_or_else(|| bad("property before element".into()))?
                    .props
                    .push(Prop::List(name.to_string(), c, i));
            }
            ["property", ty, name] => {
                let s = Scalar::parse(ty)
                    .ok_or_else(|| bad(format!("unknown property type '{ty}'")))?;
                elements
                    .last_mut()
                    .ok_or_else(|| bad("property before element".into()))?
                    .props
                    .push(Prop::Scalar(name.to_string(), s));
            }
            _ => {} // comment, obj_info, blank
        }
    }
    let le = match format.as_deref() {
        Some("ascii") => None,
        Some("binary_little_endian") => Some(true),
        Some("binary_big_endian") => Some(false),
        other => return Err(bad(format!("unsupported PLY format {other:?}"))),
    };
    let mut mesh = Mesh::default();
    let mut ascii_tokens: Vec<String> = Vec::new();
    let mut ascii_pos = 0usize;
    if le.is_none() {
        let mut rest = String::new();
        r.read_to_string(&mut rest)
            .map_err(|e| bad(format!("cannot read PLY body: {e}")))?;
        ascii_tokens = rest.split_whitespace().map(str::to_string).collect();
    }
    let mut next = |r: &mut BufReader<std::fs::File>, s: Scalar| -> Result<f64> {
        match le {
            None => {
                let t = ascii_tokens
                    .get(ascii_pos)
                    .ok_or_else(|| bad("PLY body ends early".into()))?;
                ascii_pos += 1;
                t.parse::<f64>()
                    .map_err(|_| bad(format!("bad number '{t}' in PLY body")))
            }
            Some(le) => {
                let mut b = [0u8; 8];
                r.read_exact(&mut b[..s.size()])
                    .map_err(|_| bad("PLY body ends early".into()))?;
                Ok(s.decode(&b, le))
            }
        }
    };
    for el in &elements {
        let is_vertex = el.name == "vertex";
        let is_face = el.name == "face";
        for _ in 0..el.count {
            let mut xyz = [f64::NAN; 3];
            for p in &el.props {
                match p {
                    Prop::Scalar(name, s) => {
                        let x = next(&mut r, *s)?;
                        if is_vertex {
                            match name.as_str() {
                                "x" => xyz[0] = x,
                                "y" => xyz[1] = x,
                                "z" => xyz[2] = x,
                                _ => {}
                            }
                        }
                    }
                    Prop::List(name, c, i) => {
                        let n = next(&mut r, *c)?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(bad(format!("bad list length {n}")));
                        }
                        let mut idx = Vec::with_capacity(n as usize);
                        for _ in 0..n as usize {
                            idx.push(next(&mut r, *i)?);
                        }
                        if is_face && (name == "vertex_indices" || name == "vertex_index") {
                            let nv = elements
                                .iter()
                                .find(|e| e.name == "vertex")
                                .map_or(0, |e| e.count);
                            if idx.iter().any(|&k| !(k >= 0.0 && (k as usize) < nv)) {
                                return Err(bad("face refers to a missing vertex".into()));
                            }
                            for k in 1..idx.len().saturating_sub(1) {
                                mesh.faces
                                    .push([idx[0] as u32, idx[k] as u32, idx[k + 1] as u32]);
                            }
                        }
                    }
                }
            }
            if is_vertex {
                if !xyz.iter().all(|x| x.is_finite()) {
                    return Err(bad("vertex without finite x, y, z".into()));
                }
                mesh.vertices.push(xyz);
            }
        }
    }
    if mesh.faces.is_empty() {
        return Err(bad("PLY has no faces (a surface mesh is required)".into()));
    }
    Ok(mesh)
}

/// Is `mesh` a closed, consistently oriented, outward-facing solid? Every undirected edge
/// must be used by exactly two faces, once in each direction, and the signed volume must be
/// positive. The message names the first problem found.
pub fn check_watertight(mesh: &Mesh) -> std::result::Result<(), String> {
    use std::collections::HashMap;
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for (k, f) in mesh.faces.iter().enumerate() {
        if f.iter().any(|&i| i as usize >= mesh.vertices.len()) {
            return Err(format!("face {k} refers to a missing vertex"));
        }
        if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
            return Err(format!("face {k} repeats a vertex"));
        }
        for e in 0..3 {
            *directed.entry((f[e], f[(e + 1) % 3])).or_insert(0) += 1;
        }
    }
    for (&(a, b), &n) in &directed {
        if n != 1 {
            return Err(format!(
                "edge {a}->{b} used {n} times in the same direction"
            ));
        }
        if !directed.contains_key(&(b, a)) {
            return Err(format!("edge {a}-{b} has one face only (open)"));
        }
    }
    let v = super::solid::signed_volume(mesh);
    if v.is_nan() || v <= 0.0 {
        return Err(format!("signed volume {v} is not positive"));
    }
    Ok(())
}
