//! Triangle meshes in PLY (Turk 1994, "The PLY polygon file format"): writing the event
//! solids, reading the user's surfaces.
//!
//! Written: `binary_little_endian 1.0`, `element vertex` with `double x, y, z`,
//! `element face` with `list uchar int vertex_indices`; to a temporary name, then renamed, so
//! nothing half-written is left under the final name.
//!
//! Read: ascii, binary_little_endian and binary_big_endian; any scalar types; x, y, z taken
//! from the vertex element (other properties and elements skipped); faces from a list
//! property named `vertex_indices` or `vertex_index`, polygons fan-triangulated.

use std::io::{BufReader, Read, Write};
use std::path::Path;

use crate::error::{Error, Result};
use crate::io::ply::{self, Encoding, Property, Scalar};
use crate::volume::Mesh;

/// Write a mesh to `w` as binary little-endian PLY.
pub(crate) fn write_ply_to(w: &mut impl Write, mesh: &Mesh) -> std::io::Result<()> {
    write_header(w, mesh.vertices.len() as u64, mesh.faces.len() as u64)?;
    write_vertices(w, &mesh.vertices)?;
    write_faces(w, &mesh.faces, 0)
}

/// The header of a PLY file of `vertices` and `faces` (a file written in parts: the header,
/// every part's vertices, every part's faces).
pub(crate) fn write_header(w: &mut impl Write, vertices: u64, faces: u64) -> std::io::Result<()> {
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment talus event solid\n\
         element vertex {vertices}\nproperty double x\nproperty double y\nproperty double z\n\
         element face {faces}\nproperty list uchar int vertex_indices\nend_header\n",
    )
}

/// Vertices as the body of a PLY file of [`write_header`].
pub(crate) fn write_vertices(w: &mut impl Write, vertices: &[[f64; 3]]) -> std::io::Result<()> {
    for p in vertices {
        for c in p {
            w.write_all(&c.to_le_bytes())?;
        }
    }
    Ok(())
}

/// Faces as the body of a PLY file of [`write_header`], their vertex indices moved by `offset`
/// (the vertices of the parts before). Fails on an index beyond a PLY `int`.
pub(crate) fn write_faces(
    w: &mut impl Write,
    faces: &[[u32; 3]],
    offset: u64,
) -> std::io::Result<()> {
    for f in faces {
        w.write_all(&[3u8])?;
        for &i in f {
            let i = i32::try_from(u64::from(i) + offset).map_err(|_| {
                std::io::Error::other("a solid of more than 2^31 vertices does not fit PLY's int")
            })?;
            w.write_all(&i.to_le_bytes())?;
        }
    }
    Ok(())
}

/// Write a mesh as binary little-endian PLY (atomic: temporary file + rename).
pub fn write_ply(path: &Path, mesh: &Mesh) -> Result<()> {
    Ok(talus_tiling::atomic_write_with(path, |f| {
        let mut w = std::io::BufWriter::new(f);
        write_ply_to(&mut w, mesh)?;
        w.flush()
    })?)
}

/// Read a triangle mesh (global coordinates) from a PLY file.
pub fn read_ply_mesh(path: &Path) -> Result<Mesh> {
    let bad = |m: String| Error::input(path, m);
    let f = super::open_file(path)?;
    let mut r = BufReader::new(f);
    // The header parser is the point reader's: one PLY grammar in the project.
    let (enc, elements) = ply::parse_elements(path, &mut r)?;
    let mut mesh = Mesh::default();
    let mut ascii_tokens: Vec<String> = Vec::new();
    let mut ascii_pos = 0usize;
    if enc == Encoding::Ascii {
        let mut rest = String::new();
        r.read_to_string(&mut rest)
            .map_err(|e| bad(format!("cannot read PLY body: {e}")))?;
        ascii_tokens = rest.split_whitespace().map(str::to_string).collect();
    }
    let mut next = |r: &mut BufReader<std::fs::File>, s: Scalar| -> Result<f64> {
        match enc {
            Encoding::Ascii => {
                let t = ascii_tokens
                    .get(ascii_pos)
                    .ok_or_else(|| bad("PLY body ends early".into()))?;
                ascii_pos += 1;
                t.parse::<f64>()
                    .map_err(|_| bad(format!("bad number '{t}' in PLY body")))
            }
            _ => s
                .read(r, enc)
                .map_err(|_| bad("PLY body ends early".into())),
        }
    };
    for el in &elements {
        let is_vertex = el.name == "vertex";
        let is_face = el.name == "face";
        for _ in 0..el.count {
            let mut xyz = [f64::NAN; 3];
            for (name, p) in &el.props {
                match p {
                    Property::Scalar(s) => {
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
                    Property::List { count: c, item: i } => {
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
                                .map_or(0, |e| e.count as usize);
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
