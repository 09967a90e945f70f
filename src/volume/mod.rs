//! Event volumes (SPEC.md §1 "Volume" and "Volume accounting"; Gorup & Bohak §3.5, with the
//! fixes of SPEC.md §4): the volume between the before (C1) and after (C2) surfaces over the
//! event's region.
//!
//! Method, per event:
//! 1. Frame: the event's OBB axes (u, v, w), w = outward normal (`frame`).
//! 2. Footprint: the OBB's first two extents grown by `margin` on every side, so the rim of
//!    the change lies inside; the same rectangle R for both epochs.
//! 3. Surfaces: each epoch's points near the event, in (u, v, w), triangulated in (u, v)
//!    (2.5-D Delaunay TIN, `surface`); no height outside the data's hull.
//! 4. Region (`region`): the cells of R that both epochs cover (no hole, nothing beyond the
//!    data) and that no other event owns (`ownership`).
//! 5. Solids: each TIN clipped exactly to the region's cells, closed by walls down to one common
//!    base plane below both surfaces and a bottom: two watertight solids ([`solid`]).
//! 6. Volume of each solid by the divergence theorem; V = V(after) − V(before), positive for
//!    gain (the after surface lies further out along w). The base cancels in the difference.
//! 7. Gross gain and loss: ∫ max(Δw, 0) and ∫ min(Δw, 0) over the region, Δw = w_after −
//!    w_before, by the midpoint rule on sub-cells of about spacing/2. (Net V is exact for the
//!    TINs; gain + loss equals it up to the sampling of the steps.)
//!
//! An event of more than [`PIECE_CELLS`] cells is measured in bands of whole rows or whole
//! columns of cells, whichever puts fewer points into its fullest band ([`pieces`]; steps 3 to 6
//! per band, each with the points 8 spacings around it, each band's solids closed
//! over its own base; the volumes added up), and the region, its open rim and step variance from
//! the whole grid's flags and changes: what one event holds is a band's surfaces and solids and a
//! few bytes a cell of the whole, not its surfaces and solids whole. A band's triangulation is the
//! whole one's inside it wherever the Delaunay circle of a triangle there stays within the 8
//! spacings (every triangle of the tests' scenes, walls and noise of 2.5 spacings among them).
//!
//! Callers pass each epoch's points around the event: at least R grown by a few spacings in
//! (u, v) (extra points are ignored beyond 3 spacings), and along w far enough to hold both
//! surfaces (at least the M3C2 cylinder half-length, since a distance can reach it), and say
//! which locations the event owns. Everything here is a pure function of its inputs (Send +
//! Sync), for rayon.

pub(crate) mod axis;
pub(crate) mod boundary;
pub(crate) mod frame;
pub(crate) mod ownership;
pub(crate) mod region;
pub(crate) mod search;
pub mod solid;
pub(crate) mod surface;
pub(crate) mod uncertainty;
pub(crate) mod user_mesh;

pub use frame::{Footprint, Frame};
pub(crate) use ownership::{Claim, Ownership};
pub use region::Cut;
pub(crate) use region::{Cells, Region};
pub(crate) use search::Search;
pub use solid::check_watertight;
pub use solid::Mesh;
pub use surface::Tin;
pub(crate) use surface::{Lattice, Surface};
pub use user_mesh::UserMesh;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::events::Obb;

/// Which locations (global coordinates, on the before surface) an event may count.
pub(crate) type Owned<'a> = &'a (dyn Fn(&[f64; 3]) -> bool + Sync);

/// The volume of one event and its two solids.
#[derive(Debug, Clone, PartialEq)]
pub struct EventVolume {
    /// V(after) − V(before) over the region, m³ for metric input (loss < 0).
    pub volume_m3: f64,
    /// ∫ max(Δw, 0) over the region (≥ 0).
    pub gain_m3: f64,
    /// ∫ min(Δw, 0) over the region (≤ 0).
    pub loss_m3: f64,
    /// Area of the footprint rectangle.
    pub footprint_area_m2: f64,
    /// Area of the region the volume is integrated over.
    pub region_area_m2: f64,
    /// Share of the footprint both epochs cover (0..1).
    pub coverage: f64,
    /// The footprint in the event frame.
    pub(crate) footprint: Footprint,
    /// The region's cells.
    pub region: Region,
    /// The frame (origin, axes) the footprint is expressed in.
    pub(crate) frame: Frame,
    /// The common base plane, w = base_w in the frame (in pieces, the lowest of theirs).
    pub(crate) base_w: f64,
    /// Volumes of the two solids above the base (summed over the pieces, each over its own
    /// base).
    pub(crate) before_solid_m3: f64,
    pub(crate) after_solid_m3: f64,
    /// Points of each epoch used (inside the footprint grown by 3 spacings; in pieces, summed
    /// over the bands grown by 3 spacings, so a point near a seam counts twice).
    pub(crate) n_before: usize,
    pub(crate) n_after: usize,
    /// Points of each epoch inside the region (0 for user meshes).
    pub region_points: [usize; 2],
    /// Where the region borders ground it could not measure, and how much changed there.
    pub(crate) open_rim: region::OpenRim,
    /// The variance of the volume from where the points sample its steps (m⁶,
    /// `Region::step_variance`).
    pub step_variance_m6: f64,
}

impl EventVolume {
    /// The region's outline in global coordinates: polygons (outer ring, holes) in the
    /// footprint plane (w = 0 of the frame), each ring closed (first vertex repeated).
    pub(crate) fn outline(&self) -> Vec<Vec<Vec<[f64; 3]>>> {
        let ring = |r: &[[f64; 2]]| -> Vec<[f64; 3]> {
            let mut g: Vec<[f64; 3]> = r
                .iter()
                .map(|p| self.frame.to_global(&[p[0], p[1], 0.0]))
                .collect();
            if let Some(&first) = g.first() {
                g.push(first);
            }
            g
        };
        self.region
            .outline()
            .iter()
            .map(|p| {
                std::iter::once(ring(&p.outer))
                    .chain(p.holes.iter().map(|h| ring(h)))
                    .collect()
            })
            .collect()
    }
}

fn check_params(obb: &Obb, margin: f64, spacing: f64) -> Result<()> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !(finite(&obb.center) && finite(&obb.half_extents) && obb.axes.iter().all(|a| finite(a))) {
        return Err(Error::Internal(format!(
            "volume: non-finite event box {obb:?}"
        )));
    }
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(Error::Usage(format!(
            "volume: point spacing must be > 0, got {spacing}"
        )));
    }
    if !(margin.is_finite() && margin >= 0.0) {
        return Err(Error::Usage(format!(
            "volume: margin must be ≥ 0, got {margin}"
        )));
    }
    Ok(())
}

/// Most cells one piece of an event's volume covers: a larger event is measured in bands of
/// whole rows or columns of its cells ([`pieces`]), each with its own triangulations, tops and
/// solids, so what one event holds at a time is bounded by this, not by the event (SPEC.md §3:
/// "a large event measured in pieces"). A constant, never the budget, so an event's numbers do
/// not depend on `--memory`. 2^14 cells are 16 MiB at `units::volumes::BYTES_PER_CELL`, and a
/// band of them takes about a quarter of the points a band of 2^16 would: the 20M-point cliff's
/// debris fan (1.55 M points gathered) needed 173 MiB in bands of 2^16 rows.
pub const PIECE_CELLS: usize = 1 << 14;

/// How far (in spacings) beyond its band a piece triangulates the points: a band's triangles are
/// the whole event's wherever their Delaunay circles stay within it. At 3 spacings (the whole
/// footprint's own margin) a sampling of the face hollow of `tests/events_volume/` (walls, the
/// after survey at half density) came out 2 × 10⁻⁶ off the whole in 14 bands; at 8, to rounding.
const BAND_MARGIN_SPACINGS: f64 = 8.0;

/// How far (in spacings) beyond its band a piece takes points to find the unchanged walls
/// ([`axis::unchanged_walls`]) of the points it triangulates: a wall point's flags look a
/// spacing or two around it, its match two spacings into the other epoch, its column one.
const WALL_REACH_SPACINGS: f64 = BAND_MARGIN_SPACINGS + 5.0;

/// Where each piece's two solids (before, after; global coordinates, each closed on its own) go,
/// in the order of the pieces: an event of one piece has one pair of watertight solids, a larger
/// one a pair per band (their walls on the seams face each other).
pub(crate) type Solids<'a> = &'a mut dyn FnMut([Mesh; 2]) -> Result<()>;

/// The points (global) inside `keep` in the event frame, sorted. The points may come in any
/// order (a tiled run gathers them tile by tile): they are sorted, because the triangulation of
/// ties (points sharing u, v) depends on the insertion order.
fn local_in(frame: &Frame, keep: &Footprint, points: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut local: Vec<[f64; 3]> = points
        .iter()
        .map(|p| frame.to_local(p))
        .filter(|l| l.iter().all(|x| x.is_finite()) && keep.contains(l[0], l[1]))
        .collect();
    local.sort_unstable_by(|a, b| {
        a[0].total_cmp(&b[0])
            .then(a[1].total_cmp(&b[1]))
            .then(a[2].total_cmp(&b[2]))
    });
    local
}

/// Both epochs' local points ([`local_in`]) without the unchanged walls
/// ([`axis::unchanged_walls`], the points gathered over `gathered` within |w| ≤ `window`), those
/// inside `tin_keep` (all when None) triangulated.
fn epoch_tins(
    local: [Vec<[f64; 3]>; 2],
    spacing: f64,
    gathered: &Footprint,
    window: f64,
    tin_keep: Option<&Footprint>,
) -> Result<[(Tin, Vec<[f64; 3]>); 2]> {
    // Only the window's points: the gather may bring more (other candidate boxes), cut by
    // other faces.
    let local = local.map(|mut l| {
        l.retain(|q| q[2].abs() <= window);
        l
    });
    let drop = axis::unchanged_walls([&local[0], &local[1]], spacing, gathered, window);
    let mut out = Vec::with_capacity(2);
    for ((l, d), epoch) in local.into_iter().zip(&drop).zip(["before", "after"]) {
        let kept: Vec<[f64; 3]> = l
            .into_iter()
            .zip(d)
            .filter(|(p, &d)| !d && tin_keep.is_none_or(|k| k.contains(p[0], p[1])))
            .map(|(p, _)| p)
            .collect();
        let tin = Tin::new(&kept)
            .map_err(|e| Error::Epochs(format!("{epoch} epoch around the event: {e}")))?;
        out.push((tin, kept));
    }
    let after = out.pop().expect("two epochs");
    let before = out.pop().expect("two epochs");
    Ok([before, after])
}

/// The region over `cells`: cells whose four corners and centre both surfaces cover (a TIN's
/// hull is convex, so its corners imply its centre; a user's mesh may have a hole there), that
/// pass `cell_covered` (e.g. a point of each epoch near the centre), and whose location (the
/// centre on the before surface, global) is `owned`.
fn region_of(
    frame: &Frame,
    cells: Cells,
    before: &dyn Surface,
    after: &dyn Surface,
    cell_covered: &(dyn Fn([f64; 2]) -> bool + Sync),
    owned: Owned,
) -> (Region, [Vec<f64>; 2]) {
    let (nu, nv) = (cells.nu, cells.nv);
    // Nodes covered by both surfaces; both surfaces' heights at the centres (the before one's
    // place the cell's owner; both give the change, `change_of`).
    let (nodes, centres) = (Lattice::nodes(&cells), Lattice::centres(&cells));
    let ((h1, h2), (c1, c2)) = rayon::join(
        || rayon::join(|| before.heights_on(&nodes), || after.heights_on(&nodes)),
        || {
            rayon::join(
                || before.heights_on(&centres),
                || after.heights_on(&centres),
            )
        },
    );
    let node = |i: usize, j: usize| {
        let k = j * (nu + 1) + i;
        h1[k].is_finite() && h2[k].is_finite()
    };
    let flags: Vec<(bool, bool)> = (0..nv)
        .into_par_iter()
        .flat_map_iter(|j| {
            let (node, c1, c2) = (&node, &c1, &c2);
            (0..nu).map(move |i| {
                let (c, k) = (cells.centre(i, j), cells.index(i, j));
                let covered = node(i, j)
                    && node(i + 1, j)
                    && node(i, j + 1)
                    && node(i + 1, j + 1)
                    && c1[k].is_finite()
                    && c2[k].is_finite()
                    && cell_covered(c);
                let own = covered && owned(&frame.to_global(&[c[0], c[1], c1[k]]));
                (covered, own)
            })
        })
        .collect();
    let covered = flags.iter().map(|f| f.0).collect();
    let own: Vec<bool> = flags.iter().map(|f| f.1).collect();
    (Region::new(cells, covered, &own), [c1, c2])
}

/// Volume change of one event from the two epochs' points around it (global coordinates;
/// extra points are tolerated), `spacing` = point spacing of the clouds, over the part of the
/// footprint both epochs cover and the event owns; its solids to `solids`.
pub fn event_volume(
    obb: &Obb,
    margin: f64,
    before: &[[f64; 3]],
    after: &[[f64; 3]],
    spacing: f64,
    owned: Owned,
    solids: Solids,
) -> Result<EventVolume> {
    event_volume_in(
        obb,
        margin,
        f64::INFINITY,
        [before, after],
        spacing,
        owned,
        Cutting::Fewest(PIECE_CELLS),
        solids,
    )
}

/// [`event_volume`] of points gathered within |w| ≤ `window` of the box's centre along its third
/// axis (the search box: the unchanged walls, `axis::unchanged_walls`, know where the window
/// cut them), in pieces cut as `cutting` says ([`Cutting::Fewest`] of [`PIECE_CELLS`] in a run).
#[allow(clippy::too_many_arguments)]
pub fn event_volume_in(
    obb: &Obb,
    margin: f64,
    window: f64,
    points: [&[[f64; 3]]; 2],
    spacing: f64,
    owned: Owned,
    cutting: Cutting,
    solids: Solids,
) -> Result<EventVolume> {
    check_params(obb, margin, spacing)?;
    let frame = Frame::of_obb(obb);
    let r = Footprint::of_obb(obb, margin);
    // The points the search box gathered reach 3 spacings beyond the footprint.
    let gathered = r.grown(3.0 * spacing);
    let piece = |c: Cells, whole: bool| -> Result<Piece> {
        // A band takes the points a wall test of its own points needs, and triangulates those
        // within `BAND_MARGIN_SPACINGS` of it (a whole event those 3 spacings around its
        // footprint, all that was gathered).
        let band = meet(&c.r.grown(BAND_MARGIN_SPACINGS * spacing), &gathered);
        let keep = if whole {
            gathered
        } else {
            meet(&c.r.grown(WALL_REACH_SPACINGS * spacing), &gathered)
        };
        let local = points.map(|p| local_in(&frame, &keep, p));
        let tins = epoch_tins(local, spacing, &gathered, window, (!whole).then_some(&band));
        let [(tin1, local1), (tin2, local2)] = match tins {
            Ok(t) => t,
            // A band neither epoch spans has nothing to measure (a whole event is refused).
            Err(_) if !whole => return Ok(Piece::empty(c)),
            Err(e) => return Err(e),
        };
        let radius = region::COVER_RADIUS * spacing;
        let uv = |l: &Vec<[f64; 3]>| {
            region::PointCoverage::new(l.iter().map(|p| [p[0], p[1]]), &c.r, radius)
        };
        let (cov1, cov2) = (uv(&local1), uv(&local2));
        let near_points =
            |q: [f64; 2]| cov1.covers(q[0], q[1], radius) && cov2.covers(q[0], q[1], radius);
        let (region, centres) = region_of(&frame, c, &tin1, &tin2, &near_points, owned);
        let inside = |l: &Vec<[f64; 3]>| {
            l.iter()
                .filter(|p| {
                    region
                        .cells
                        .cell_of(p[0], p[1])
                        .is_some_and(|(i, j)| region.contains(i, j))
                })
                .count()
        };
        let region_points = [inside(&local1), inside(&local2)];
        let used = [local1.len(), local2.len()];
        // Counted, the event's own points are no longer needed (the triangulations hold theirs).
        drop((local1, local2));
        // What needs both triangulations first; then each top is clipped from its own, which is
        // given back as soon as it is: a large event's peak was both triangulations beside both
        // tops (≈ 2.2 KB per region cell on the cliff's debris fan).
        let change = change_of(&region, &centres, &tin1, &tin2, spacing);
        drop((cov1, cov2));
        let top = |tin: Tin| {
            let (v, f) = tin.mesh();
            drop(tin);
            solid::clipped_top(&v, &f, &region)
        };
        let tops = (!region.is_empty()).then(|| [top(tin1), top(tin2)]);
        Ok(Piece {
            used,
            region_points,
            ..Piece::new(region, change, tops)
        })
    };
    let (parts, _) = pieces(obb, margin, points, spacing, cutting);
    measure(&frame, r, spacing, parts, solids, &piece)
}

/// Volume change of one event between two arbitrary surfaces (e.g. the user's meshes,
/// [`UserMesh`]): the region is where both surfaces have a height and the event owns the
/// location; the tops are sampled on squares of half a cell (see `solid::grid_top`).
pub fn event_volume_from_surfaces(
    obb: &Obb,
    margin: f64,
    before: &dyn Surface,
    after: &dyn Surface,
    spacing: f64,
    owned: Owned,
    solids: Solids,
) -> Result<EventVolume> {
    check_params(obb, margin, spacing)?;
    let frame = Frame::of_obb(obb);
    let r = Footprint::of_obb(obb, margin);
    let piece = |c: Cells, _whole: bool| -> Result<Piece> {
        let (region, centres) = region_of(&frame, c, before, after, &|_| true, owned);
        let tops = if region.is_empty() {
            None
        } else {
            let none = || Error::Epochs("event footprint not covered by a surface".into());
            let top1 = solid::grid_top(before, &region, 2).ok_or_else(none)?;
            let top2 = solid::grid_top(after, &region, 2).ok_or_else(none)?;
            Some([top1, top2])
        };
        let change = change_of(&region, &centres, before, after, spacing);
        Ok(Piece::new(region, change, tops))
    };
    let cells = Cells::new(&r, spacing);
    measure(
        &frame,
        r,
        spacing,
        cells.bands(PIECE_CELLS, Cut::Rows),
        solids,
        &piece,
    )
}

/// The grid of cells of the event of box `obb`: its footprint (the box grown by `margin`) in
/// cells of about one `spacing`, the grid every piece and the whole region are cells of.
pub(crate) fn grid(obb: &Obb, margin: f64, spacing: f64) -> Cells {
    Cells::new(&Footprint::of_obb(obb, margin), spacing)
}

/// The pieces of an event's grid: the columns and rows of each.
pub(crate) type Pieces = Vec<(std::ops::Range<usize>, std::ops::Range<usize>)>;

/// How an event's grid is cut into pieces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cutting {
    /// Bands of at most this many cells, of rows or of columns, whichever takes fewer points.
    Fewest(usize),
    /// Bands of at most this many cells, along this way.
    Along(usize, Cut),
}

/// The `Pieces` of the event of box `obb`, and the most points (both epochs) one of them takes
/// from its gathered `points`: one piece when the grid has at most the cutting's cells, else
/// bands of whole rows or of whole columns ([`Cutting::Fewest`]: whichever takes fewer points
/// into its fullest band, rows on a tie). A band takes every point that projects into it grown
/// by the wall test's reach, so a wall seen edge-on (a cliff face under a debris fan's box, most
/// of the points gathered) falls into one band of rows but across every band of columns, or the
/// reverse. Nothing per point is held: the points are put in the frame again for each way.
pub fn pieces(
    obb: &Obb,
    margin: f64,
    points: [&[[f64; 3]]; 2],
    spacing: f64,
    cutting: Cutting,
) -> (Pieces, usize) {
    let (Cutting::Fewest(piece_cells) | Cutting::Along(piece_cells, _)) = cutting;
    let frame = Frame::of_obb(obb);
    let cells = grid(obb, margin, spacing);
    let gathered = cells.r.grown(3.0 * spacing);
    if cells.len() <= piece_cells {
        return (
            vec![(0..cells.nu, 0..cells.nv)],
            points[0].len() + points[1].len(),
        );
    }
    let reach = WALL_REACH_SPACINGS * spacing;
    let local = || {
        points
            .iter()
            .flat_map(|p| p.iter())
            .map(|p| frame.to_local(p))
            .filter(|l| gathered.contains(l[0], l[1]))
    };
    let count = |cut: Cut| {
        let bands = cells.bands(piece_cells, cut);
        // Each band's reach along the cut's axis: [start − reach, end + reach]; across it a band
        // takes the whole gathered box.
        let (axis, line): (usize, &dyn Fn(usize) -> f64) = match cut {
            Cut::Rows => (1, &|j| cells.v(j)),
            Cut::Columns => (0, &|i| cells.u(i)),
        };
        let span = |b: &(std::ops::Range<usize>, std::ops::Range<usize>)| match cut {
            Cut::Rows => b.1.clone(),
            Cut::Columns => b.0.clone(),
        };
        let reaches: Vec<[f64; 2]> = bands
            .iter()
            .map(|b| {
                let s = span(b);
                [line(s.start) - reach, line(s.end) + reach]
            })
            .collect();
        let mut taken = vec![0usize; bands.len()];
        for l in local() {
            let x = l[axis];
            // The reaches rise with the band: the first that does not end before x, then on.
            let first = reaches.partition_point(|b| b[1] < x);
            for (k, b) in reaches.iter().enumerate().skip(first) {
                if b[0] > x {
                    break;
                }
                taken[k] += 1;
            }
        }
        (bands, taken.into_iter().max().unwrap_or(0))
    };
    if let Cutting::Along(_, cut) = cutting {
        return count(cut);
    }
    let (rows, by_rows) = count(Cut::Rows);
    let (columns, by_columns) = count(Cut::Columns);
    if by_columns < by_rows {
        (columns, by_columns)
    } else {
        (rows, by_rows)
    }
}

/// The rectangle both `a` and `b` cover.
fn meet(a: &Footprint, b: &Footprint) -> Footprint {
    Footprint {
        u0: a.u0.max(b.u0),
        u1: a.u1.min(b.u1),
        v0: a.v0.max(b.v0),
        v1: a.v1.min(b.v1),
    }
}

/// What one band of an event's cells gives.
struct Piece {
    /// The band's region (its cells, row for row those of the event's grid).
    region: Region,
    /// The surfaces' difference at each of its cells' centres ([`Region::cell_changes`]).
    dw: Vec<Option<f64>>,
    gain: f64,
    loss: f64,
    /// The two tops clipped to the band's region (local); None when it has no region.
    tops: Option<[Mesh; 2]>,
    /// Points of each epoch triangulated, and those inside the band's region.
    used: [usize; 2],
    region_points: [usize; 2],
}

impl Piece {
    /// A band's region, its change ([`change_of`]) and tops; no points counted.
    fn new(region: Region, change: (Vec<Option<f64>>, f64, f64), tops: Option<[Mesh; 2]>) -> Piece {
        let (dw, gain, loss) = change;
        Piece {
            region,
            dw,
            gain,
            loss,
            tops,
            used: [0; 2],
            region_points: [0; 2],
        }
    }

    /// A band with nothing measured (no cell covered).
    fn empty(c: Cells) -> Piece {
        let n = c.len();
        let region = Region::new(c, vec![false; n], &vec![false; n]);
        Piece::new(region, (vec![None; n], 0.0, 0.0), None)
    }
}

/// The event's volume over footprint `r`, band by band (`parts` of its grid; `piece` measures
/// one: its cells and whether it is the whole grid): each band's tops closed into solids over a base plane of
/// their own (one spacing below both) and sent to `solids`, the volumes added up; the region,
/// its open rim and the step variance from the whole grid's flags and changes (a few bytes a
/// cell), so they do not depend on where the seams fall.
fn measure(
    frame: &Frame,
    r: Footprint,
    spacing: f64,
    parts: Pieces,
    solids: Solids,
    piece: &dyn Fn(Cells, bool) -> Result<Piece>,
) -> Result<EventVolume> {
    let cells = Cells::new(&r, spacing);
    let whole = parts.len() == 1;
    // Each part's cells put in their place in the whole grid (row-major).
    let mut covered = vec![false; cells.len()];
    let mut inside = vec![false; cells.len()];
    let mut dw = vec![None; cells.len()];
    // Sums that start from the first band's value (a sum from 0.0 would turn −0.0 into 0.0).
    let add = |s: &mut Option<f64>, x: f64| *s = Some(s.map_or(x, |s| s + x));
    let (mut gain, mut loss, mut v1, mut v2) = (None, None, None, None);
    let mut base_w = f64::INFINITY;
    let (mut used, mut region_points) = ([0; 2], [0; 2]);
    let to_global = |mut m: Mesh| {
        for v in &mut m.vertices {
            *v = frame.to_global(v);
        }
        m
    };
    for (cols, rows) in parts {
        let c = cells.part(cols.clone(), rows.clone());
        let p = piece(c, whole)?;
        if let Some([top1, top2]) = p.tops {
            covered_by_both(&p.region, &top1, &top2)?;
            // One base plane below both surfaces, one spacing lower still so no wall is flat.
            let base = solid::min_height(&top1).min(solid::min_height(&top2)) - spacing;
            let solid1 = solid::close(top1, base, &c.r);
            let solid2 = solid::close(top2, base, &c.r);
            add(&mut v1, solid::signed_volume(&solid1));
            add(&mut v2, solid::signed_volume(&solid2));
            base_w = base_w.min(base);
            solids([to_global(solid1), to_global(solid2)])?;
        }
        add(&mut gain, p.gain);
        add(&mut loss, p.loss);
        for k in 0..2 {
            used[k] += p.used[k];
            region_points[k] += p.region_points[k];
        }
        for (j, row) in rows.enumerate() {
            for (i, col) in cols.clone().enumerate() {
                let (from, to) = (c.index(i, j), cells.index(col, row));
                covered[to] = p.region.covered[from];
                inside[to] = p.region.inside[from];
                dw[to] = p.dw[from];
            }
        }
    }
    let region = Region::new(cells, covered, &inside);
    if region.is_empty() {
        return Err(Error::Epochs(format!(
            "no part of the footprint is covered by both epochs and free of other events (coverage {:.0} %)",
            100.0 * region.coverage()
        )));
    }
    let (v1, v2) = (v1.unwrap_or(0.0), v2.unwrap_or(0.0));
    Ok(EventVolume {
        volume_m3: v2 - v1,
        gain_m3: gain.unwrap_or(0.0),
        loss_m3: loss.unwrap_or(0.0),
        footprint_area_m2: r.area(),
        region_area_m2: region.area(),
        coverage: region.coverage(),
        footprint: r,
        open_rim: region.open_rim(&dw),
        step_variance_m6: region.step_variance(&dw, spacing),
        region,
        frame: *frame,
        base_w,
        before_solid_m3: v1,
        after_solid_m3: v2,
        n_before: used[0],
        n_after: used[1],
        region_points,
    })
}

/// Refuse a region (or a band's) no part of which both epochs cover.
fn covered_by_both(region: &Region, top1: &Mesh, top2: &Mesh) -> Result<()> {
    if region.is_empty() || top1.faces.is_empty() || top2.faces.is_empty() {
        return Err(Error::Epochs(format!(
            "no part of the footprint is covered by both epochs and free of other events (coverage {:.0} %)",
            100.0 * region.coverage()
        )));
    }
    Ok(())
}

/// What the two surfaces say of the change over the region beyond the solids: the difference at
/// each cell's centre (from their heights there, `centres`, as [`region_of`] found them), and the
/// gross gain and loss.
fn change_of(
    region: &Region,
    centres: &[Vec<f64>; 2],
    s1: &dyn Surface,
    s2: &dyn Surface,
    spacing: f64,
) -> (Vec<Option<f64>>, f64, f64) {
    let dw = region.cell_changes(&centres[0], &centres[1]);
    // Gross terms (reported, not part of V) by the midpoint rule on sub-cells of about
    // spacing/2 (a step is misplaced by at most half a sub-cell).
    let (gain, loss) = gross(s1, s2, region, spacing / 2.0);
    (dw, gain, loss)
}

/// Midpoint-rule gross gain and loss over the region's cells, each cut into sub-cells of at
/// most `sub` a side.
fn gross(s1: &dyn Surface, s2: &dyn Surface, region: &Region, sub: f64) -> (f64, f64) {
    let c = &region.cells;
    let (du, dv) = c.pitch();
    let k = ((du.max(dv) / sub).ceil() as usize).clamp(1, 8);
    let w = c.cell_area() / (k * k) as f64;
    // The sub-cells' heights a band of rows at a time, at most 4 per cell of the piece for each
    // surface (what the piece's cells reserve covers them, [`crate::units::volumes`]); each
    // row's sum in order, then the rows' in order (a parallel `reduce` would add the floats in an
    // order that depends on the thread count).
    let band = (4 * c.nv / (k * k)).max(1);
    let mut rows: Vec<(f64, f64)> = Vec::with_capacity(c.nv);
    for j0 in (0..c.nv).step_by(band) {
        let j1 = (j0 + band).min(c.nv);
        let l = Lattice::within(c, k, j0..j1);
        let (h1, h2) = rayon::join(|| s1.heights_on(&l), || s2.heights_on(&l));
        rows.extend((j0..j1).map(|j| {
            let (mut g, mut l) = (0.0, 0.0);
            for i in (0..c.nu).filter(|&i| region.contains(i, j)) {
                for b in 0..k {
                    let row = ((j - j0) * k + b) * c.nu * k;
                    for a in 0..k {
                        let d = h2[row + i * k + a] - h1[row + i * k + a];
                        if d > 0.0 {
                            g += d;
                        } else if d < 0.0 {
                            l += d;
                        }
                    }
                }
            }
            (g, l)
        }));
    }
    let (g, l) = rows.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    (g * w, l * w)
}
