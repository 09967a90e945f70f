//! Closed solids between a surface and a base plane, and their volumes.
//!
//! A *top* is a triangulated height field over an event's region (a union of the footprint's
//! cells, `Region`), facing +w. It is closed into a solid by vertical walls under its boundary
//! edges, down to a base plane w = base below both epochs, and a bottom (a fan from the base
//! centre). Every edge of the result is shared by exactly two faces with opposite directions:
//! walls pair with the top's boundary edges, the bottom fan with the walls' lower edges. The
//! volume is then exact by the divergence theorem, V = Σ v0·(v1×v2)/6 over the faces (the
//! solid's signed volume), whatever the region's shape (holes, several parts, parts touching at
//! a corner); the fan's triangles may overlap in the base plane, where their signed areas still
//! add up to the region's.
//!
//! Two tops:
//! - `clipped_top` (points → [`Tin`](super::surface::Tin)): every TIN triangle clipped to each
//!   region cell it overlaps (Sutherland & Hodgman 1974). The volume is the exact integral of the
//!   piecewise-linear TIN over the region, so vertical steps (box sides, cliff scars) are kept
//!   where the wall points put them. (A plain grid resampling would move each step to the nearest
//!   grid line: up to height × cell/2 per metre of wall, i.e. up to 3 % on the 4 × 3 × 1.5 m test
//!   box at cell = spacing/2; that is why points are not resampled.) What remains is a zero-mean
//!   sampling error: the triangles joining the last top (or ground) points to the wall points
//!   take the random heights of those wall points over about half a spacing; on the test box
//!   (10 cm spacing) its standard deviation is 0.35 % of the volume.
//!   New vertices are labelled by what they are (a TIN vertex, a TIN edge ∩ a grid line, a grid
//!   node) and shared by label, so neighbouring pieces share them exactly and the top is
//!   watertight by construction. Heights on clipped edges are interpolated along the edge (never
//!   through a triangle's area, so slivers cannot blow up).
//! - `grid_top` (any `Surface`, e.g. a user mesh): heights sampled on a regular grid over
//!   the region (2 triangles per square).

use rustc_hash::FxHashMap as HashMap;
use smallvec::SmallVec;

use super::boundary;
use super::frame::Footprint;
use super::region::{Cells, Region};
use super::surface::Surface;
use crate::geom::Bounds;

/// A triangle mesh (local or global coordinates, counter-clockwise = outward).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    pub vertices: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
}

/// Signed volume by the divergence theorem (positive for an outward-oriented closed mesh).
/// Computed relative to the first vertex to keep precision with large coordinates.
pub fn signed_volume(mesh: &Mesh) -> f64 {
    let Some(o) = mesh.vertices.first().copied() else {
        return 0.0;
    };
    let rel = |i: u32| -> [f64; 3] {
        let p = mesh.vertices[i as usize];
        [p[0] - o[0], p[1] - o[1], p[2] - o[2]]
    };
    mesh.faces
        .iter()
        .map(|f| {
            let (a, b, c) = (rel(f[0]), rel(f[1]), rel(f[2]));
            let cross = [
                b[1] * c[2] - b[2] * c[1],
                b[2] * c[0] - b[0] * c[2],
                b[0] * c[1] - b[1] * c[0],
            ];
            a[0] * cross[0] + a[1] * cross[1] + a[2] * cross[2]
        })
        .sum::<f64>()
        / 6.0
}

/// A grid line of the region's cells: u = cells.u(i) or v = cells.v(j).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Line {
    U(u32),
    V(u32),
}

/// What a clipped vertex is; equal labels are the same vertex.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Label {
    Vertex(u32),
    /// TIN edge (a < b) ∩ a grid line.
    Cross(u32, u32, Line),
    /// Grid node (i, j).
    Node(u32, u32),
}

/// The line a polygon edge lies on.
#[derive(Debug, Clone, Copy)]
enum Carrier {
    Edge(u32, u32),
    Line(Line),
}

/// One side of a cell: the half-plane p[axis] ≥ value (`lower`) or ≤ value.
#[derive(Debug, Clone, Copy)]
struct Side {
    line: Line,
    axis: usize,
    value: f64,
    lower: bool,
}

impl Side {
    fn inside(&self, p: &[f64; 3]) -> bool {
        if self.lower {
            p[self.axis] >= self.value
        } else {
            p[self.axis] <= self.value
        }
    }
}

/// A vertex of a clipped polygon: its label, position, and the line of the edge to the next.
type Corner3 = (Label, [f64; 3], Carrier);

/// A triangle clipped by a cell's four sides has at most 3 + 4 corners (each side of a convex
/// polygon adds at most one): held in place, not allocated for each triangle and cell it
/// overlaps. Rounding can leave a clipped polygon a hair from convex, so more corners are not
/// impossible: they go to the heap instead of past the end.
type Polygon = SmallVec<[Corner3; 8]>;

/// Each vertex of a top by its label: TIN vertices and grid nodes in tables by their index (4
/// bytes each), only the crossings in a hash map (a map of every label was most of a large
/// event's peak: 20-byte keys in a table that doubles).
struct Ids {
    vertices: Vec<u32>,
    nodes: Vec<u32>,
    /// Nodes a row (nu + 1).
    row: usize,
    crossings: HashMap<(u32, u32, Line), u32>,
}

impl Ids {
    const NONE: u32 = u32::MAX;

    fn new(tin_vertices: usize, cells: &Cells) -> Ids {
        Ids {
            vertices: vec![Ids::NONE; tin_vertices],
            nodes: vec![Ids::NONE; (cells.nu + 1) * (cells.nv + 1)],
            row: cells.nu + 1,
            crossings: HashMap::default(),
        }
    }

    /// The id of the vertex labelled `label`, added to `top` at `pos` the first time.
    fn id(&mut self, label: Label, pos: [f64; 3], top: &mut Mesh) -> u32 {
        let mut add = || {
            top.vertices.push(pos);
            (top.vertices.len() - 1) as u32
        };
        let slot = match label {
            Label::Vertex(a) => &mut self.vertices[a as usize],
            Label::Node(i, j) => &mut self.nodes[j as usize * self.row + i as usize],
            Label::Cross(a, b, l) => return *self.crossings.entry((a, b, l)).or_insert_with(add),
        };
        if *slot == Ids::NONE {
            *slot = add();
        }
        *slot
    }
}

/// Top surface: the triangles of `tin_vertices`/`tin_faces` (counter-clockwise in (u, v))
/// clipped to the cells of `region` (Sutherland & Hodgman 1974, one cell at a time). The integral
/// of the result is the exact integral of the TIN over the region. Returns local vertices and
/// faces.
///
/// A triangle inside the region (every cell its box overlaps is a region cell, the box inside the
/// footprint) is kept whole: cutting it along the grid lines would change neither its integral
/// nor the boundary, only multiply the faces (about four pieces a triangle at cells of one point
/// spacing: most of the time and the solids' bytes went there). Only the triangles the region's
/// edge passes through are cut. Where a whole triangle shares an edge with a cut one, the cut one
/// put vertices on that edge (where grid lines cross it); the whole one takes the same vertices,
/// as a fan from its centroid (on its plane, so the integral is unchanged), so every edge still
/// has one face on each side.
pub(crate) fn clipped_top(
    tin_vertices: &[[f64; 3]],
    tin_faces: &[[u32; 3]],
    region: &Region,
) -> Mesh {
    clip_top(tin_vertices, tin_faces, region, true)
}

/// [`clipped_top`], or with `whole` false every triangle cut cell by cell (the reference the
/// whole triangles are tested against).
fn clip_top(
    tin_vertices: &[[f64; 3]],
    tin_faces: &[[u32; 3]],
    region: &Region,
    whole: bool,
) -> Mesh {
    let cells = &region.cells;
    let mut ids = Ids::new(tin_vertices.len(), cells);
    let mut top = Mesh::default();
    // A hair (relative to a cell) by which a triangle's box is grown before it is called whole,
    // so that rounding in the cell lookup cannot leave a sliver of it in a cell outside.
    let hair = 1e-9 * (cells.r.u1 - cells.r.u0).max(cells.r.v1 - cells.r.v0);
    let is_whole = |b: &Bounds| -> bool {
        let (lo, hi) = (b.min.map(|x| x - hair), b.max.map(|x| x + hair));
        let r = &cells.r;
        if lo[0] < r.u0 || hi[0] > r.u1 || lo[1] < r.v0 || hi[1] > r.v1 {
            return false;
        }
        let (iu, iv) = cells.overlapping(lo[0], hi[0], lo[1], hi[1]);
        iv.into_iter()
            .all(|j| iu.clone().all(|i| region.contains(i, j)))
    };
    // TIN edge ∩ grid line, always computed from the smaller index so that both triangles of an
    // edge get the same bits; an end of the edge when the line passes through it.
    let cross = |a: u32, b: u32, side: &Side| -> (Label, [f64; 3]) {
        let (a, b) = (a.min(b), a.max(b));
        let (pa, pb) = (tin_vertices[a as usize], tin_vertices[b as usize]);
        let k = side.axis;
        let den = pb[k] - pa[k];
        let t = if den != 0.0 {
            ((side.value - pa[k]) / den).clamp(0.0, 1.0)
        } else {
            0.5
        };
        if t == 0.0 {
            return (Label::Vertex(a), pa);
        }
        if t == 1.0 {
            return (Label::Vertex(b), pb);
        }
        let mut p: [f64; 3] = std::array::from_fn(|i| pa[i] + t * (pb[i] - pa[i]));
        p[k] = side.value;
        (Label::Cross(a, b, side.line), p)
    };
    let line_value = |l: Line| match l {
        Line::U(i) => cells.u(i as usize),
        Line::V(j) => cells.v(j as usize),
    };
    // Pass 1: the triangles the region's edge cuts, cell by cell; the whole ones wait until
    // every vertex the cut ones put on shared edges is known.
    let mut whole_faces = Vec::new();
    for f in tin_faces {
        let pts = f.map(|i| tin_vertices[i as usize]);
        let b = Bounds::of(&pts);
        if whole && is_whole(&b) {
            whole_faces.push(*f);
            continue;
        }
        let (iu, iv) = cells.overlapping(b.min[0], b.max[0], b.min[1], b.max[1]);
        for j in iv {
            for i in iu.clone() {
                if !region.contains(i, j) {
                    continue;
                }
                let sides = [
                    Side {
                        line: Line::U(i as u32),
                        axis: 0,
                        value: cells.u(i),
                        lower: true,
                    },
                    Side {
                        line: Line::U(i as u32 + 1),
                        axis: 0,
                        value: cells.u(i + 1),
                        lower: false,
                    },
                    Side {
                        line: Line::V(j as u32),
                        axis: 1,
                        value: cells.v(j),
                        lower: true,
                    },
                    Side {
                        line: Line::V(j as u32 + 1),
                        axis: 1,
                        value: cells.v(j + 1),
                        lower: false,
                    },
                ];
                let mut poly: Polygon = (0..3)
                    .map(|k| {
                        (
                            Label::Vertex(f[k]),
                            pts[k],
                            Carrier::Edge(f[k], f[(k + 1) % 3]),
                        )
                    })
                    .collect();
                for side in &sides {
                    if poly.iter().all(|p| side.inside(&p.1)) {
                        continue;
                    }
                    let mut out = Polygon::new();
                    for n in 0..poly.len() {
                        let (pl, pp, pc) = poly[n];
                        let (_, qp, _) = poly[(n + 1) % poly.len()];
                        let (pin, qin) = (side.inside(&pp), side.inside(&qp));
                        let cut = || -> (Label, [f64; 3]) {
                            match pc {
                                Carrier::Edge(a, b) => cross(a, b, side),
                                Carrier::Line(l0) => {
                                    // A grid node: its height on this triangle's plane (it lies
                                    // inside it; every triangle sharing it agrees up to rounding,
                                    // and the first one wins).
                                    let (ni, nj) = match (l0, side.line) {
                                        (Line::U(i), Line::V(j)) | (Line::V(j), Line::U(i)) => {
                                            (i, j)
                                        }
                                        // Parallel lines never cross inside a cell.
                                        _ => unreachable!("a cell side cut by a parallel line"),
                                    };
                                    let (u, v) = (line_value(Line::U(ni)), line_value(Line::V(nj)));
                                    (Label::Node(ni, nj), [u, v, plane_height(&pts, u, v)])
                                }
                            }
                        };
                        match (pin, qin) {
                            (true, true) => out.push((pl, pp, pc)),
                            (true, false) => {
                                out.push((pl, pp, pc));
                                let (l, p) = cut();
                                out.push((l, p, Carrier::Line(side.line)));
                            }
                            (false, true) => {
                                let (l, p) = cut();
                                out.push((l, p, pc));
                            }
                            (false, false) => {}
                        }
                    }
                    poly = out;
                    if poly.len() < 3 {
                        break;
                    }
                }
                if poly.len() < 3 {
                    continue;
                }
                let ids: SmallVec<[u32; 8]> = poly
                    .iter()
                    .map(|&(l, p, _)| ids.id(l, p, &mut top))
                    .collect();
                for k in 1..ids.len() - 1 {
                    let tri = [ids[0], ids[k], ids[k + 1]];
                    if tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2] {
                        top.faces.push(tri);
                    }
                }
            }
        }
    }
    // Pass 2: the whole triangles, each with the vertices cut neighbours put on its edges.
    for f in &whole_faces {
        let mut ring: SmallVec<[u32; 12]> = SmallVec::new();
        let mut cut = false;
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            ring.push(ids.id(Label::Vertex(a), tin_vertices[a as usize], &mut top));
            if ids.crossings.is_empty() {
                continue;
            }
            let (lo, hi) = (a.min(b), a.max(b));
            let (pa, pb) = (tin_vertices[a as usize], tin_vertices[b as usize]);
            let mut on_edge: SmallVec<[(f64, u32); 4]> = SmallVec::new();
            // The grid lines the edge crosses: those bounding the cells its box overlaps, within
            // its extent.
            let (ulo, uhi) = (pa[0].min(pb[0]) - hair, pa[0].max(pb[0]) + hair);
            let (vlo, vhi) = (pa[1].min(pb[1]) - hair, pa[1].max(pb[1]) + hair);
            let (iu, iv) = cells.overlapping(ulo, uhi, vlo, vhi);
            let lines = (iu.start..=iu.end)
                .filter(|&i| (ulo..=uhi).contains(&cells.u(i)))
                .map(|i| Line::U(i as u32))
                .chain(
                    (iv.start..=iv.end)
                        .filter(|&j| (vlo..=vhi).contains(&cells.v(j)))
                        .map(|j| Line::V(j as u32)),
                );
            for l in lines {
                if let Some(&id) = ids.crossings.get(&(lo, hi, l)) {
                    let p = top.vertices[id as usize];
                    // Position along a → b.
                    let t = (p[0] - pa[0]) * (pb[0] - pa[0]) + (p[1] - pa[1]) * (pb[1] - pa[1]);
                    on_edge.push((t, id));
                }
            }
            on_edge.sort_by(|x, y| x.0.total_cmp(&y.0));
            cut |= !on_edge.is_empty();
            ring.extend(on_edge.iter().map(|e| e.1));
        }
        if !cut {
            top.faces.push([ring[0], ring[1], ring[2]]);
            continue;
        }
        let pts = f.map(|i| tin_vertices[i as usize]);
        top.vertices.push(std::array::from_fn(|k| {
            (pts[0][k] + pts[1][k] + pts[2][k]) / 3.0
        }));
        let g = (top.vertices.len() - 1) as u32;
        for k in 0..ring.len() {
            top.faces.push([g, ring[k], ring[(k + 1) % ring.len()]]);
        }
    }
    // Grown by doubling: give back the unused half (a large fan holds tens of MB here).
    top.vertices.shrink_to_fit();
    top.faces.shrink_to_fit();
    top
}

/// Height at (u, v) on the plane through a triangle; a degenerate triangle gives the mean of
/// its vertex heights (a node inside a sliver: any value on the sliver is as good).
fn plane_height(t: &[[f64; 3]; 3], u: f64, v: f64) -> f64 {
    let (a, b, c) = (t[0], t[1], t[2]);
    let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
    let scale =
        ((b[0] - a[0]).abs() + (c[0] - a[0]).abs() + (b[1] - a[1]).abs() + (c[1] - a[1]).abs())
            .powi(2);
    if det.abs() <= 1e-12 * scale || det == 0.0 {
        return (a[2] + b[2] + c[2]) / 3.0;
    }
    let l1 = ((u - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (v - a[1])) / det;
    let l2 = ((b[0] - a[0]) * (v - a[1]) - (u - a[0]) * (b[1] - a[1])) / det;
    a[2] + l1 * (b[2] - a[2]) + l2 * (c[2] - a[2])
}

/// Sub-samples per grid node along each axis (see [`grid_top`]).
const SUB: usize = 4;

/// Top surface sampled from `surface` over the region's cells, each cut into `split × split`
/// squares (2 triangles each). Each node takes the mean height over its dual cell (the square
/// around it, clipped to the region), sampled at SUB × SUB midpoints: the integral of the
/// triangulated grid is Σ node height × dual-cell area, so it equals a midpoint-rule integral SUB
/// times finer, and a vertical step is misplaced by at most a square's side / (2·SUB) instead of
/// half of it. `None` when a node of the region has no height (the region must be covered).
pub(crate) fn grid_top(surface: &dyn Surface, region: &Region, split: usize) -> Option<Mesh> {
    use rayon::prelude::*;
    let c = &region.cells;
    let split = split.max(1);
    let (nu, nv) = (c.nu * split, c.nv * split);
    let (du, dv) = ((c.r.u1 - c.r.u0) / nu as f64, (c.r.v1 - c.r.v0) / nv as f64);
    let fine_in = |i: usize, j: usize| i < nu && j < nv && region.contains(i / split, j / split);
    let node_used = |i: usize, j: usize| {
        (0..2).any(|a| (0..2).any(|b| i + a >= 1 && j + b >= 1 && fine_in(i + a - 1, j + b - 1)))
    };
    let node = |i: usize, j: usize| j * (nu + 1) + i;
    let h: Vec<Option<f64>> = (0..(nu + 1) * (nv + 1))
        .into_par_iter()
        .map(|k| {
            let (i, j) = (k % (nu + 1), k / (nu + 1));
            if !node_used(i, j) {
                return Some(0.0);
            }
            let (uc, vc) = (c.r.u0 + i as f64 * du, c.r.v0 + j as f64 * dv);
            let (mut s, mut n) = (0.0, 0usize);
            for b in 0..SUB {
                let fb = (b as f64 + 0.5) / SUB as f64 - 0.5;
                for a in 0..SUB {
                    let fa = (a as f64 + 0.5) / SUB as f64 - 0.5;
                    // The fine square this sample falls in must be in the region.
                    let (si, sj) = (
                        if fa < 0.0 { i.wrapping_sub(1) } else { i },
                        if fb < 0.0 { j.wrapping_sub(1) } else { j },
                    );
                    if !fine_in(si, sj) {
                        continue;
                    }
                    if let Some(w) = surface
                        .height_at(uc + du * fa, vc + dv * fb)
                        .filter(|w| w.is_finite())
                    {
                        s += w;
                        n += 1;
                    }
                }
            }
            if n > 0 {
                Some(s / n as f64)
            } else {
                surface.height_at(uc, vc).filter(|w| w.is_finite())
            }
        })
        .collect();
    if h.iter().any(|x| x.is_none()) {
        return None;
    }
    let mut top = Mesh::default();
    let mut id: HashMap<usize, u32> = HashMap::default();
    let mut vertex = |i: usize, j: usize, top: &mut Mesh| -> u32 {
        *id.entry(node(i, j)).or_insert_with(|| {
            top.vertices.push([
                c.r.u0 + i as f64 * du,
                c.r.v0 + j as f64 * dv,
                h[node(i, j)].unwrap_or(0.0),
            ]);
            (top.vertices.len() - 1) as u32
        })
    };
    for j in 0..nv {
        for i in 0..nu {
            if !fine_in(i, j) {
                continue;
            }
            let a = vertex(i, j, &mut top);
            let b = vertex(i + 1, j, &mut top);
            let cc = vertex(i + 1, j + 1, &mut top);
            let d = vertex(i, j + 1, &mut top);
            top.faces.push([a, b, cc]);
            top.faces.push([a, cc, d]);
        }
    }
    Some(top)
}

/// Lowest height of a top.
pub(crate) fn min_height(top: &Mesh) -> f64 {
    top.vertices
        .iter()
        .map(|p| p[2])
        .fold(f64::INFINITY, f64::min)
}

/// Close a top into a solid: walls under its boundary edges down to w = `base`, and a
/// bottom fan from the base point under the centre of `r`. A top vertex where two parts of the
/// region touch (a pinch) gets one base vertex per loop through it (see [`boundary`]), so every
/// edge of the solid has exactly one face on each side.
/// The directed edges of `faces` whose reverse is not an edge of any face: the boundary, in no
/// particular order. Found by sorting the edges by their vertex pair, each packed in 8 bytes
/// (a hash map of the same edges costs about eight times the memory and most of the time on a
/// fan of millions of faces; a (pair, direction) tuple is padded to 16): the smaller vertex,
/// the larger, and whether this copy runs from the smaller to the larger in the lowest bit.
fn boundary_edges(faces: &[[u32; 3]]) -> Vec<(u32, u32)> {
    // Vertex indices below 2^31 (a mesh of fewer than two billion vertices) leave room for
    // the direction bit.
    let mut all: Vec<u64> = faces
        .iter()
        .flat_map(|f| (0..3).map(move |k| (f[k], f[(k + 1) % 3])))
        .map(|(a, b)| (u64::from(a.min(b)) << 33) | (u64::from(a.max(b)) << 1) | u64::from(a < b))
        .collect();
    all.sort_unstable();
    let mut edges = Vec::new();
    for group in all.chunk_by(|x, y| x >> 1 == y >> 1) {
        let (up, down) = (
            group.iter().any(|e| e & 1 == 1),
            group.iter().any(|e| e & 1 == 0),
        );
        let (lo, hi) = (
            (group[0] >> 33) as u32,
            ((group[0] >> 1) & 0xffff_ffff) as u32,
        );
        // A loop edge (a, a) is its own reverse.
        if up != down && lo != hi {
            edges.push(if up { (lo, hi) } else { (hi, lo) });
        }
    }
    edges
}

pub(crate) fn close(top: Mesh, base: f64, r: &Footprint) -> Mesh {
    let mut edges = boundary_edges(&top.faces);
    edges.sort_unstable();
    let next = boundary::successors(&edges, |v| {
        let p = top.vertices[v as usize];
        [p[0], p[1]]
    });
    let mut pred = vec![None; edges.len()];
    for (k, n) in next.iter().enumerate() {
        if let Some(n) = *n {
            pred[n] = Some(k);
        }
    }
    /// Which base vertex: the one at the end of boundary edge k, or a vertex's own where the
    /// boundary is not a closed loop.
    #[derive(Clone, Copy, PartialEq, Eq, Hash)]
    enum Corner {
        End(usize),
        Loose(u32),
    }
    // The top grows into the solid in place: a vertex below every boundary vertex and the
    // centre (two where the boundary is not a loop), three faces per boundary edge, reserved at once (no doubling, no copy).
    let mut solid = top;
    solid.vertices.reserve_exact(2 * edges.len() + 1);
    solid.faces.reserve_exact(3 * edges.len());
    let mut below: HashMap<Corner, u32> = HashMap::default();
    let mut base_of = |corner: Corner, a: u32, solid: &mut Mesh| -> u32 {
        *below.entry(corner).or_insert_with(|| {
            let p = solid.vertices[a as usize];
            solid.vertices.push([p[0], p[1], base]);
            (solid.vertices.len() - 1) as u32
        })
    };
    solid
        .vertices
        .push([0.5 * (r.u0 + r.u1), 0.5 * (r.v0 + r.v1), base]);
    let centre = (solid.vertices.len() - 1) as u32;
    for (k, &(a, b)) in edges.iter().enumerate() {
        let start = pred[k].map_or(Corner::Loose(a), Corner::End);
        let end = if next[k].is_some() {
            Corner::End(k)
        } else {
            Corner::Loose(b)
        };
        let (a2, b2) = (base_of(start, a, &mut solid), base_of(end, b, &mut solid));
        solid.faces.push([a, a2, b2]);
        solid.faces.push([a, b2, b]);
        solid.faces.push([centre, b2, a2]);
    }
    solid
}

/// Is `mesh` a closed, consistently oriented, outward-facing solid? Every undirected edge
/// must be used by exactly two faces, once in each direction, and the signed volume must be
/// positive. The message names the first problem found.
pub fn check_watertight(mesh: &Mesh) -> std::result::Result<(), String> {
    use rustc_hash::FxHashMap as HashMap;
    let mut directed: HashMap<(u32, u32), u32> = HashMap::default();
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
    let v = signed_volume(mesh);
    if v.is_nan() || v <= 0.0 {
        return Err(format!("signed volume {v} is not positive"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::surface::Tin;

    use crate::volume::region::Cells;

    fn random_flat_tin(w: f64) -> Tin {
        let mut pts = Vec::new();
        let mut s = 12345u64;
        let mut f = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..4000 {
            pts.push([f() * 10.0 - 5.0, f() * 10.0 - 5.0, w]);
        }
        Tin::new(&pts).unwrap()
    }

    fn projected_area(top: &Mesh) -> f64 {
        top.faces
            .iter()
            .map(|t| {
                let (a, b, c) = (
                    top.vertices[t[0] as usize],
                    top.vertices[t[1] as usize],
                    top.vertices[t[2] as usize],
                );
                0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
            })
            .sum()
    }

    #[test]
    fn flat_tin_clipped_solid_volume() {
        let tin = random_flat_tin(0.5);
        let (v, fc) = tin.mesh();
        let r = Footprint {
            u0: -2.31,
            u1: 2.31,
            v0: -1.9,
            v1: 1.9,
        };
        let cells = Cells::new(&r, 0.37);
        let all = vec![true; cells.len()];
        let region = Region::new(cells, all.clone(), &all);
        let top = clipped_top(&v, &fc, &region);
        let solid = close(top.clone(), 0.0, &r);
        check_watertight(&solid).unwrap();
        assert!((projected_area(&top) - r.area()).abs() < 1e-9);
        assert!((signed_volume(&solid) - 0.5 * r.area()).abs() < 1e-9);
    }

    /// Whole triangles against every triangle cut cell by cell, on a rough TIN (random heights:
    /// a wrong height anywhere would move the volume) with cells of about one point spacing and
    /// a region with holes, pinches and a ragged edge: the same volume and area, watertight,
    /// and far fewer faces.
    #[test]
    fn whole_triangles_keep_the_cut_volume() {
        let mut rng = crate::rng::SplitMix64::new(987654321);
        let mut f = || rng.uniform();
        let pts: Vec<[f64; 3]> = (0..6000)
            .map(|_| [f() * 10.0 - 5.0, f() * 10.0 - 5.0, 0.5 + f()])
            .collect();
        let (v, fc) = Tin::new(&pts).unwrap().mesh();
        let r = Footprint {
            u0: -4.1,
            u1: 3.9,
            v0: -3.7,
            v1: 4.2,
        };
        // 6000 points over 100 m²: spacing ≈ 0.13 m; cells of that size.
        let cells = Cells::new(&r, 0.13);
        // Holes scattered over 8 % of the cells (nearly every triangle is cut), and none (only
        // the footprint's edge is cut).
        let ragged: Vec<bool> = (0..cells.len()).map(|_| f() > 0.08).collect();
        for (owned, fewer) in [(ragged, 1.5), (vec![true; cells.len()], 3.0)] {
            let region = Region::new(cells, vec![true; cells.len()], &owned);
            let cut = clip_top(&v, &fc, &region, false);
            let whole = clipped_top(&v, &fc, &region);
            let (sc, sw) = (close(cut.clone(), 0.0, &r), close(whole.clone(), 0.0, &r));
            check_watertight(&sc).unwrap();
            check_watertight(&sw).unwrap();
            let (vc, vw) = (signed_volume(&sc), signed_volume(&sw));
            assert!((vc - vw).abs() < 1e-9 * vc, "{vc} vs {vw}");
            assert!((projected_area(&whole) - region.area()).abs() < 1e-9);
            assert!(
                whole.faces.len() as f64 * fewer < cut.faces.len() as f64,
                "{} whole vs {} cut faces",
                whole.faces.len(),
                cut.faces.len()
            );
        }
    }

    #[test]
    fn region_with_holes_and_pinches_is_watertight_and_exact() {
        let tin = random_flat_tin(0.25);
        let (v, fc) = tin.mesh();
        let r = Footprint {
            u0: -3.0,
            u1: 3.0,
            v0: -2.0,
            v1: 2.5,
        };
        let cells = Cells::new(&r, 0.5);
        // A checkerboard in one corner (pinches everywhere), a hole in the middle, the rest in.
        let owned: Vec<bool> = (0..cells.len())
            .map(|k| {
                let (i, j) = (k % cells.nu, k / cells.nu);
                if i < 4 && j < 4 {
                    (i + j) % 2 == 0
                } else {
                    !((6..8).contains(&i) && (5..7).contains(&j))
                }
            })
            .collect();
        let region = Region::new(cells, vec![true; cells.len()], &owned);
        let top = clipped_top(&v, &fc, &region);
        let solid = close(top.clone(), -1.0, &r);
        check_watertight(&solid).unwrap();
        assert!((projected_area(&top) - region.area()).abs() < 1e-9);
        assert!((signed_volume(&solid) - 1.25 * region.area()).abs() < 1e-9);
        // The grid top over the same region closes the same way.
        let grid = grid_top(&tin, &region, 2).unwrap();
        let solid = close(grid.clone(), -1.0, &r);
        check_watertight(&solid).unwrap();
        assert!((signed_volume(&solid) - 1.25 * region.area()).abs() < 1e-9);
    }
}
