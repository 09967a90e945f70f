//! The scenes of larger terrain where much changes: beach, large and events.

use std::f64::consts::{PI, TAU};

use super::{
    ground, square, wave, z_at, ModelEvent, SceneModel, LARGE_MARGIN, LARGE_PITCH, LARGE_SPACING,
};
use crate::surface::{
    box_walls_on, bump_volume, cap_footprint, cap_volume, Base, Feature, Heightfield, Patch,
};
use talus_base::rng::Rng;

/// beach: a 60 m × 46 m beach (y < 40, rising 3 % landward) below a sea wall (a 1 m block, y from
/// 40 to 41.5) and a road behind it (y > 41.5, level with the wall's foot + 1 m: the block's top
/// continues as the road, a plane). Between the surveys most of the beach moves: a lattice of
/// 6 m cells (10 along the shore, 6 across) each holding a cos² bump or dent of radius 2.9 m,
/// signs alternating like a chessboard, heights 0.1 to 1 m (a low-discrepancy spread), so 73 %
/// of the beach (taking in their skirts, where the sand moved a few centimetres) changed. On
/// the road, a pothole (box 2 m × 2 m, 8 cm deep) and a small heap (cos² R = 1.5 m, 10 cm): found
/// only at the surveys' true level of detection, which the sand must not inflate. Truth: each
/// bump ±h·R²(π/2 − 2/π), the box w·d·h.
pub(super) fn beach() -> SceneModel {
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

/// large: a square of side sqrt(points)·0.15 m of gently undulating terrain (slopes below 12 %)
/// with a grid of bumps and pits every 50 m (centres on multiples of 50 m, ≥ 25 m from the edges):
/// cos² bumps and dents (V = ±h·R²(π/2 − 2/π)) and spherical caps and dents (V = ±πh²(3R − h)/3).
pub(super) fn large(points: u64) -> SceneModel {
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
pub(super) fn events(seed: u64) -> SceneModel {
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
