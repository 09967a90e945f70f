//! The scenes on a plane or gentle terrain with shapes of closed-form volume: hill, cube,
//! spheres, cubes, hole and stable.

use super::{ground, square, tilted_plane, wave, z_at, ModelEvent, SceneModel};
use crate::surface::{
    box_walls, bump_volume, cap_footprint, cap_volume, Base, Feature, Heightfield, Hole, Patch,
};

/// hill: a 40 m × 40 m tilted plane; epoch 2 adds h·cos²(πr/2R), R = 6 m, h = 1.5 m at the centre.
/// V = h·R²·(π/2 − 2/π) ≈ 50.44 m³.
pub(super) fn hill() -> SceneModel {
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
pub(super) fn cube() -> SceneModel {
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
pub(super) fn spheres() -> SceneModel {
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
pub(super) fn cubes() -> SceneModel {
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

/// hole: the hill scene's 40 m × 40 m tilted plane; epoch 2 adds h·cos²(πr/2R), R = 4 m, h = 1 m at (20, 20)
/// (V = h·R²(π/2 − 2/π) ≈ 14.95 m³). Epoch 1 has no points over x ∈ [20, 30), y ∈ [12, 28) (a
/// water body or an occlusion): the hole's edge x = 20 runs through the bump's centre, so epoch 1
/// sees the half x < 20 of the event, and by the bump's symmetry that half holds V/2. Epoch 1 is
/// sampled only outside the hole, with 90 % of the requested points (the plane's area outside it),
/// so its density matches epoch 2's.
pub(super) fn hole() -> SceneModel {
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

/// stable: 40 m × 40 m undulating surface, the same in both epochs except a 5 mm vertical shift of
/// epoch 2 (a registration error below any sensible detection threshold): no events.
pub(super) fn stable() -> SceneModel {
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
