//! The synthetic scenes: two analytic surfaces per scene and the closed-form volumes of their
//! differences (the ground truth of `talus synth`).
//!
//! All scenes are built in local metres (x east, y north, z up, ground at z ≈ 100) and shifted to
//! UTM-like coordinates when written. Change features never overlap and stay at least a few metres
//! from the scene edges. Volumes (signed: loss < 0) follow from the formulas in
//! [`surface`](super::surface): bump h·R²(π/2 − 2/π), spherical cap πh²(3R − h)/3, box w·d·h,
//! half-cone (a cone cut in half by the cliff face) πR²H/6, half-ellipsoid (2/3)πabc.

use std::f64::consts::{PI, TAU};

use super::plants::{Plant, PlantKind, Standing};
use crate::rng::Rng;
use super::surface::{
    box_walls, box_walls_on, bump_volume, cap_footprint, cap_volume, Base, Feature, Heightfield,
    Hole, Patch, Wave,
};
use super::SceneKind;

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
    /// A rectangle of a scanned face's own frame (strike a, up-dip b: [`super::face`]), over
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
    pub fn new(kind: SceneKind, points: u64, seed: u64) -> Self {
        match kind {
            SceneKind::Hill => hill(),
            SceneKind::Cube => cube(),
            SceneKind::Spheres => spheres(),
            SceneKind::Cubes => cubes(),
            SceneKind::Cliff => cliff(),
            SceneKind::Deposit => deposit(),
            SceneKind::Hole => hole(),
            SceneKind::Events => events(seed),
            SceneKind::Stable => stable(),
            SceneKind::Large => large(points),
            SceneKind::Dense => dense(),
            SceneKind::Beach => beach(),
            SceneKind::Vegetation => vegetation(),
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
/// overhang, scanned alone from 300 m (see [`super::face`]).
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

/// hill: a 40 m × 40 m tilted plane; epoch 2 adds h·cos²(πr/2R), R = 6 m, h = 1.5 m at the centre.
/// V = h·R²·(π/2 − 2/π) ≈ 50.44 m³.
fn hill() -> SceneModel {
    let base = tilted_plane();
    let (c, radius, height) = ([20.0, 20.0], 6.0, 1.5);
    let f1 = Heightfield::new(base.clone(), Vec::new());
    let f2 = Heightfield::new(base, vec![Feature::Bump { c, radius, height }]);
    let events = vec![ModelEvent {
        volume_m3: bump_volume(radius, height),
        centre: [c[0], c[1], z_at(&f1, c)],
        radius_m: radius,
        footprint: square(c, radius),
        covered_volume_m3: None,
        description: format!("hill: h·cos²(πr/2R) bump, R = {radius} m, h = {height} m"),
    }];
    SceneModel::heightfield_scene(
        [40.0, 40.0],
        [f1, f2],
        [Vec::new(), Vec::new()],
        events,
        "smooth bump on a tilted plane",
    )
}

/// cube: a 30 m × 30 m plane; epoch 2 has a 4 × 4 × 1.5 m box on it (top and four walls sampled).
/// V = 24 m³.
fn cube() -> SceneModel {
    let (min, max, h) = ([13.0, 13.0], [17.0, 17.0], 1.5);
    let f1 = Heightfield::new(Base::plane(100.0), Vec::new());
    let f2 = Heightfield::new(
        Base::plane(100.0),
        vec![Feature::Block {
            min,
            max,
            height: h,
        }],
    );
    let events = vec![ModelEvent {
        volume_m3: 4.0 * 4.0 * h,
        centre: [15.0, 15.0, 100.0],
        radius_m: 8f64.sqrt(),
        footprint: ground(min, max),
        covered_volume_m3: None,
        description: "cube: 4 × 4 × 1.5 m box raised from the plane".into(),
    }];
    SceneModel::heightfield_scene(
        [30.0, 30.0],
        [f1, f2],
        [Vec::new(), box_walls(min, max, 100.0, 100.0 + h)],
        events,
        "box raised from a plane",
    )
}

/// spheres: a 50 m × 50 m gently tilted plane; epoch 2 has spherical caps (gains) and dents
/// (losses), V = ±πh²(3R − h)/3 each.
fn spheres() -> SceneModel {
    let base = Base {
        z0: 100.0,
        gx: 0.01,
        gy: -0.005,
        waves: Vec::new(),
    };
    // (centre, sphere radius, signed cap height)
    let caps: [([f64; 2], f64, f64); 5] = [
        ([12.0, 12.0], 5.0, 1.0),
        ([38.0, 14.0], 3.0, 1.5),
        ([14.0, 37.0], 4.0, -0.8),
        ([36.0, 36.0], 6.0, -1.2),
        ([25.0, 25.0], 2.0, 0.5),
    ];
    let f1 = Heightfield::new(base.clone(), Vec::new());
    let features = caps
        .iter()
        .map(|&(c, sphere_radius, height)| Feature::Cap {
            c,
            sphere_radius,
            height,
        })
        .collect();
    let f2 = Heightfield::new(base, features);
    let events = caps
        .iter()
        .map(|&(c, rs, h)| {
            let a = cap_footprint(rs, h);
            ModelEvent {
                volume_m3: cap_volume(rs, h),
                centre: [c[0], c[1], z_at(&f1, c)],
                radius_m: a,
                footprint: square(c, a),
                covered_volume_m3: None,
                description: format!(
                    "spherical {} R = {rs} m, h = {} m",
                    if h > 0.0 { "cap" } else { "dent" },
                    h.abs()
                ),
            }
        })
        .collect();
    SceneModel::heightfield_scene(
        [50.0, 50.0],
        [f1, f2],
        [Vec::new(), Vec::new()],
        events,
        "spherical caps and dents on a tilted plane",
    )
}

/// cubes: boxes on a 40 m × 40 m plane in both epochs: A removed (loss), B appears (gain), C grows
/// from 1 m to 2 m (gain), D a pit dug (loss), E unchanged (a control: no event).
fn cubes() -> SceneModel {
    struct Bx {
        name: &'static str,
        min: [f64; 2],
        max: [f64; 2],
        h: [f64; 2],
    }
    let boxes = [
        Bx {
            name: "A: 3 × 3 × 1 m box removed",
            min: [8.0, 8.0],
            max: [11.0, 11.0],
            h: [1.0, 0.0],
        },
        Bx {
            name: "B: 4 × 2 × 1.5 m box placed",
            min: [28.0, 9.0],
            max: [32.0, 11.0],
            h: [0.0, 1.5],
        },
        Bx {
            name: "C: 3 × 3 m box grown from 1 m to 2 m",
            min: [8.5, 28.5],
            max: [11.5, 31.5],
            h: [1.0, 2.0],
        },
        Bx {
            name: "D: 3 × 2 × 1 m pit dug",
            min: [28.5, 29.0],
            max: [31.5, 31.0],
            h: [0.0, -1.0],
        },
        Bx {
            name: "E: 2 × 2 × 1 m box unchanged",
            min: [19.0, 19.0],
            max: [21.0, 21.0],
            h: [1.0, 1.0],
        },
    ];
    let z0 = 100.0;
    let mut fields = Vec::new();
    let mut walls = [Vec::new(), Vec::new()];
    for (e, w) in walls.iter_mut().enumerate() {
        let mut features = Vec::new();
        for b in boxes.iter().filter(|b| b.h[e] != 0.0) {
            features.push(Feature::Block {
                min: b.min,
                max: b.max,
                height: b.h[e],
            });
            w.extend(box_walls(
                b.min,
                b.max,
                z0 + b.h[e].min(0.0),
                z0 + b.h[e].max(0.0),
            ));
        }
        fields.push(Heightfield::new(Base::plane(z0), features));
    }
    let events = boxes
        .iter()
        .filter(|b| b.h[0] != b.h[1])
        .map(|b| {
            let (dx, dy) = (b.max[0] - b.min[0], b.max[1] - b.min[1]);
            let c = [(b.min[0] + b.max[0]) / 2.0, (b.min[1] + b.max[1]) / 2.0];
            ModelEvent {
                volume_m3: dx * dy * (b.h[1] - b.h[0]),
                centre: [c[0], c[1], z0 + b.h[0]],
                radius_m: dx.hypot(dy) / 2.0,
                footprint: ground(b.min, b.max),
                covered_volume_m3: None,
                description: b.name.to_string(),
            }
        })
        .collect();
    let [f1, f2]: [Heightfield; 2] = match fields.try_into() {
        Ok(f) => f,
        Err(_) => unreachable!("two epochs"),
    };
    SceneModel::heightfield_scene(
        [40.0, 40.0],
        [f1, f2],
        walls,
        events,
        "boxes removed, placed, grown, dug and unchanged",
    )
}

/// The frame of the cliff scenes: a beach (x ∈ [0, width], y ∈ [−beach, 0], sloping 2 % seaward
/// to −y) at the foot of a vertical face of `height` in the plane y = 0 (rock at y > 0, face normal
/// −y) rising from z0, with a plateau `plateau` deep on top.
#[derive(Debug, Clone)]
pub(crate) struct CliffFrame {
    pub width: f64,
    pub height: f64,
    pub beach: f64,
    pub plateau: f64,
    pub z0: f64,
}

const CLIFF: CliffFrame = CliffFrame {
    width: 60.0,
    height: 30.0,
    beach: 20.0,
    plateau: 10.0,
    z0: 100.0,
};

impl CliffFrame {
    pub(crate) fn beach_base(&self) -> Base {
        Base {
            z0: self.z0,
            gx: 0.0,
            gy: 0.02,
            waves: Vec::new(),
        }
    }

    /// Beach (with `features`), plateau and face (minus `holes`), in that order.
    pub(crate) fn patches(&self, features: Vec<Feature>, holes: Vec<Hole>) -> Vec<Patch> {
        self.patches_with(features, Vec::new(), holes)
    }

    /// [`CliffFrame::patches`] with `on_top` features on the plateau.
    pub(crate) fn patches_with(
        &self,
        features: Vec<Feature>,
        on_top: Vec<Feature>,
        holes: Vec<Hole>,
    ) -> Vec<Patch> {
        let top = Heightfield::new(Base::plane(self.z0 + self.height), on_top);
        vec![
            height_patch(
                Heightfield::new(self.beach_base(), features),
                [0.0, -self.beach],
                [self.width, 0.0],
            ),
            height_patch(top, [0.0, 0.0], [self.width, self.plateau]),
            Patch::Plane {
                origin: [0.0, 0.0, self.z0],
                eu: [1.0, 0.0, 0.0],
                ev: [0.0, 0.0, 1.0],
                len: [self.width, self.height],
                holes,
            },
        ]
    }

    pub(crate) fn model(
        &self,
        patches: [Vec<Patch>; 2],
        scars: [Vec<Scar>; 2],
        events: Vec<ModelEvent>,
        summary: &str,
    ) -> SceneModel {
        SceneModel {
            patches,
            scars,
            face: Some(([0.0, self.z0], [self.width, self.z0 + self.height])),
            events,
            observed: [1.0; 2],
            centre: [self.width / 2.0, (self.plateau - self.beach) / 2.0],
            summary: summary.into(),
            plants: [Vec::new(), Vec::new()],
            scanned: None,
        }
    }
}

/// cliff: a beach (x ∈ [0, 60], y ∈ [−20, 0], sloping 2 % seaward to −y) at the foot of a 30 m
/// vertical face in the plane y = 0 (rock at y > 0, face normal −y), with a 10 m deep plateau on
/// top. Epoch 2: a box scar 4 m wide × 3 m high × 1 m deep (V = −12 m³), a half-ellipsoid scar with
/// semi-axes 3 m (x), 1.5 m (depth), 2.5 m (z) (V = −(2/3)π·3·1.5·2.5 ≈ −23.56 m³), and a debris
/// fan at the foot: a cone of radius 5 m and height 3.5 m (35° slope) centred on the foot of the
/// face, half of which lies in front of it (V = πR²H/6 ≈ 45.81 m³; it hides the face below its
/// profile).
fn cliff() -> SceneModel {
    let z0 = CLIFF.z0;
    let (fan_c, fan_r, fan_h) = ([26.0, 0.0], 5.0, 3.5);
    let box_scar = Scar::Box {
        min: [10.0, z0 + 15.0],
        max: [14.0, z0 + 18.0],
        depth: 1.0,
    };
    let (ell_c, ell_a, ell_b, ell_cz) = ([40.0, z0 + 20.0], 3.0, 1.5, 2.5);
    let ell_scar = Scar::HalfEllipsoid {
        c: ell_c,
        a: ell_a,
        b: ell_b,
        cz: ell_cz,
    };
    let scars = vec![box_scar, ell_scar];
    let p1 = CLIFF.patches(Vec::new(), Vec::new());
    let mut holes: Vec<Hole> = scars.iter().map(|s| s.hole(z0)).collect();
    holes.push(Hole::BelowTent {
        cu: fan_c[0],
        peak: fan_h,
        slope: fan_h / fan_r,
    });
    let mut p2 = CLIFF.patches(
        vec![Feature::Cone {
            c: fan_c,
            radius: fan_r,
            height: fan_h,
        }],
        holes,
    );
    p2.extend(scars.iter().flat_map(Scar::patches));
    let fan_centroid_y = -4.0 * fan_r / (3.0 * PI);
    let events = vec![
        scar_event(
            &box_scar,
            "rockfall scar: box 4 m wide, 3 m high, 1 m deep into the face".into(),
        ),
        scar_event(
            &ell_scar,
            "rockfall scar: half-ellipsoid 3 m × 2.5 m semi-axes, 1.5 m deep".into(),
        ),
        ModelEvent {
            volume_m3: PI * fan_r * fan_r * fan_h / 6.0,
            centre: [
                fan_c[0],
                fan_centroid_y,
                z0 + CLIFF.beach_base().gy * fan_centroid_y,
            ],
            radius_m: fan_r,
            footprint: ground([fan_c[0] - fan_r, -fan_r], [fan_c[0] + fan_r, 0.0]),
            covered_volume_m3: None,
            description: "debris fan: half-cone R = 5 m, H = 3.5 m against the face foot".into(),
        },
    ];
    CLIFF.model(
        [p1, p2],
        [Vec::new(), scars],
        events,
        "vertical cliff face with beach and plateau; rockfall scars and a debris fan",
    )
}

/// The frame of the `dense` scene: a smaller cliff, so that a terrestrial scanner's spacing
/// (1.5 cm at the default 4.4M points per epoch) stays within a few million points.
const DENSE: CliffFrame = CliffFrame {
    width: 30.0,
    height: 15.0,
    beach: 10.0,
    plateau: 8.0,
    z0: 100.0,
};

/// dense: a cliff as a terrestrial scanner delivers it (≈ 1.5 cm spacing at the default 4.4M
/// points per epoch: 990 m² of beach x ∈ [0, 30], y ∈ [−10, 0], a 15 m vertical face in the
/// plane y = 0 and an 8 m deep plateau), with changes from 0.1 m to 3 m deep, most of them far
/// deeper than the derived cylinder half-length (10 × 3 × spacing ≈ 0.45 m):
/// - on the face: a box rockfall 2.5 m wide, 2 m high and 3 m deep (−15 m³), a half-ellipsoid
///   scar 2 m deep with semi-axes 2 m (x) and 1.5 m (z) (−(2/3)π·2·2·1.5 ≈ −12.57 m³), and a
///   shallow box scar 2 m × 1.5 m × 0.1 m (−0.3 m³);
/// - at its foot: a debris cone R = 3 m, H = 2.5 m against the face (πR²H/6 ≈ +11.78 m³);
/// - on the beach: a deposit 1.5 m high, a cos² bump R = 2.5 m, 2.5 m in front of the face
///   (h·R²(π/2 − 2/π) ≈ +8.76 m³);
/// - on the plateau: a collapse, a box pit 2 m × 2 m × 1 m deep, 3 m behind the edge (−4 m³).
fn dense() -> SceneModel {
    let f = DENSE;
    let z0 = f.z0;
    let deep = Scar::Box {
        min: [3.0, z0 + 5.0],
        max: [5.5, z0 + 7.0],
        depth: 3.0,
    };
    let bowl = Scar::HalfEllipsoid {
        c: [11.0, z0 + 8.0],
        a: 2.0,
        b: 2.0,
        cz: 1.5,
    };
    let shallow = Scar::Box {
        min: [17.0, z0 + 9.0],
        max: [19.0, z0 + 10.5],
        depth: 0.1,
    };
    let (cone_c, cone_r, cone_h) = ([24.0, 0.0], 3.0, 2.5);
    let (bump_c, bump_r, bump_h) = ([8.0, -5.0], 2.5, 1.5);
    let (pit_min, pit_max, pit_d) = ([14.0, 3.0], [16.0, 5.0], 1.0);
    let top = z0 + f.height;
    let scars = vec![deep, bowl, shallow];
    let mut holes: Vec<Hole> = scars.iter().map(|s| s.hole(z0)).collect();
    holes.push(Hole::BelowTent {
        cu: cone_c[0],
        peak: cone_h,
        slope: cone_h / cone_r,
    });
    let beach2 = vec![
        Feature::Cone {
            c: cone_c,
            radius: cone_r,
            height: cone_h,
        },
        Feature::Bump {
            c: bump_c,
            radius: bump_r,
            height: bump_h,
        },
    ];
    let pit = vec![Feature::Block {
        min: pit_min,
        max: pit_max,
        height: -pit_d,
    }];
    let mut p2 = f.patches_with(beach2, pit, holes);
    p2.extend(scars.iter().flat_map(Scar::patches));
    p2.extend(box_walls(pit_min, pit_max, top - pit_d, top));
    let beach = Heightfield::new(f.beach_base(), Vec::new());
    let cone_y = -4.0 * cone_r / (3.0 * PI);
    let events = vec![
        scar_event(
            &deep,
            "rockfall: box 2.5 m wide, 2 m high, 3 m deep into the face".into(),
        ),
        scar_event(
            &bowl,
            "rockfall scar: half-ellipsoid 2 m × 1.5 m semi-axes, 2 m deep".into(),
        ),
        scar_event(&shallow, "shallow scar: box 2 m × 1.5 m, 0.1 m deep".into()),
        ModelEvent {
            volume_m3: PI * cone_r * cone_r * cone_h / 6.0,
            centre: [cone_c[0], cone_y, z_at(&beach, [cone_c[0], cone_y])],
            radius_m: cone_r,
            footprint: ground([cone_c[0] - cone_r, -cone_r], [cone_c[0] + cone_r, 0.0]),
            covered_volume_m3: None,
            description: "debris cone at the face foot: R = 3 m, H = 2.5 m".into(),
        },
        ModelEvent {
            volume_m3: bump_volume(bump_r, bump_h),
            centre: [bump_c[0], bump_c[1], z_at(&beach, bump_c)],
            radius_m: bump_r,
            footprint: square(bump_c, bump_r),
            covered_volume_m3: None,
            description: "deposit on the beach: cos² bump R = 2.5 m, 1.5 m high".into(),
        },
        ModelEvent {
            volume_m3: -(pit_max[0] - pit_min[0]) * (pit_max[1] - pit_min[1]) * pit_d,
            centre: [
                (pit_min[0] + pit_max[0]) / 2.0,
                (pit_min[1] + pit_max[1]) / 2.0,
                top,
            ],
            radius_m: (pit_max[0] - pit_min[0]).hypot(pit_max[1] - pit_min[1]) / 2.0,
            footprint: ground(pit_min, pit_max),
            covered_volume_m3: None,
            description: "plateau collapse: box pit 2 m × 2 m, 1 m deep".into(),
        },
    ];
    f.model(
        [f.patches(Vec::new(), Vec::new()), p2],
        [Vec::new(), scars],
        events,
        "terrestrial-scan cliff (1.5 cm spacing): rockfalls 0.1 to 3 m deep, a cone at the foot, \
         a deposit on the beach, a collapse on the plateau",
    )
}

/// The event of a scar opened in an intact face: its volume lost, centred on the face plane,
/// within the circle about the centre through the corners of its rectangle (a box) or of radius
/// its larger semi-axis (a half-ellipsoid).
pub(crate) fn scar_event(scar: &Scar, description: String) -> ModelEvent {
    let (min, max) = scar.bounds();
    let radius_m = match *scar {
        Scar::Box { .. } => (max[0] - min[0]).hypot(max[1] - min[1]) / 2.0,
        Scar::HalfEllipsoid { a, cz, .. } => a.max(cz),
    };
    ModelEvent {
        volume_m3: -scar.volume(),
        centre: [(min[0] + max[0]) / 2.0, 0.0, (min[1] + max[1]) / 2.0],
        radius_m,
        footprint: Footprint::Face { min, max },
        covered_volume_m3: None,
        description,
    }
}

/// vegetation: the cliff scene's frame (beach, 30 m face, plateau) with rough rock and plants,
/// where only two things move between the surveys:
/// - a rockfall from the face: a box 3 m wide, 2 m high, 0.8 m deep at x ∈ [20, 23] (−4.8 m³);
/// - a rubble deposit on the beach: a cos² mound R = 3 m, h = 0.5 m at (46, −11) with seven
///   boulders (spherical caps) on it (the bump's and the caps' volumes: +5.48 m³).
///
/// In both surveys, and unchanged: a boulder beach (x 4–18 m, y −18 to −7 m: 50 caps of spheres
/// 0.35–0.7 m, 0.5–0.8 of their radius high) and a scree cone at the face foot (a cos² mound
/// R = 4.5 m, h = 1.2 m at (34, −4.5) under 300 clasts of 0.12–0.3 m). And plants, which change
/// without any material moving: three shrubs on the face, two on the beach and a tree at the cliff
/// top (grown 10 %, 10 % and 5 % in the second survey, their leaves resampled), 40 grass tufts on
/// the plateau (grown 20 %), and a shrub on the beach cut before the second survey. Crowns hide
/// 60 % of the surface behind them. Unclassified (class 1) unless `--classified` (ground 2, grass
/// 3, shrubs 4, tree 5).
fn vegetation() -> SceneModel {
    let z0 = CLIFF.z0;
    let mut rng = Rng::new(23, 0);
    let cap = |rng: &mut Rng, c: [f64; 2], r: [f64; 2], h: [f64; 2]| {
        let sphere_radius = rng.range(r[0], r[1]);
        Feature::Cap {
            c,
            sphere_radius,
            height: sphere_radius * rng.range(h[0], h[1]),
        }
    };
    // Rough rock in both surveys.
    let mut rock: Vec<Feature> = (0..50)
        .map(|_| {
            let c = [rng.range(4.0, 18.0), rng.range(-18.0, -7.0)];
            cap(&mut rng, c, [0.35, 0.7], [0.5, 0.8])
        })
        .collect();
    let scree_c = [34.0, -4.5];
    rock.push(Feature::Bump {
        c: scree_c,
        radius: 4.5,
        height: 1.2,
    });
    for _ in 0..300 {
        let (r, a) = (4.0 * rng.uniform().sqrt(), TAU * rng.uniform());
        let c = [
            scree_c[0] + r * a.cos(),
            (scree_c[1] + r * a.sin()).min(-0.4),
        ];
        rock.push(cap(&mut rng, c, [0.12, 0.3], [0.4, 0.7]));
    }
    // The rubble deposit: a mound and boulders on it.
    let rubble_c = [46.0, -11.0];
    let mut rubble = vec![Feature::Bump {
        c: rubble_c,
        radius: 3.0,
        height: 0.5,
    }];
    for _ in 0..7 {
        let (r, a) = (1.8 * rng.uniform().sqrt(), TAU * rng.uniform());
        let c = [rubble_c[0] + r * a.cos(), rubble_c[1] + r * a.sin()];
        rubble.push(cap(&mut rng, c, [0.4, 0.7], [0.5, 0.7]));
    }
    let rubble_volume: f64 = rubble.iter().map(|f| f.volume()).sum();
    let scar = Scar::Box {
        min: [20.0, z0 + 8.0],
        max: [23.0, z0 + 10.0],
        depth: 0.8,
    };
    let beach1 = Heightfield::new(CLIFF.beach_base(), rock.clone());
    let p1 = CLIFF.patches(rock.clone(), Vec::new());
    let mut after = rock;
    after.extend(rubble);
    let mut p2 = CLIFF.patches(after, vec![scar.hole(z0)]);
    p2.extend(scar.patches());
    let events = vec![
        scar_event(
            &scar,
            "rockfall scar: box 3 m wide, 2 m high, 0.8 m deep into the face".into(),
        ),
        ModelEvent {
            volume_m3: rubble_volume,
            centre: [rubble_c[0], rubble_c[1], z_at(&beach1, rubble_c)],
            radius_m: 3.0,
            footprint: square(rubble_c, 3.0),
            covered_volume_m3: None,
            description: "rubble deposit: a cos² mound R = 3 m, h = 0.5 m with seven boulders on \
                          it"
            .into(),
        },
    ];
    // Plants: each epoch's, with streams of their own.
    let top = z0 + CLIFF.height;
    let ground = |x: f64, y: f64| z_at(&beach1, [x, y]);
    let shrub = |standing, root, size, stream| Plant {
        kind: PlantKind::Shrub,
        standing,
        root,
        size,
        stream,
    };
    let mut both = vec![
        shrub(Standing::Face, [8.0, 0.0, z0 + 20.0], [0.9, 0.6, 0.7], 1),
        shrub(Standing::Face, [31.0, 0.0, z0 + 15.0], [0.9, 0.6, 0.7], 2),
        shrub(Standing::Face, [52.0, 0.0, z0 + 6.0], [0.9, 0.6, 0.7], 3),
        shrub(
            Standing::Ground,
            [28.0, -15.0, ground(28.0, -15.0)],
            [1.0, 1.0, 0.8],
            4,
        ),
        shrub(
            Standing::Ground,
            [40.0, -17.0, ground(40.0, -17.0)],
            [0.8, 0.8, 0.6],
            5,
        ),
        Plant {
            kind: PlantKind::Tree,
            standing: Standing::Ground,
            root: [12.0, 4.0, top],
            size: [2.0, 2.0, 1.8],
            stream: 6,
        },
    ];
    let growth = [1.1, 1.1, 1.1, 1.1, 1.1, 1.05];
    for k in 0..40 {
        let (x, y) = (rng.range(2.0, 58.0), rng.range(1.5, 9.0));
        if (x - 12.0).hypot(y - 4.0) < 2.5 {
            continue;
        }
        both.push(Plant {
            kind: PlantKind::Tuft,
            standing: Standing::Ground,
            root: [x, y, top],
            size: [0.08, 0.08, 0.3],
            stream: 10 + k,
        });
    }
    let cut = shrub(
        Standing::Ground,
        [54.0, -16.0, ground(54.0, -16.0)],
        [1.0, 1.0, 0.8],
        7,
    );
    let mut before = both.clone();
    before.push(cut);
    let after: Vec<Plant> = both
        .iter()
        .enumerate()
        .map(|(i, p)| p.grown(*growth.get(i).unwrap_or(&1.2), 1000 + p.stream))
        .collect();
    let mut model = CLIFF.model(
        [p1, p2],
        [Vec::new(), vec![scar]],
        events,
        "vertical cliff face with beach and plateau, a boulder beach and a scree cone; shrubs, \
         grass and a tree that grow or are cut; one rockfall and one rubble deposit",
    );
    model.plants = [before, after];
    model
}

/// deposit: the cliff scene's frame without scars; epoch 2 has one debris deposit on the beach, a
/// cos² bump of radius 2.5 m and height 1.2 m whose edge stays 1.5 m in front of the face foot
/// (centre 4 m from it): V = h·R²(π/2 − 2/π) ≈ 7.01 m³. Horizontal M3C2 cylinders from the face
/// foot reach it though it does not touch the face.
fn deposit() -> SceneModel {
    let (radius, height, gap) = (2.5, 1.2, 1.5);
    let c = [CLIFF.width / 2.0, -(gap + radius)];
    let bump = Feature::Bump { c, radius, height };
    let events = vec![ModelEvent {
        volume_m3: bump_volume(radius, height),
        centre: [
            c[0],
            c[1],
            z_at(&Heightfield::new(CLIFF.beach_base(), Vec::new()), c),
        ],
        radius_m: radius,
        footprint: square(c, radius),
        covered_volume_m3: None,
        description: format!(
            "debris deposit on the beach: cos² bump R = {radius} m, h = {height} m, {gap} m in \
             front of the face foot"
        ),
    }];
    CLIFF.model(
        [
            CLIFF.patches(Vec::new(), Vec::new()),
            CLIFF.patches(vec![bump], Vec::new()),
        ],
        [Vec::new(), Vec::new()],
        events,
        "vertical cliff face with beach and plateau; a debris deposit on the beach near the foot",
    )
}

/// hole: the hill scene's 40 m × 40 m tilted plane; epoch 2 adds h·cos²(πr/2R), R = 4 m, h = 1 m at (20, 20)
/// (V = h·R²(π/2 − 2/π) ≈ 14.95 m³). Epoch 1 has no points over x ∈ [20, 30), y ∈ [12, 28) (a
/// water body or an occlusion): the hole's edge x = 20 runs through the bump's centre, so epoch 1
/// sees the half x < 20 of the event, and by the bump's symmetry that half holds V/2. Epoch 1 is
/// sampled only outside the hole, with 90 % of the requested points (the plane's area outside it),
/// so its density matches epoch 2's.
fn hole() -> SceneModel {
    let size = 40.0;
    let base = tilted_plane();
    let (c, radius, height) = ([20.0, 20.0], 4.0, 1.0);
    let (hole_min, hole_max) = ([c[0], 12.0], [30.0, 28.0]);
    let f1 = Heightfield::new(base.clone(), Vec::new());
    let f2 = Heightfield::new(base, vec![Feature::Bump { c, radius, height }]);
    let volume = bump_volume(radius, height);
    let events = vec![ModelEvent {
        volume_m3: volume,
        centre: [c[0], c[1], z_at(&f1, c)],
        radius_m: radius,
        footprint: square(c, radius),
        covered_volume_m3: Some(volume / 2.0),
        description: format!(
            "cos² bump R = {radius} m, h = {height} m, its half x > {} m unseen by epoch 1",
            c[0]
        ),
    }];
    let mut model = SceneModel::heightfield_scene(
        [size, size],
        [f1, f2],
        [Vec::new(), Vec::new()],
        events,
        "smooth bump on a tilted plane, half of it in a hole of epoch 1",
    );
    let Patch::Height { holes, .. } = &mut model.patches[0][0] else {
        unreachable!("a heightfield scene's first patch is its ground")
    };
    holes.push(Hole::Rect {
        min: hole_min,
        max: hole_max,
    });
    // A plane's area element is constant: the observed share is the share of the footprint.
    let hole_area = (hole_max[0] - hole_min[0]) * (hole_max[1] - hole_min[1]);
    model.observed[0] = 1.0 - hole_area / (size * size);
    model
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

/// Beach scene: its sea wall's top and the road behind it, the ground that does not move
/// (`[x0, y0, x1, y1]`, local metres): what a user marks with `--stable`.
pub const BEACH_STABLE: [[f64; 4]; 2] = [[0.0, 40.0, 60.0, 41.5], [0.0, 41.5, 60.0, 46.0]];

/// beach: a 60 m × 46 m beach (y < 40, rising 3 % landward) below a sea wall (a 1 m block, y from
/// 40 to 41.5) and a road behind it (y > 41.5, level with the wall's foot + 1 m: the block's top
/// continues as the road, a plane). Between the surveys most of the beach moves: a lattice of
/// 6 m cells (10 along the shore, 6 across) each holding a cos² bump or dent of radius 2.9 m,
/// signs alternating like a chessboard, heights 0.1 to 1 m (a low-discrepancy spread), so 73 %
/// of the beach (taking in their skirts, where the sand moved a few centimetres) changed. On
/// the road, a pothole (box 2 m × 2 m, 8 cm deep) and a small heap (cos² R = 1.5 m, 10 cm): found
/// only at the surveys' true level of detection, which the sand must not inflate. Truth: each
/// bump ±h·R²(π/2 − 2/π), the box w·d·h.
fn beach() -> SceneModel {
    let size = [60.0, 46.0];
    let base = Base {
        z0: 100.0,
        gx: 0.0,
        gy: 0.03,
        waves: Vec::new(),
    };
    // The wall and the road: one block 1 m high over y ≥ 40 (its seaward face a wall patch).
    let wall = Feature::Block {
        min: [0.0, 40.0],
        max: [size[0], size[1]],
        height: 1.0,
    };
    let (pitch, radius) = (6.0, 2.9);
    let mut sand = Vec::new();
    let mut events = Vec::new();
    let f1 = Heightfield::new(base.clone(), vec![wall]);
    for j in 0..6 {
        for i in 0..10 {
            let k = j * 10 + i;
            let c = [pitch * (i as f64 + 0.5), 2.0 + pitch * (j as f64 + 0.5)];
            let sign = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
            let height = sign * (0.1 + 0.9 * ((0.5 + k as f64 * 0.618_033_988_749_894_9).fract()));
            sand.push(Feature::Bump { c, radius, height });
            events.push(ModelEvent {
                volume_m3: bump_volume(radius, height),
                centre: [c[0], c[1], z_at(&f1, c)],
                radius_m: radius,
                footprint: square(c, radius),
                covered_volume_m3: None,
                description: format!(
                    "sand {}: cos² R = {radius} m, h = {:.3} m",
                    if sign > 0.0 { "accreted" } else { "eroded" },
                    height.abs()
                ),
            });
        }
    }
    // On the road (its top at z = 101 + 0.03 y).
    let pothole = Feature::Block {
        min: [14.0, 43.0],
        max: [16.0, 45.0],
        height: -0.08,
    };
    let heap = Feature::Bump {
        c: [40.0, 44.0],
        radius: 1.5,
        height: 0.1,
    };
    // The pothole lies within the road's block: features add, and its volume is its own.
    events.push(ModelEvent {
        volume_m3: pothole.volume(),
        centre: [15.0, 44.0, z_at(&f1, [15.0, 44.0])],
        radius_m: 2f64.sqrt(),
        footprint: ground([14.0, 43.0], [16.0, 45.0]),
        covered_volume_m3: None,
        description: "pothole in the road: box 2 m × 2 m, 0.08 m deep".into(),
    });
    events.push(ModelEvent {
        volume_m3: heap.volume(),
        centre: [40.0, 44.0, z_at(&f1, [40.0, 44.0])],
        radius_m: 1.5,
        footprint: square([40.0, 44.0], 1.5),
        covered_volume_m3: None,
        description: "heap on the road: cos² R = 1.5 m, h = 0.1 m".into(),
    });
    let mut f2_features = vec![wall, heap, pothole];
    f2_features.extend(sand);
    let f2 = Heightfield::new(base.clone(), f2_features);
    // The wall's seaward face, from the beach up to its top.
    let face = || {
        vec![Patch::Wall {
            base: base.clone(),
            start: [0.0, 40.0],
            dir: [1.0, 0.0],
            len: size[0],
            z: [0.0, 1.0],
        }]
    };
    SceneModel::heightfield_scene(
        size,
        [f1, f2],
        [face(), face()],
        events,
        "a beach below a sea wall and a road: most of the sand moved by 0.1 to 1 m; a pothole and \
         a heap on the road",
    )
}

/// stable: 40 m × 40 m undulating surface, the same in both epochs except a 5 mm vertical shift of
/// epoch 2 (a registration error below any sensible detection threshold): no events.
fn stable() -> SceneModel {
    let base = |z0| Base {
        z0,
        gx: 0.0,
        gy: 0.0,
        waves: vec![
            wave(0.5, 25.0, f64::INFINITY, 0.3),
            wave(0.3, f64::INFINITY, 30.0, 1.0),
        ],
    };
    SceneModel::heightfield_scene(
        [40.0, 40.0],
        [
            Heightfield::new(base(100.0), Vec::new()),
            Heightfield::new(base(100.005), Vec::new()),
        ],
        [Vec::new(), Vec::new()],
        Vec::new(),
        "unchanged undulating surface resampled, epoch 2 shifted +5 mm in z",
    )
}

/// large: a square of side sqrt(points)·0.15 m of gently undulating terrain (slopes below 12 %)
/// with a grid of bumps and pits every 50 m (centres on multiples of 50 m, ≥ 25 m from the edges):
/// cos² bumps and dents (V = ±h·R²(π/2 − 2/π)) and spherical caps and dents (V = ±πh²(3R − h)/3).
fn large(points: u64) -> SceneModel {
    let side = (points as f64).sqrt() * LARGE_SPACING;
    let base = Base {
        z0: 100.0,
        gx: 0.0,
        gy: 0.0,
        waves: vec![
            wave(3.0, 400.0, 583.0, 0.3),
            wave(1.5, -520.0, 310.0, 1.1),
            wave(0.4, 90.0, 120.0, 2.0),
        ],
    };
    let f1 = Heightfield::new(base.clone(), Vec::new());
    // Centres k·pitch for k = 1..=n with k·pitch ≤ side − margin (and pitch ≥ margin).
    let n = ((side - LARGE_MARGIN) / LARGE_PITCH).floor().max(0.0) as usize;
    let mut features = Vec::new();
    let mut events = Vec::new();
    for j in 1..=n {
        for i in 1..=n {
            let c = [i as f64 * LARGE_PITCH, j as f64 * LARGE_PITCH];
            let sign = if (i + j) % 2 == 0 { 1.0 } else { -1.0 };
            let word = if sign > 0.0 { "bump" } else { "dent" };
            let (feature, volume, radius, what) = if (i / 2 + j) % 2 == 0 {
                let radius = 4.0 + (i % 3) as f64;
                let height = sign * (0.5 + 0.25 * (j % 3) as f64);
                (
                    Feature::Bump { c, radius, height },
                    bump_volume(radius, height),
                    radius,
                    format!("cos² {word} R = {radius} m, h = {} m", height.abs()),
                )
            } else {
                let sphere_radius = 8.0;
                let height = sign * (0.6 + 0.2 * (i % 3) as f64);
                (
                    Feature::Cap {
                        c,
                        sphere_radius,
                        height,
                    },
                    cap_volume(sphere_radius, height),
                    cap_footprint(sphere_radius, height),
                    format!(
                        "spherical {} R = {sphere_radius} m, h = {} m",
                        if sign > 0.0 { "cap" } else { "dent" },
                        height.abs()
                    ),
                )
            };
            features.push(feature);
            events.push(ModelEvent {
                volume_m3: volume,
                centre: [c[0], c[1], z_at(&f1, c)],
                radius_m: radius,
                footprint: square(c, radius),
                covered_volume_m3: None,
                description: what,
            });
        }
    }
    let f2 = Heightfield::new(base, features);
    SceneModel::heightfield_scene(
        [side, side],
        [f1, f2],
        [Vec::new(), Vec::new()],
        events,
        "undulating terrain with a 50 m grid of bumps and pits",
    )
}

/// Grid of cells of the events scene (x, y): one event per cell.
const EVENTS_GRID: [usize; 2] = [4, 3];
/// Side of an events cell (m).
const EVENTS_PITCH: f64 = 12.0;
/// Least distance between two events' footprints, and from a footprint to the scene's border (m):
/// each footprint stays half of it inside its cell, and the cells lie half of it inside the border.
const EVENTS_GAP: f64 = 5.0;
/// Range of the events' volumes (m³, absolute).
const EVENTS_VOLUME: [f64; 2] = [0.2, 6.0];
/// Random stream of the events scene's layout (the sampling streams are (epoch << 32) | strip).
const EVENTS_STREAM: u64 = u64::MAX;

/// Side lengths (x, y) of the events scene.
fn events_size() -> [f64; 2] {
    [0, 1].map(|k| EVENTS_GRID[k] as f64 * EVENTS_PITCH + EVENTS_GAP)
}

/// events: gently undulating ground (a tilt and two waves whose phases the seed draws; slopes
/// below 0.018 + 0.049 + 0.030 < 10 %) with a dozen events drawn from the seed, one per cell of a
/// 4 × 3 grid of 12 m cells: each of six kinds (box raised, box dug, spherical cap, spherical
/// dent, cos² bump, cos² dent) twice, in shuffled cells; volumes stratified over [0.2, 6] m³ on a
/// log scale (one per twelfth of the range, shuffled); shapes solved for the volume from a random
/// aspect (bump h/R and cap h/a in [0.2, 0.5], box height 0.3–0.8 m and side ratio 0.5–1), so
/// that footprints reach at most 3.2 m from their centre along x and y and fit in their cell with
/// 2.5 m to spare; centres uniform where they fit. Truth: bump ±h·R²(π/2 − 2/π), cap
/// ±πh²(3R − h)/3, box w·d·h, computed from the drawn dimensions.
fn events(seed: u64) -> SceneModel {
    #[derive(Clone, Copy)]
    enum Shape {
        Box,
        Cap,
        Bump,
    }
    let mut rng = Rng::new(seed, EVENTS_STREAM);
    let base = Base {
        z0: 100.0,
        gx: 0.015,
        gy: -0.01,
        waves: vec![
            wave(0.25, 40.0, 55.0, rng.range(0.0, TAU)),
            wave(0.07, -18.0, 25.0, rng.range(0.0, TAU)),
        ],
    };
    let n = EVENTS_GRID[0] * EVENTS_GRID[1];
    let [v0, v1] = EVENTS_VOLUME;
    let mut volumes: Vec<f64> = (0..n)
        .map(|k| v0 * (v1 / v0).powf((k as f64 + rng.uniform()) / n as f64))
        .collect();
    rng.shuffle(&mut volumes);
    let mut kinds: Vec<(Shape, f64)> = [Shape::Box, Shape::Cap, Shape::Bump]
        .into_iter()
        .flat_map(|s| [(s, 1.0), (s, -1.0)])
        .cycle()
        .take(n)
        .collect();
    rng.shuffle(&mut kinds);
    let f1 = Heightfield::new(base.clone(), Vec::new());
    let (mut features, mut walls, mut events) = (Vec::new(), Vec::new(), Vec::new());
    for (cell, (&(shape, sign), &volume)) in kinds.iter().zip(&volumes).enumerate() {
        // The feature centred on the origin and its description.
        let (feature, description) = match shape {
            Shape::Bump => {
                let aspect = rng.range(0.2, 0.5);
                let radius = (volume / (bump_volume(1.0, 1.0) * aspect)).cbrt();
                let height = sign * aspect * radius;
                let word = if sign > 0.0 { "bump" } else { "dent" };
                (
                    Feature::Bump {
                        c: [0.0; 2],
                        radius,
                        height,
                    },
                    format!("cos² {word} R = {radius:.3} m, h = {:.3} m", height.abs()),
                )
            }
            Shape::Cap => {
                // Footprint radius a and height h = t·a: V = πh(3a² + h²)/6 = πa³t(3 + t²)/6.
                let t = rng.range(0.2, 0.5);
                let a = (6.0 * volume / (PI * t * (3.0 + t * t))).cbrt();
                let h = t * a;
                let sphere_radius = (a * a + h * h) / (2.0 * h);
                let word = if sign > 0.0 { "cap" } else { "dent" };
                (
                    Feature::Cap {
                        c: [0.0; 2],
                        sphere_radius,
                        height: sign * h,
                    },
                    format!("spherical {word} R = {sphere_radius:.3} m, h = {h:.3} m"),
                )
            }
            Shape::Box => {
                let h = rng.range(0.3, 0.8);
                let ratio = rng.range(0.5, 1.0);
                let long = (volume / (h * ratio)).sqrt();
                let mut side = [long, ratio * long];
                if rng.uniform() < 0.5 {
                    side.swap(0, 1);
                }
                let word = if sign > 0.0 { "raised" } else { "dug" };
                (
                    Feature::Block {
                        min: side.map(|s| -s / 2.0),
                        max: side.map(|s| s / 2.0),
                        height: sign * h,
                    },
                    format!("box {word} {:.3} × {:.3} × {h:.3} m", side[0], side[1]),
                )
            }
        };
        let half = feature.bbox().1;
        let ij = [cell % EVENTS_GRID[0], cell / EVENTS_GRID[0]];
        let c = [0, 1].map(|k| {
            let lo = EVENTS_GAP + ij[k] as f64 * EVENTS_PITCH + half[k];
            let span = (EVENTS_PITCH - EVENTS_GAP - 2.0 * half[k]).max(0.0);
            lo + span * rng.uniform()
        });
        let feature = feature.moved(c);
        if let Feature::Block { min, max, height } = feature {
            walls.extend(box_walls_on(
                &base,
                min,
                max,
                [height.min(0.0), height.max(0.0)],
            ));
        }
        features.push(feature);
        events.push(ModelEvent {
            volume_m3: feature.volume(),
            centre: [c[0], c[1], z_at(&f1, c)],
            radius_m: half[0].hypot(half[1]),
            footprint: ground(
                [c[0] - half[0], c[1] - half[1]],
                [c[0] + half[0], c[1] + half[1]],
            ),
            covered_volume_m3: None,
            description,
        });
    }
    let f2 = Heightfield::new(base, features);
    SceneModel::heightfield_scene(
        events_size(),
        [f1, f2],
        [Vec::new(), walls],
        events,
        "undulating ground with a dozen seeded events: boxes raised and dug, spherical caps and \
         dents, cos² bumps and dents",
    )
}
