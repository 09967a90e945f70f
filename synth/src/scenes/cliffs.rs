//! The cliff scenes: a beach at the foot of a vertical face with a plateau on top (cliff,
//! dense, vegetation, deposit), and the scars and events of a face.

use std::f64::consts::{PI, TAU};

use super::{ground, height_patch, square, z_at, Footprint, ModelEvent, Scar, SceneModel};
use crate::plants::{Plant, PlantKind, Standing};
use crate::surface::{box_walls, bump_volume, Base, Feature, Heightfield, Hole, Patch};
use talus_base::rng::Rng;

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
pub(super) fn cliff() -> SceneModel {
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
pub(super) fn dense() -> SceneModel {
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
pub(super) fn vegetation() -> SceneModel {
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
pub(super) fn deposit() -> SceneModel {
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
