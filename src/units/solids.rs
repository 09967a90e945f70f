//! An event's two solids written as PLY while its volume is measured (`volume::event_volume_in`
//! sends each piece's pair as it is closed). An event of one piece holds its pair and writes it
//! as before; a larger one appends each piece's vertices and faces to temporary files of the
//! unit (the PLY bodies, byte for byte), and its files are the header and those bodies, so no
//! piece is held beyond its own. The temporary files are removed before the unit commits.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::io::mesh_ply;
use crate::store::UnitWriter;
use crate::volume::Mesh;

/// One epoch's solid in parts: its vertices' and its faces' PLY bodies.
struct Parts {
    vertices: (PathBuf, BufWriter<File>),
    faces: (PathBuf, BufWriter<File>),
    n_vertices: u64,
    n_faces: u64,
}

/// The solids of one event, before and after (`units::volumes::mesh_files`).
pub(crate) struct EventSolids {
    id: u32,
    state: State,
}

enum State {
    /// One piece: its pair, once closed.
    Held(Option<[Mesh; 2]>),
    /// Several: what is appended so far.
    Parts(Box<[Parts; 2]>),
}

impl EventSolids {
    /// For event `id`, measured in one piece or in several (`pieced`).
    pub(crate) fn new(out: &mut UnitWriter, id: u32, pieced: bool) -> Result<EventSolids> {
        if !pieced {
            return Ok(EventSolids {
                id,
                state: State::Held(None),
            });
        }
        let [b, a] = super::volumes::mesh_files(id);
        let open = |out: &mut UnitWriter, name: String| -> Result<(PathBuf, BufWriter<File>)> {
            let path = out.path(&name)?;
            let f = File::create(&path).map_err(|e| Error::output(&path, e))?;
            Ok((path, BufWriter::with_capacity(super::scratch::BUFFER, f)))
        };
        let parts = |out: &mut UnitWriter, name: &str| -> Result<Parts> {
            Ok(Parts {
                vertices: open(out, format!("{name}.vertices.tmp"))?,
                faces: open(out, format!("{name}.faces.tmp"))?,
                n_vertices: 0,
                n_faces: 0,
            })
        };
        Ok(EventSolids {
            id,
            state: State::Parts(Box::new([parts(out, &b)?, parts(out, &a)?])),
        })
    }

    /// One piece's pair.
    pub(crate) fn push(&mut self, solids: [Mesh; 2]) -> Result<()> {
        match &mut self.state {
            State::Held(held) => {
                if held.replace(solids).is_some() {
                    return Err(Error::Internal(
                        "an event measured in one piece sent a second pair of solids".into(),
                    ));
                }
            }
            State::Parts(parts) => {
                for (p, m) in parts.iter_mut().zip(&solids) {
                    let (path, w) = &mut p.vertices;
                    mesh_ply::write_vertices(w, &m.vertices)
                        .map_err(|e| Error::output(&*path, e))?;
                    let (path, w) = &mut p.faces;
                    mesh_ply::write_faces(w, &m.faces, p.n_vertices)
                        .map_err(|e| Error::output(&*path, e))?;
                    p.n_vertices += m.vertices.len() as u64;
                    p.n_faces += m.faces.len() as u64;
                }
            }
        }
        Ok(())
    }

    /// Write the two files into `out`, and remove the temporary ones.
    pub(crate) fn finish(self, out: &mut UnitWriter) -> Result<()> {
        let names = super::volumes::mesh_files(self.id);
        match self.state {
            State::Held(None) => Err(Error::Internal(format!(
                "event {}: a volume without solids",
                self.id
            ))),
            State::Held(Some(pair)) => {
                for (name, solid) in names.iter().zip(&pair) {
                    super::write_streamed(out, name, |mut w| {
                        mesh_ply::write_ply_to(&mut w, solid)
                    })?;
                }
                Ok(())
            }
            State::Parts(parts) => {
                for (name, p) in names.iter().zip(*parts) {
                    let (vertices, faces) = (flushed(p.vertices)?, flushed(p.faces)?);
                    super::write_streamed(out, name, |mut w| {
                        mesh_ply::write_header(&mut w, p.n_vertices, p.n_faces)?;
                        for body in [&vertices, &faces] {
                            std::io::copy(&mut File::open(body)?, &mut w)?;
                        }
                        Ok(())
                    })?;
                    for body in [vertices, faces] {
                        std::fs::remove_file(&body).map_err(|e| Error::output(&body, e))?;
                    }
                }
                Ok(())
            }
        }
    }

    /// Remove what was written (an event whose volume failed has no solids).
    pub(crate) fn discard(self) -> Result<()> {
        if let State::Parts(parts) = self.state {
            for p in *parts {
                for body in [p.vertices, p.faces] {
                    let path = flushed(body)?;
                    std::fs::remove_file(&path).map_err(|e| Error::output(&path, e))?;
                }
            }
        }
        Ok(())
    }
}

/// The file's path once its buffer is written.
fn flushed((path, mut w): (PathBuf, BufWriter<File>)) -> Result<PathBuf> {
    w.flush().map_err(|e| Error::output(&path, e))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{Store, UnitRef};

    /// A closed tetrahedron moved by `d`.
    fn tetra(d: f64) -> Mesh {
        Mesh {
            vertices: vec![
                [d, 0.0, 0.0],
                [d + 1.0, 0.0, 0.0],
                [d, 1.0, 0.0],
                [d, 0.0, 1.0],
            ],
            faces: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    /// Pieces appended to temporary files make the PLY of their union (indices moved by the
    /// pieces before), byte for byte what one mesh of them all writes; the unit then holds only
    /// its two files (a commit refuses a stray temporary file). One piece is written as it
    /// always was; a failed event leaves nothing.
    #[test]
    fn pieces_make_the_ply_of_their_union_and_leave_nothing_behind() {
        let tmp = tempfile::tempdir().unwrap();
        let store = Store::open(&tmp.path().join("out"), true).unwrap();
        let mut out = store.begin(&UnitRef::new("volumes", "t").unwrap()).unwrap();
        let union = |ds: &[f64]| {
            let mut m = Mesh::default();
            for &d in ds {
                let n = m.vertices.len() as u32;
                let t = tetra(d);
                m.vertices.extend(t.vertices);
                m.faces.extend(t.faces.iter().map(|f| f.map(|i| i + n)));
            }
            m
        };
        let mut pieced = EventSolids::new(&mut out, 7, true).unwrap();
        for d in [0.0, 2.0, 4.0] {
            pieced.push([tetra(d), tetra(d + 10.0)]).unwrap();
        }
        pieced.finish(&mut out).unwrap();
        let mut whole = EventSolids::new(&mut out, 8, false).unwrap();
        whole.push([tetra(0.0), tetra(1.0)]).unwrap();
        assert!(
            whole.push([tetra(0.0), tetra(1.0)]).is_err(),
            "one piece, one pair"
        );
        let mut held = EventSolids::new(&mut out, 9, false).unwrap();
        held.push([tetra(0.0), tetra(1.0)]).unwrap();
        held.finish(&mut out).unwrap();
        let mut failed = EventSolids::new(&mut out, 10, true).unwrap();
        failed.push([tetra(0.0), tetra(1.0)]).unwrap();
        failed.discard().unwrap();
        let bytes = |m: &Mesh| {
            let mut b = Vec::new();
            mesh_ply::write_ply_to(&mut b, m).unwrap();
            b
        };
        let read = |name: &str| std::fs::read(out.path(name).unwrap()).unwrap();
        let [b7, a7] = crate::units::volumes::mesh_files(7);
        assert_eq!(read(&b7), bytes(&union(&[0.0, 2.0, 4.0])));
        assert_eq!(read(&a7), bytes(&union(&[10.0, 12.0, 14.0])));
        let [b9, a9] = crate::units::volumes::mesh_files(9);
        assert_eq!(read(&b9), bytes(&tetra(0.0)));
        assert_eq!(read(&a9), bytes(&tetra(1.0)));
        let back = mesh_ply::read_ply_mesh(&out.path(&b7).unwrap()).unwrap();
        crate::volume::check_watertight(&back).unwrap();
        out.commit(serde_json::Value::Null, None).unwrap();
    }
}
