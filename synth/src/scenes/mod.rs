//! The synthetic scenes: two analytic surfaces per scene and the closed-form volumes of their
//! differences (the ground truth of `talus synth`).
//!
//! All scenes are built in local metres (x east, y north, z up, ground at z ≈ 100) and shifted to
//! UTM-like coordinates when written. Change features never overlap and stay at least a few metres
//! from the scene edges. Volumes (signed: loss < 0) follow from the formulas in
//! `surface`: bump h·R²(π/2 − 2/π), spherical cap πh²(3R − h)/3, box w·d·h,
//! half-cone (a cone cut in half by the cliff face) πR²H/6, half-ellipsoid (2/3)πabc.
//!
//! Here the model of a scene and what the scenes share; the scenes themselves by family in
//! `plains.rs` (hill, cube, spheres, cubes, hole, stable), `cliffs.rs` (cliff, dense,
//! vegetation, deposit) and `terrain.rs` (beach, large, events); the face scenes in
//! `face`.

use std::f64::consts::{PI, TAU};

use super::plants::Plant;
use super::surface::{Base, Heightfield, Hole, Patch, Wave};
use super::SceneKind;

mod cliffs;
mod plains;
mod terrain;

pub(crate) use cliffs::{scar_event, CliffFrame};

/// Where an event's change lies, for integrating it: a rectangle of the ground (x, y) over which
/// the two heightfields differ, or a rectangle of the cliff face (x, z) over which the depth into
/// the face differs. Local coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Footprint {
    Ground {
        min: [f64; 2],
        max: [f64; 2],
    },
    Face {
        min: [f64; 2],
        max: [f64; 2],
    },
    /// A rectangle of a scanned face's own frame (strike a, up-dip b: `face`), over
    /// which its offset out of the face's mean plane differs.
    Frame {
        min: [f64; 2],
        max: [f64; 2],
    },
}

/// One change event of a scene in local coordinates, with its closed-form volume.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelEvent {
    /// Signed volume V(after) − V(before) in m³.
    pub volume_m3: f64,
    /// Centre of the footprint on the epoch-1 surface (on the face plane for face scars; the
    /// footprint centroid for the half-disk of the debris fan).
    pub centre: [f64; 3],
    /// Radius of a circle around `centre` that contains the footprint.
    pub radius_m: f64,
    pub footprint: Footprint,
    /// The part of `volume_m3` over ground that both epochs observed, when epoch 1 has a hole over
    /// part of the event (None: all of it is observed).
    pub covered_volume_m3: Option<f64>,
    pub description: String,
}

/// A rockfall scar hollowed into the cliff face (plane y = 0, rock at y > 0); (x, z) coordinates.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Scar {
    Box {
        min: [f64; 2],
        max: [f64; 2],
        depth: f64,
    },
    /// Half-ellipsoid with semi-axes a (along x), depth b (into the face, y), c (along z).
    HalfEllipsoid {
        c: [f64; 2],
        a: f64,
        b: f64,
        cz: f64,
    },
}

impl Scar {
    /// Volume of rock removed (m³, positive): w·h·d for a box, (2/3)πabc for a half-ellipsoid.
    pub(crate) fn volume(&self) -> f64 {
        match *self {
            Scar::Box { min, max, depth } => (max[0] - min[0]) * (max[1] - min[1]) * depth,
            Scar::HalfEllipsoid { a, b, cz, .. } => 2.0 / 3.0 * PI * a * b * cz,
        }
    }

    /// The rectangle of the face (x, z) the scar opens: (min, max).
    pub(crate) fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        match *self {
            Scar::Box { min, max, .. } => (min, max),
            Scar::HalfEllipsoid { c, a, cz, .. } => ([c[0] - a, c[1] - cz], [c[0] + a, c[1] + cz]),
        }
    }

    /// The hole the scar cuts out of the face plane of a cliff whose foot is at `z0`, in the
    /// face's (u = x, v = z − z0) coordinates.
    pub(crate) fn hole(&self, z0: f64) -> Hole {
        match *self {
            Scar::Box { min, max, .. } => Hole::Rect {
                min: [min[0], min[1] - z0],
                max: [max[0], max[1] - z0],
            },
            Scar::HalfEllipsoid { c, a, cz, .. } => Hole::Ellipse {
                c: [c[0], c[1] - z0],
                a,
                b: cz,
            },
        }
    }

    /// The scar's own surface: a box's back wall, floor, ceiling and two side walls, or the
    /// half-ellipsoid.
    pub(crate) fn patches(&self) -> Vec<Patch> {
        match *self {
            Scar::Box { min, max, depth: d } => {
                let ([x0, z0], [x1, z1]) = (min, max);
                let plane = |origin, eu, ev, len| Patch::Plane {
                    origin,
                    eu,
                    ev,
                    len,
                    holes: Vec::new(),
                };
                let (ex, ey, ez) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
                vec![
                    plane([x0, d, z0], ex, ez, [x1 - x0, z1 - z0]),
                    plane([x0, 0.0, z0], ex, ey, [x1 - x0, d]),
                    plane([x0, 0.0, z1], ex, ey, [x1 - x0, d]),
                    plane([x0, 0.0, z0], ey, ez, [d, z1 - z0]),
                    plane([x1, 0.0, z0], ey, ez, [d, z1 - z0]),
                ]
            }
            Scar::HalfEllipsoid { c, a, b, cz } => vec![Patch::HalfEllipsoid {
                centre: [c[0], 0.0, c[1]],
                radii: [a, b, cz],
            }],
        }
    }

    fn depth(&self, x: f64, z: f64) -> f64 {
        match *self {
            Scar::Box { min, max, depth } => {
                if x >= min[0] && x < max[0] && z >= min[1] && z < max[1] {
                    depth
                } else {
                    0.0
                }
            }
            Scar::HalfEllipsoid { c, a, b, cz } => {
                let q = 1.0 - ((x - c[0]) / a).powi(2) - ((z - c[1]) / cz).powi(2);
                if q > 0.0 {
                    b * q.sqrt()
                } else {
                    0.0
                }
            }
        }
    }
}

/// The analytic model of a scene: each epoch's surface as sampling patches, the heightfields and
/// face scars for evaluating it, and the events.
#[derive(Debug, Clone)]
pub struct SceneModel {
    pub(crate) patches: [Vec<Patch>; 2],
    scars: [Vec<Scar>; 2],
    face: Option<([f64; 2], [f64; 2])>,
    pub(crate) events: Vec<ModelEvent>,
    /// Fraction of each epoch's surface that is sampled (1 unless it has holes): an epoch gets
    /// this fraction of the requested points, so holes keep the density of the rest.
    pub(crate) observed: [f64; 2],
    /// Centre of the scene's footprint: the vertical rotation axis of `--rotate`.
    pub(crate) centre: [f64; 2],
    pub(crate) summary: String,
    /// Each epoch's plants (`plants`): points that are not surfaces, and the surface they hide.
    pub(crate) plants: [Vec<Plant>; 2],
    /// A face scanned by a terrestrial scanner (`face`, `face-vertical`): its epochs are rays
    /// cast from the scanner, not samples of `patches`.
    pub(crate) scanned: Option<super::face::FaceScene>,
}

/// Default points per epoch of each scene (about 0.1 m spacing for the small ones; holes are left
/// out of the count: see [`SceneModel::observed`]).
pub(crate) fn default_points(kind: SceneKind) -> u64 {
    match kind {
        SceneKind::Hill | SceneKind::Cubes | SceneKind::Stable | SceneKind::Hole => 160_000,
        SceneKind::Cube => 100_000,
        SceneKind::Spheres | SceneKind::Cliff | SceneKind::Deposit => 250_000,
        // 2173 m² at about 0.08 m spacing.
        SceneKind::Events => 350_000,
        SceneKind::Large => 120_000_000,
        // 990 m² at 1.5 cm spacing.
        SceneKind::Dense => 4_400_000,
        // 60 m × 46 m at about 0.1 m spacing.
        SceneKind::Beach => 280_000,
        // The cliff's 3600 m² of surfaces at about 7 cm spacing.
        SceneKind::Vegetation => 750_000,
        // 2400 m² of face at about 0.1 m spacing seen from 300 m.
        SceneKind::Face | SceneKind::FaceVertical => 250_000,
    }
}

/// Default noise (standard deviation, m) of each scene.
pub(crate) fn default_noise(kind: SceneKind) -> f64 {
    match kind {
        SceneKind::Stable | SceneKind::Events => 0.01,
        _ => 0.005,
    }
}

/// Point spacing of the large scene: its side is sqrt(points)·spacing.
pub(crate) const LARGE_SPACING: f64 = 0.15;
/// Feature grid pitch of the large scene (centres on multiples of it, so every feature straddles
/// round-number coordinates such as 100 m tile borders).
const LARGE_PITCH: f64 = 50.0;
/// Distance from the large scene's edges within which no feature centre lies.
const LARGE_MARGIN: f64 = 25.0;
/// Smallest large scene that still holds a feature: 2 × margin + pitch on a side.
pub(crate) const LARGE_MIN_POINTS: u64 = 1_000_000;

pub(crate) fn ground(min: [f64; 2], max: [f64; 2]) -> Footprint {
    Footprint::Ground { min, max }
}

fn square(c: [f64; 2], r: f64) -> Footprint {
    ground([c[0] - r, c[1] - r], [c[0] + r, c[1] + r])
}

fn height_patch(field: Heightfield, min: [f64; 2], max: [f64; 2]) -> Patch {
    Patch::Height {
        field,
        min,
        max,
        holes: Vec::new(),
    }
}

impl SceneModel {
    /// The model of `kind`; `points` is the per-epoch count (used by the large scene for its size),
    /// `seed` lays out the events scene.
    pub(crate) fn new(kind: SceneKind, points: u64, seed: u64) -> Self {
        match kind {
            SceneKind::Hill => plains::hill(),
            SceneKind::Cube => plains::cube(),
            SceneKind::Spheres => plains::spheres(),
            SceneKind::Cubes => plains::cubes(),
            SceneKind::Cliff => cliffs::cliff(),
            SceneKind::Deposit => cliffs::deposit(),
            SceneKind::Hole => plains::hole(),
            SceneKind::Events => terrain::events(seed),
            SceneKind::Stable => plains::stable(),
            SceneKind::Large => terrain::large(points),
            SceneKind::Dense => cliffs::dense(),
            SceneKind::Beach => terrain::beach(),
            SceneKind::Vegetation => cliffs::vegetation(),
            SceneKind::Face => face(70.0),
            SceneKind::FaceVertical => face(90.0),
        }
    }

    /// Whether the scene has plants (points that are not surfaces: `plants`).
    pub(crate) fn has_plants(&self) -> bool {
        self.plants.iter().any(|p| !p.is_empty())
    }

    /// The events with their closed-form volumes (local coordinates).
    pub fn events(&self) -> &[ModelEvent] {
        &self.events
    }

    /// Height of epoch `epoch` (0 = before, 1 = after) at local (x, y), where the epoch's surface
    /// is a heightfield there (ground, box tops, plateau), also over holes the epoch did not
    /// observe; None elsewhere.
    pub fn height(&self, epoch: usize, x: f64, y: f64) -> Option<f64> {
        self.patches[epoch].iter().find_map(|p| match p {
            Patch::Height {
                field, min, max, ..
            } if x >= min[0] && x <= max[0] && y >= min[1] && y <= max[1] => {
                Some(field.eval(x, y).0)
            }
            _ => None,
        })
    }

    /// Whether local (x, y) lies in a hole of one of epoch `epoch`'s heightfields (ground that
    /// epoch has no points on).
    pub fn unobserved(&self, epoch: usize, x: f64, y: f64) -> bool {
        self.patches[epoch].iter().any(|p| match p {
            Patch::Height { holes, .. } => holes.iter().any(|h| h.contains(x, y)),
            _ => false,
        })
    }

    /// Depth into the cliff face (m, ≥ 0) of epoch `epoch` at face coordinates (x, z); None when
    /// the scene has no face or (x, z) is off it.
    pub fn face_depth(&self, epoch: usize, x: f64, z: f64) -> Option<f64> {
        let (min, max) = self.face?;
        if x < min[0] || x > max[0] || z < min[1] || z > max[1] {
            return None;
        }
        Some(self.scars[epoch].iter().map(|s| s.depth(x, z)).sum())
    }

    /// Local centre of the scene (rotation axis).
    pub fn centre(&self) -> [f64; 2] {
        self.centre
    }

    fn heightfield_scene(
        size: [f64; 2],
        fields: [Heightfield; 2],
        walls: [Vec<Patch>; 2],
        events: Vec<ModelEvent>,
        summary: &str,
    ) -> Self {
        let [f1, f2] = fields;
        let [w1, w2] = walls;
        let mut p1 = vec![height_patch(f1, [0.0, 0.0], size)];
        p1.extend(w1);
        let mut p2 = vec![height_patch(f2, [0.0, 0.0], size)];
        p2.extend(w2);
        SceneModel {
            patches: [p1, p2],
            scars: [Vec::new(), Vec::new()],
            face: None,
            events,
            observed: [1.0; 2],
            centre: [size[0] / 2.0, size[1] / 2.0],
            summary: summary.to_string(),
            plants: [Vec::new(), Vec::new()],
            scanned: None,
        }
    }
}

/// face: a 60 m × 40 m rock face dipping at `dip` degrees, with a ledge, a bay and an
/// overhang, scanned alone from 300 m (see `face`).
fn face(dip: f64) -> SceneModel {
    let f = super::face::FaceScene::new(dip);
    SceneModel {
        patches: [Vec::new(), Vec::new()],
        scars: [Vec::new(), Vec::new()],
        face: None,
        events: f.events(),
        observed: [1.0; 2],
        centre: f.centre(),
        summary: format!(
            "a {dip}° rock face with a ledge, a bay and an overhang, scanned alone by a \
             terrestrial scanner 300 m away; rockfall scars, debris on the ledge and a toppling \
             block"
        ),
        plants: [Vec::new(), Vec::new()],
        scanned: Some(f),
    }
}

/// Epoch-1 height at (x, y), for event centres.
fn z_at(field: &Heightfield, c: [f64; 2]) -> f64 {
    field.eval(c[0], c[1]).0
}

/// The plane of the hill and hole scenes: z = 100 + 0.02 x + 0.01 y.
fn tilted_plane() -> Base {
    Base {
        z0: 100.0,
        gx: 0.02,
        gy: 0.01,
        waves: Vec::new(),
    }
}

/// A smooth wave of wavelengths (lx, ly) (∞ = constant along that axis).
fn wave(amp: f64, lx: f64, ly: f64, phase: f64) -> Wave {
    Wave {
        amp,
        kx: TAU / lx,
        ky: TAU / ly,
        phase,
    }
}
