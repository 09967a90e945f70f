//! A user-supplied surface mesh (PLY, global coordinates; `--before-mesh/--after-mesh`, as in
//! Gorup & Bohak, who let the user bring meshes from their own reconstruction) used as a
//! height field in the event frame.
//!
//! At (u, v) a ray parallel to w is intersected with every triangle whose (u, v) projection
//! contains the point; the height is the *topmost* hit (largest w). w is the outward normal
//! of the event, so the topmost hit is the outer skin of the terrain, the surface a scanner
//! or a 2.5-D triangulation of the points sees; inner layers of a closed or folded mesh
//! (the underside of an overhang, the back of a boulder) are ignored, as they are for points.
//! Triangles are binned in a uniform (u, v) grid over the footprint so a query tests only the
//! few triangles of its bin. Triangles seen edge-on (zero projected area) are skipped: a
//! vertical wall has no height of its own, the triangles on either side give it.

use super::frame::{Footprint, Frame};
use super::solid::Mesh;
use super::surface::Surface;

/// A mesh in the event frame, ready for vertical ray queries.
#[derive(Debug, Clone)]
pub struct UserMesh {
    tris: Vec<[[f64; 3]; 3]>,
    r: Footprint,
    n: usize,
    bins: Vec<Vec<u32>>,
}

impl UserMesh {
    /// Take the triangles of `mesh` (global coordinates) that overlap `r` (a footprint in
    /// `frame`, e.g. already grown) and index them.
    pub fn new(mesh: &Mesh, frame: &Frame, r: &Footprint) -> Self {
        let local: Vec<[f64; 3]> = mesh.vertices.iter().map(|p| frame.to_local(p)).collect();
        let tris: Vec<[[f64; 3]; 3]> = mesh
            .faces
            .iter()
            .filter(|f| f.iter().all(|&i| (i as usize) < local.len()))
            .map(|f| f.map(|i| local[i as usize]))
            .filter(|t| {
                let (lo_u, hi_u) = minmax(t.map(|p| p[0]));
                let (lo_v, hi_v) = minmax(t.map(|p| p[1]));
                hi_u >= r.u0 && lo_u <= r.u1 && hi_v >= r.v0 && lo_v <= r.v1
            })
            .collect();
        // About 4 triangles per bin on average, at most 1024 bins a side.
        let n = ((tris.len() as f64 / 4.0).sqrt().ceil() as usize).clamp(1, 1024);
        let mut bins = vec![Vec::new(); n * n];
        let bin = |x: f64, lo: f64, hi: f64| -> usize {
            (((x - lo) / (hi - lo) * n as f64).floor().max(0.0) as usize).min(n - 1)
        };
        for (k, t) in tris.iter().enumerate() {
            let (lo_u, hi_u) = minmax(t.map(|p| p[0]));
            let (lo_v, hi_v) = minmax(t.map(|p| p[1]));
            for j in bin(lo_v, r.v0, r.v1)..=bin(hi_v, r.v0, r.v1) {
                for i in bin(lo_u, r.u0, r.u1)..=bin(hi_u, r.u0, r.u1) {
                    bins[j * n + i].push(k as u32);
                }
            }
        }
        UserMesh {
            tris,
            r: *r,
            n,
            bins,
        }
    }
}

fn minmax(x: [f64; 3]) -> (f64, f64) {
    (x[0].min(x[1]).min(x[2]), x[0].max(x[1]).max(x[2]))
}

impl Surface for UserMesh {
    /// The topmost intersection of the ray along w at (u, v); `None` off the mesh.
    fn height_at(&self, u: f64, v: f64) -> Option<f64> {
        let r = &self.r;
        if !r.contains(u, v) {
            return None;
        }
        let n = self.n;
        let bin = |x: f64, lo: f64, hi: f64| -> usize {
            (((x - lo) / (hi - lo) * n as f64).floor().max(0.0) as usize).min(n - 1)
        };
        let (i, j) = (bin(u, r.u0, r.u1), bin(v, r.v0, r.v1));
        let mut best: Option<f64> = None;
        for &k in &self.bins[j * n + i] {
            let [a, b, c] = self.tris[k as usize];
            let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
            if det == 0.0 {
                continue;
            }
            let l1 = ((u - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (v - a[1])) / det;
            let l2 = ((b[0] - a[0]) * (v - a[1]) - (u - a[0]) * (b[1] - a[1])) / det;
            let l0 = 1.0 - l1 - l2;
            // Closed test with a small tolerance so rays through shared edges hit.
            let tol = -1e-12;
            if l0 >= tol && l1 >= tol && l2 >= tol {
                let w = l0 * a[2] + l1 * b[2] + l2 * c[2];
                best = Some(best.map_or(w, |m: f64| m.max(w)));
            }
        }
        best
    }
}
