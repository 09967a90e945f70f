//! Accuracy of `talus compare` against ground truth we did not compute with the pipeline: the
//! closed-form volumes of the `talus synth` scenes (bump h·R²(π/2 − 2/π), spherical caps
//! πh²(3R − h)/3, boxes w·d·h, half-ellipsoid (2/3)πabc, half-cone πR²H/6; checked against
//! numerical integration in tests/synth/), and a gain/loss pair of boxes built here.
//!
//! Issue "Change events and their volumes", item 5: every event of the paper's four tests (hill,
//! cube, spheres, cubes) and of the cliff scene within 2 % (Gorup & Bohak report 10 % on their
//! mixed "cubes" test); cliff scars measured along the horizontal axis; a gain and a loss 1 m
//! apart as two events; a rotated cliff; epoch 2 at half the density; a stable scene with no
//! event above 0.2 m³. Item 3: every written solid is watertight (`check_watertight`), and the
//! solids' volumes, recomputed here by the divergence theorem, give the reported volume.
//!
//! Everything runs the real binary with default parameters only (no tuning flags). Each scene is
//! its own test function so that the harness runs them in parallel. Run
//! `cargo test --test accuracy -- --nocapture` to see the accuracy table.

mod common;

use std::path::Path;

use serde_json::Value;
use talus::io::mesh_ply::read_ply_mesh;
use talus::synth::Truth;
use talus::volume::check_watertight;

/// Relative volume tolerance of the issue: 2 % of the true volume.
const REL_TOL: f64 = 0.02;
/// A found event matches a truth event of the same kind when its centroid lies within this
/// distance (m) of the truth centre. The truth centre is the footprint centre on the epoch-1
/// surface while talus reports the centroid of the changed core points, which differ by up to
/// about 1 m for asymmetric shapes (the debris fan's half-cone); the nearest other event of any
/// scene is more than 10 m away, so 3 m cannot pick the wrong one.
const MATCH_DIST: f64 = 3.0;
/// Largest |volume| (m³) an event may have without matching a planted event. This is the
/// false-positive bound the issue sets for the stable scene (1 cm noise, 5 mm shift): anything
/// larger is either a spurious detection or a planted event split in two (the smallest planted
/// event is 1.44 m³, so a split-off part above 0.2 m³ would also cost its match more than 2 % in
/// most scenes, and we want to see it named rather than hidden in that error).
const STRAY_MAX: f64 = 0.2;
/// The reported uncertainty must bracket the error: |V − V_true| ≤ UNC_K · U. talus reports at
/// least the conservative bound area × mean LoD95 (a 95 % level), so 1 would do; 2 leaves room
/// for a tighter (e.g. one-sigma) estimate the spec welcomes, without allowing a vacuous one.
const UNC_K: f64 = 2.0;
/// ... and must not be vacuous: U ≤ UNC_MAX_REL · |V_true| (an uncertainty of half the volume
/// would make the event's volume meaningless).
const UNC_MAX_REL: f64 = 0.5;

// ---------------------------------------------------------------- running talus

/// Run `talus synth SCENE --out DIR [extra...]` and read its truth.json.
fn synth(scene: &str, extra: &[&str], dir: &Path) -> Truth {
    let out = dir.to_str().expect("utf-8 temp path");
    let mut args = vec!["synth", scene, "--out", out];
    args.extend_from_slice(extra);
    let o = common::run(&args);
    assert!(
        o.status.success(),
        "talus {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let text = std::fs::read_to_string(dir.join("truth.json")).expect("truth.json written");
    serde_json::from_str(&text).expect("truth.json parses")
}

/// One event of events.geojson.
#[derive(Debug, Clone)]
struct Found {
    id: u64,
    kind: String,
    volume: f64,
    uncertainty: f64,
    gain: f64,
    loss: f64,
    n_points: u64,
    centre: [f64; 3],
    /// OBB axes (rows); the third is the extrusion direction, out of the terrain.
    axes: [[f64; 3]; 3],
    note: Option<String>,
}

fn num(v: &Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("property {key} is not a number: {v}"))
}

fn vec3(v: &Value) -> [f64; 3] {
    std::array::from_fn(|k| {
        v[k].as_f64()
            .unwrap_or_else(|| panic!("not a 3-vector: {v}"))
    })
}

/// Run `talus compare BEFORE AFTER --out RES` (defaults only), read events.geojson, and check
/// every written solid (see [`check_solids`]).
fn compare(before: &Path, after: &Path, res: &Path) -> Vec<Found> {
    compare_with(before, after, res, &[])
}

/// [`compare`] with `extra` arguments.
fn compare_with(before: &Path, after: &Path, res: &Path, extra: &[&str]) -> Vec<Found> {
    let o = common::run_compare(before, after, res, extra);
    assert!(
        o.status.success(),
        "talus compare {} failed: {}",
        before.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    let text = std::fs::read_to_string(res.join("events.geojson")).expect("events.geojson");
    let gj: Value = serde_json::from_str(&text).expect("events.geojson parses");
    assert_eq!(gj["type"], "FeatureCollection");
    let found: Vec<Found> = gj["features"]
        .as_array()
        .expect("features array")
        .iter()
        .map(|f| {
            let p = &f["properties"];
            let axes = &p["obb"]["axes"];
            Found {
                id: p["id"].as_u64().expect("id"),
                kind: p["kind"].as_str().expect("kind").to_string(),
                volume: num(p, "volume_m3"),
                uncertainty: num(p, "volume_uncertainty_m3"),
                gain: num(p, "gain_m3"),
                loss: num(p, "loss_m3"),
                n_points: p["n_points"].as_u64().expect("n_points"),
                centre: vec3(&f["geometry"]["coordinates"]),
                axes: [vec3(&axes[0]), vec3(&axes[1]), vec3(&axes[2])],
                note: p["volume_note"].as_str().map(str::to_string),
            }
        })
        .collect();
    check_solids(res, &found);
    found
}

/// Issue item 3: both solids of every event are watertight (every edge shared by exactly two
/// faces, once in each direction, positive volume), and V(after) − V(before) of the written
/// solids is the reported volume_m3.
fn check_solids(res: &Path, found: &[Found]) {
    for e in found {
        let mut v = [0.0; 2];
        for (k, which) in ["before", "after"].into_iter().enumerate() {
            let path = res
                .join("meshes")
                .join(format!("event_{:04}_{which}.ply", e.id));
            let mesh =
                read_ply_mesh(&path).unwrap_or_else(|err| panic!("{}: {err}", path.display()));
            if let Err(why) = check_watertight(&mesh) {
                panic!("{} is not a watertight solid: {why}", path.display());
            }
            v[k] = talus::volume::solid::signed_volume(&mesh);
        }
        let dv = v[1] - v[0];
        assert!(
            (dv - e.volume).abs() <= 1e-6 * (1.0 + v[0].abs() + v[1].abs()),
            "event {}: solids give V(after) − V(before) = {} − {} = {dv}, reported {}",
            e.id,
            v[1],
            v[0],
            e.volume
        );
    }
}

// ---------------------------------------------------------------- judging

/// A planted event: kind, signed volume, centre (global), what it is.
#[derive(Debug, Clone)]
struct Planted {
    kind: String,
    volume: f64,
    centre: [f64; 3],
    what: String,
}

fn planted(truth: &Truth) -> Vec<Planted> {
    truth
        .events
        .iter()
        .map(|e| Planted {
            kind: e.kind.clone(),
            volume: e.volume_m3,
            centre: e.centre,
            what: e.description.clone(),
        })
        .collect()
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// For each planted event, the index of its found event (nearest centroid of the same kind
/// within [`MATCH_DIST`], each found event used once), or None.
fn match_events(planted: &[Planted], found: &[Found]) -> Vec<Option<usize>> {
    // Pairs by increasing distance, taken greedily: a found event goes to its closest truth.
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (t, p) in planted.iter().enumerate() {
        for (f, e) in found.iter().enumerate() {
            let d = dist(p.centre, e.centre);
            if e.kind == p.kind && d <= MATCH_DIST {
                pairs.push((d, t, f));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut of_truth = vec![None; planted.len()];
    let mut used = vec![false; found.len()];
    for (_, t, f) in pairs {
        if of_truth[t].is_none() && !used[f] {
            of_truth[t] = Some(f);
            used[f] = true;
        }
    }
    of_truth
}

/// Check a run against its planted events; prints the accuracy table rows of `scene` and
/// returns the matches. Panics listing every failure (never a widened tolerance).
fn judge(scene: &str, planted: &[Planted], found: &[Found]) -> Vec<Option<usize>> {
    let matches = match_events(planted, found);
    let mut table = String::new();
    let mut fails = Vec::new();
    for (p, m) in planted.iter().zip(&matches) {
        let Some(f) = *m else {
            table.push_str(&format!(
                "| {scene} | {} | {:+.3} | (none) | | | |\n",
                p.what, p.volume
            ));
            fails.push(format!(
                "{scene}: planted {} {} ({:+.3} m³ at {:?}) has no found {} event within {MATCH_DIST} m",
                p.kind, p.what, p.volume, p.centre, p.kind
            ));
            continue;
        };
        let e = &found[f];
        let err = e.volume - p.volume;
        let rel = err / p.volume.abs();
        table.push_str(&format!(
            "| {scene} | {} | {:+.3} | {:+.3} | {:+.2} | ±{:.3} | {} |\n",
            p.what,
            p.volume,
            e.volume,
            100.0 * rel,
            e.uncertainty,
            e.n_points
        ));
        let ctx = format!(
            "{scene}: {} (true {:+.4} m³) ↔ event {} ({:+.4} m³ ± {:.4}, gain {:+.4}, loss {:+.4}, {} core points, centroid {:.2} m from the truth{})",
            p.what,
            p.volume,
            e.id,
            e.volume,
            e.uncertainty,
            e.gain,
            e.loss,
            e.n_points,
            dist(p.centre, e.centre),
            e.note.as_deref().map(|n| format!(", note: {n}")).unwrap_or_default()
        );
        if rel.abs() > REL_TOL {
            fails.push(format!(
                "{ctx}: error {:+.2} % exceeds {} %",
                100.0 * rel,
                100.0 * REL_TOL
            ));
        }
        if !(e.uncertainty > 0.0 && err.abs() <= UNC_K * e.uncertainty) {
            fails.push(format!(
                "{ctx}: error {err:+.4} m³ is outside {UNC_K} × the reported uncertainty"
            ));
        }
        if e.uncertainty > UNC_MAX_REL * p.volume.abs() {
            fails.push(format!(
                "{ctx}: uncertainty is more than {} % of the volume",
                100.0 * UNC_MAX_REL
            ));
        }
    }
    for (f, e) in found.iter().enumerate() {
        if matches.contains(&Some(f)) {
            continue;
        }
        table.push_str(&format!(
            "| {scene} | unmatched event {} ({}) | | {:+.3} | | ±{:.3} | {} |\n",
            e.id, e.kind, e.volume, e.uncertainty, e.n_points
        ));
        if e.volume.abs() > STRAY_MAX {
            fails.push(format!(
                "{scene}: found {} event {} ({:+.4} m³, {} core points) at {:?} matches no planted event and exceeds {STRAY_MAX} m³",
                e.kind, e.id, e.volume, e.n_points, e.centre
            ));
        }
    }
    eprint!("{table}");
    assert!(fails.is_empty(), "{}", fails.join("\n"));
    matches
}

/// Synthesize `scene` with `extra` synth options (scene variants, never compare tuning), compare
/// with default parameters, judge. Returns the truth, the found events and the matches.
fn run_scene(scene: &str, extra: &[&str]) -> (Truth, Vec<Found>, Vec<Option<usize>>) {
    let dir = common::tempdir();
    let data = dir.path().join("data");
    let truth = synth(scene, extra, &data);
    let found = compare(
        &data.join("before.laz"),
        &data.join("after.laz"),
        &dir.path().join("res"),
    );
    let label = if extra.is_empty() {
        scene.to_string()
    } else {
        format!("{scene} {}", extra.join(" "))
    };
    let matches = judge(&label, &planted(&truth), &found);
    (truth, found, matches)
}

/// The cliff's scars (rockfall losses in the vertical face) must be measured along the horizontal
/// axis: the OBB's third axis horizontal and pointing out of the face. The face is the plane
/// y = 0 with rock at y > 0 (outward normal −y) before `--rotate θ` turns the scene
/// counter-clockwise about the vertical, which turns the outward normal to (sin θ, −cos θ, 0).
fn check_scars(label: &str, truth: &Truth, found: &[Found], matches: &[Option<usize>]) {
    let th = truth.rotate_deg.to_radians();
    let out = [th.sin(), -th.cos(), 0.0];
    let mut n = 0;
    for (t, m) in truth.events.iter().zip(matches) {
        if !t.description.contains("scar") {
            continue;
        }
        n += 1;
        let e = &found[m.expect("judged: every event matched")];
        let a = e.axes[2];
        let along = a[0] * out[0] + a[1] * out[1] + a[2] * out[2];
        eprintln!(
            "{label}: {} — OBB axis 3 = [{:.3}, {:.3}, {:.3}], outward face normal [{:.3}, {:.3}, 0], cos = {along:.3}",
            t.description, a[0], a[1], a[2], out[0], out[1]
        );
        assert!(
            a[2].abs() < 0.2,
            "{label}: {}: OBB third axis {a:?} is not horizontal",
            t.description
        );
        assert!(
            along > 0.9,
            "{label}: {}: OBB third axis {a:?} does not point out of the face {out:?} (cos {along:.3})",
            t.description
        );
    }
    assert_eq!(n, 2, "the cliff scene has two scars");
}

// ---------------------------------------------------------------- the paper's tests and the cliff

#[test]
fn hill_within_2_percent() {
    run_scene("hill", &[]);
}

#[test]
fn cube_within_2_percent() {
    run_scene("cube", &[]);
}

#[test]
fn spheres_within_2_percent() {
    run_scene("spheres", &[]);
}

/// The paper's mixed test (10 % error there): removed, placed, grown and dug boxes, plus an
/// unchanged box that must give no event.
#[test]
fn cubes_within_2_percent() {
    let (truth, _, _) = run_scene("cubes", &[]);
    assert_eq!(truth.events.len(), 4, "A–D change, E is the control");
}

/// Also: the scars are measured along the horizontal axis.
#[test]
fn cliff_within_2_percent_scars_horizontal() {
    let (truth, found, m) = run_scene("cliff", &[]);
    check_scars("cliff", &truth, &found, &m);
}

// ---------------------------------------------------------------- rotation and density

/// The cliff turned 30° about the vertical: its face is aligned with neither axis.
#[test]
fn rotated_cliff_within_2_percent() {
    let (truth, found, m) = run_scene("cliff", &["--rotate", "30"]);
    check_scars("cliff --rotate 30", &truth, &found, &m);
}

/// The mixed boxes turned 37°: box edges aligned with neither axis.
#[test]
fn rotated_cubes_within_2_percent() {
    run_scene("cubes", &["--rotate", "37"]);
}

#[test]
fn half_density_cube_within_2_percent() {
    run_scene("cube", &["--density2", "0.5"]);
}

#[test]
fn half_density_cliff_within_2_percent() {
    let (truth, found, m) = run_scene("cliff", &["--density2", "0.5"]);
    check_scars("cliff --density2 0.5", &truth, &found, &m);
}

// ---------------------------------------------------------------- stable

/// Independent resampling, 1 cm noise, a 5 mm vertical shift: no event above 0.2 m³.
#[test]
fn stable_scene_has_no_event_above_0_2_m3() {
    let (truth, found, _) = run_scene("stable", &[]);
    assert!(truth.events.is_empty());
    let worst = found.iter().map(|e| e.volume.abs()).fold(0.0, f64::max);
    eprintln!(
        "| stable | {} event(s), largest |V| | 0 | {worst:.3} | | | |",
        found.len()
    );
    // judge() already failed on any event above STRAY_MAX = 0.2 m³; say it here too.
    assert!(worst <= 0.2, "{found:?}");
}

// ---------------------------------------------------------------- a gain and a loss 1 m apart

/// Points per m² of the pair scene: about 0.1 m spacing, like the synth scenes' defaults.
const PAIR_DENSITY: f64 = 100.0;
/// Noise along the surface normal (m), as synth's default.
const PAIR_NOISE: f64 = 0.005;

/// An axis-aligned rectangle of the ground, local coordinates.
#[derive(Clone, Copy)]
struct Rect {
    min: [f64; 2],
    max: [f64; 2],
}

impl Rect {
    fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.min[0] && x < self.max[0] && y >= self.min[1] && y < self.max[1]
    }
    fn area(&self) -> f64 {
        (self.max[0] - self.min[0]) * (self.max[1] - self.min[1])
    }
    fn centre(&self) -> [f64; 2] {
        [
            (self.min[0] + self.max[0]) / 2.0,
            (self.min[1] + self.max[1]) / 2.0,
        ]
    }
}

/// `n` points uniform by area on the four vertical walls of `r` between heights z0 and z1, with
/// noise along the wall normal (its sign does not matter for symmetric noise).
fn walls(rng: &mut common::Rng, r: Rect, z0: f64, z1: f64, out: &mut Vec<[f64; 3]>) {
    let (w, d) = (r.max[0] - r.min[0], r.max[1] - r.min[1]);
    let perimeter = 2.0 * (w + d);
    let n = (PAIR_DENSITY * perimeter * (z1 - z0)).round() as usize;
    for _ in 0..n {
        let s = rng.uniform() * perimeter;
        let z = z0 + rng.uniform() * (z1 - z0);
        let e = PAIR_NOISE * rng.normal();
        let (x, y) = if s < w {
            (r.min[0] + s, r.min[1] + e)
        } else if s < w + d {
            (r.max[0] + e, r.min[1] + (s - w))
        } else if s < 2.0 * w + d {
            (r.max[0] - (s - w - d), r.max[1] + e)
        } else {
            (r.min[0] + e, r.max[1] - (s - 2.0 * w - d))
        };
        out.push([x, y, z]);
    }
}

/// One epoch of the pair scene: a level plane z = 0 over `size`², with, when `changed`, the
/// ground inside `raise` lifted by `h` and inside `sink` lowered by `h` (tops, floors and walls
/// sampled). Global coordinates (OFFSET added).
fn pair_epoch(seed: u64, size: f64, changed: Option<(Rect, Rect, f64)>) -> Vec<[f64; 3]> {
    let mut rng = common::Rng::new(seed);
    let n = (PAIR_DENSITY * size * size).round() as usize;
    let mut pts = Vec::with_capacity(n + n / 10);
    for _ in 0..n {
        let (x, y) = (rng.uniform() * size, rng.uniform() * size);
        let z = match changed {
            Some((raise, _, h)) if raise.contains(x, y) => h,
            Some((_, sink, h)) if sink.contains(x, y) => -h,
            _ => 0.0,
        };
        pts.push([x, y, z + PAIR_NOISE * rng.normal()]);
    }
    if let Some((raise, sink, h)) = changed {
        walls(&mut rng, raise, 0.0, h, &mut pts);
        walls(&mut rng, sink, -h, 0.0, &mut pts);
    }
    for p in &mut pts {
        for (c, o) in p.iter_mut().zip(common::OFFSET) {
            *c += o;
        }
    }
    pts
}

/// A 4 × 4 × 1 m box raised and a 4 × 4 × 1 m pit dug, their footprints 1 m apart (x ∈ [10, 14]
/// and [15, 19]): exactly two events, +16 m³ and −16 m³, each within 2 %. This is where a
/// footprint grown by the margin, or a rotated OBB, could swallow part of the neighbour.
#[test]
fn gain_and_loss_1_m_apart_are_two_events() {
    let dir = common::tempdir();
    let size = 30.0;
    let h = 1.0;
    let raise = Rect {
        min: [10.0, 13.0],
        max: [14.0, 17.0],
    };
    let sink = Rect {
        min: [15.0, 13.0],
        max: [19.0, 17.0],
    };
    assert_eq!(sink.min[0] - raise.max[0], 1.0);
    let before = dir.path().join("before.laz");
    let after = dir.path().join("after.laz");
    common::write_cloud(&before, &pair_epoch(11, size, None));
    common::write_cloud(&after, &pair_epoch(12, size, Some((raise, sink, h))));
    let at = |r: Rect| {
        let c = r.centre();
        [
            common::OFFSET[0] + c[0],
            common::OFFSET[1] + c[1],
            common::OFFSET[2],
        ]
    };
    let planted = vec![
        Planted {
            kind: "gain".into(),
            volume: raise.area() * h,
            centre: at(raise),
            what: "box raised 1 m (4 × 4 m)".into(),
        },
        Planted {
            kind: "loss".into(),
            volume: -sink.area() * h,
            centre: at(sink),
            what: "pit dug 1 m (4 × 4 m), 1 m from the box".into(),
        },
    ];
    let found = compare(&before, &after, &dir.path().join("res"));
    judge("gain+loss 1 m apart", &planted, &found);
    assert_eq!(
        found.iter().filter(|e| e.volume.abs() > STRAY_MAX).count(),
        2,
        "exactly two events: {found:?}"
    );
}

/// Issue "Volumes that add up on real surveys", item 2: a deposit on the beach 1.5 m in front of
/// the cliff foot, not touching the face, is one gain event (within 2 % here, 5 % asked) and the
/// face gets none: the face-foot cylinders that reach across the gap to the deposit keep the
/// face's own points only (m3c2::cylinder, "one surface per cylinder").
#[test]
fn a_deposit_near_the_cliff_foot_is_one_event() {
    let (_, found, matches) = run_scene("deposit", &[]);
    assert_eq!(matches, vec![Some(0)]);
    assert_eq!(
        found.len(),
        1,
        "no second event, on the face or anywhere: {found:?}"
    );
}

/// Issue item 1: an event half inside a hole of the before epoch (no points over a rectangle
/// through its centre) is measured over its covered half, within 5 %, and its coverage says so.
#[test]
fn an_event_half_in_a_hole_is_measured_over_its_covered_half() {
    let dir = common::tempdir();
    let data = dir.path().join("data");
    let truth = synth("hole", &[], &data);
    let res = dir.path().join("res");
    let found = compare(&data.join("before.laz"), &data.join("after.laz"), &res);
    let t = &truth.events[0];
    let covered = t
        .covered_volume_m3
        .expect("the hole scene gives the covered part");
    assert_eq!(found.len(), 1, "{found:?}");
    let e = &found[0];
    let rel = (e.volume - covered) / covered;
    eprintln!(
        "hole: whole event {:+.3} m³, covered part {covered:+.3} m³, measured {:+.3} m³ ({:+.2} %)",
        t.volume_m3,
        e.volume,
        100.0 * rel
    );
    assert!(rel.abs() <= 0.05, "{rel}");
    let gj: Value =
        serde_json::from_str(&std::fs::read_to_string(res.join("events.geojson")).unwrap())
            .unwrap();
    let coverage = gj["features"][0]["properties"]["coverage"]
        .as_f64()
        .unwrap();
    assert!(coverage < 0.95 && coverage > 0.5, "coverage {coverage}");
}

// ---------------------------------------------------------------- change of any depth

/// Issue "Change of any depth", item 4: a terrestrial-density cliff (`talus synth dense`: 4.4M
/// points per epoch, about 1.5 cm spacing) with changes from 0.1 m to 3 m deep on the face, at
/// its foot and on the plateau. With defaults every event is within 2 % and complete: the
/// derived half-length (about 0.4 m here) is only a search window. With a user-given
/// `--cyl-halflen 0.3`, every event deeper than that says it is incomplete and why (its core
/// points have the other survey beyond the half-length), and the shallow scar stays complete.
#[test]
fn dense_cliff_within_2_percent_and_a_short_user_halflen_flags_deep_events() {
    let (truth, found, m) = run_scene("dense", &[]);
    for (t, i) in truth.events.iter().zip(&m) {
        let e = &found[i.expect("judged: every event matched")];
        assert!(e.note.is_none(), "{}: {:?}", t.description, e.note);
    }
    let dir = common::tempdir();
    let data = dir.path().join("data");
    synth("dense", &[], &data);
    let res = dir.path().join("short");
    let o = common::run_compare(
        &data.join("before.laz"),
        &data.join("after.laz"),
        &res,
        &["--cyl-halflen", "0.3"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let line = String::from_utf8_lossy(&o.stderr);
    let gj: Value =
        serde_json::from_str(&std::fs::read_to_string(res.join("events.geojson")).unwrap())
            .unwrap();
    let short: Vec<&Value> = gj["features"].as_array().unwrap().iter().collect();
    let mut deep = 0;
    for t in &truth.events {
        let f = short
            .iter()
            .filter(|f| f["properties"]["kind"] == t.kind.as_str())
            .min_by(|a, b| {
                let d = |f: &Value| dist(vec3(&f["geometry"]["coordinates"]), t.centre);
                d(a).total_cmp(&d(b))
            })
            .expect("an event of its kind");
        let p = &f["properties"];
        let depth = p["max_abs_distance_m"].as_f64().unwrap();
        if t.description.contains("0.1 m deep") {
            assert_eq!(p["complete"], true, "{}: {p}", t.description);
        } else {
            deep += 1;
            assert_eq!(p["complete"], false, "{} ({depth} m): {p}", t.description);
            let note = p["volume_note"].as_str().unwrap_or_default();
            assert!(
                note.contains("beyond the M3C2 cylinder's half-length"),
                "{note}"
            );
        }
    }
    assert_eq!(deep, 5, "five events deeper than 0.3 m");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(res.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["reach"]["rule"], "flag");
    assert!(summary["reach"]["beyond_reach_points"].as_u64().unwrap() > 0);
    assert_eq!(summary["reach"]["incomplete_events"], 5);
    // Measured in part, they are bounds, reported apart from the totals.
    assert_eq!(summary["totals"]["incomplete_events"], 5);
    assert!(
        line.contains("5 incomplete, measured in part: at least"),
        "{line}"
    );
}

// ---------------------------------------------------------------- misregistered surveys

/// The cliff with its after survey off by `shift` (m) and `turn` (degrees about x, y, z through
/// the scene's centre at its mean height): after the alignment on the stable ground every planted event is within
/// 2 % (and inside its interval: [`judge`]), the alignment is applied, and every component of the
/// misregistration the stable ground constrains is recovered within 4 of its standard errors
/// (plus the second-order part of the turn a linear fit leaves, θ² × 40 m, and the 1 mm
/// coordinate quantum: 1 mm for translations, 1 mm over a 20 m radius for turns); a component it does not constrain has no standard
/// error and is left where it was.
fn misregistered_cliff(shift: [f64; 3], turn: [f64; 3]) -> Value {
    let s = format!("{},{},{}", shift[0], shift[1], shift[2]);
    let t = format!("{},{},{}", turn[0], turn[1], turn[2]);
    let dir = common::tempdir();
    let data = dir.path().join("data");
    let truth = synth("cliff", &["--shift", &s, "--turn", &t], &data);
    let res = dir.path().join("res");
    let found = compare(&data.join("before.laz"), &data.join("after.laz"), &res);
    let label = format!("cliff --shift {s} --turn {t}");
    judge(&label, &planted(&truth), &found);
    let summary: Value =
        serde_json::from_slice(&std::fs::read(res.join("summary.json")).unwrap()).unwrap();
    let a = summary["alignment"].clone();
    assert_eq!(a["applied"], true, "{label}: {a}");
    // The planted misregistration: x' = R (x − C) + C + shift, R = Rz Ry Rx, C the turn's
    // centre. Its rotation vector is the turn to first order; its translation at the fit's
    // origin o is where it moves o.
    let c = truth.turn_centre.unwrap_or([0.0; 3]);
    let [rx, ry, rz] = turn.map(f64::to_radians);
    let rot = |p: [f64; 3]| -> [f64; 3] {
        let (sx, cx) = rx.sin_cos();
        let (sy, cy) = ry.sin_cos();
        let (sz, cz) = rz.sin_cos();
        let p = [p[0], cx * p[1] - sx * p[2], sx * p[1] + cx * p[2]];
        let p = [cy * p[0] + sy * p[2], p[1], -sy * p[0] + cy * p[2]];
        [cz * p[0] - sz * p[1], sz * p[0] + cz * p[1], p[2]]
    };
    let o = vec3(&a["origin"]);
    let r = rot([o[0] - c[0], o[1] - c[1], o[2] - c[2]]);
    let planted_t: [f64; 3] = std::array::from_fn(|k| r[k] + c[k] + shift[k] - o[k]);
    let planted_w = [rx, ry, rz];
    let theta2 = rx * rx + ry * ry + rz * rz;
    let fitted_t = vec3(&a["translation"]);
    let fitted_w = vec3(&a["rotation"]);
    for k in 0..3 {
        for (what, fitted, planted, sd, slack) in [
            (
                "translation",
                fitted_t[k],
                planted_t[k],
                &a["translation_sd"][k],
                theta2 * 40.0 + 0.001,
            ),
            (
                "rotation",
                fitted_w[k],
                planted_w[k],
                &a["rotation_sd"][k],
                // The coordinates' 1 mm quantum over the stable ground's ≈ 20 m radius.
                theta2 + 0.001 / 20.0,
            ),
        ] {
            match sd.as_f64() {
                Some(sd) => {
                    let allowed = 4.0 * sd + slack;
                    eprintln!(
                        "{label}: {what}[{k}] fitted {fitted:+.6}, planted {planted:+.6}, \
                         sd {sd:.2e}, allowed {allowed:.2e}"
                    );
                    assert!(
                        (fitted - planted).abs() <= allowed,
                        "{label}: {what}[{k}] {fitted} vs planted {planted} (allowed {allowed}): {a}"
                    );
                }
                None => {
                    eprintln!("{label}: {what}[{k}] not constrained by the stable ground");
                    // Left (to within a tenth of a millimetre, or of a microradian) where it was.
                    assert!(
                        fitted.abs() < 1e-4,
                        "{label}: unconstrained {what}[{k}] moved: {a}"
                    );
                }
            }
        }
    }
    summary
}

#[test]
fn misregistered_cliff_shift_and_vertical_turn_within_2_percent() {
    // The case: (+6, −4, +8) cm and 0.1° about the vertical.
    misregistered_cliff([0.06, -0.04, 0.08], [0.0, 0.0, 0.1]);
}

#[test]
fn misregistered_cliff_20_cm_and_turns_about_the_horizontal_axes() {
    misregistered_cliff([0.2, 0.0, -0.01], [0.0, 0.0, 0.0]);
    misregistered_cliff([0.0, 0.0, 0.0], [0.3, 0.0, 0.0]);
    misregistered_cliff([0.01, 0.0, 0.0], [0.0, 0.3, 0.0]);
}

#[test]
fn misregistered_cliff_by_a_centimetre_and_two_hundredths_of_a_degree() {
    // The smallest of the range, about every axis at once.
    misregistered_cliff([0.01, -0.01, 0.01], [0.02, -0.02, 0.02]);
}

/// The cliff synthesised with `synth_args`, compared with `--align auto` and `--align off`: the
/// alignment of the auto run (asserted not applied) and whether every output of `files` is the
/// same bytes in both.
fn not_aligned(synth_args: &[&str], files: &[&str]) -> Value {
    let dir = common::tempdir();
    let data = dir.path().join("data");
    synth("cliff", synth_args, &data);
    let (b, a) = (data.join("before.laz"), data.join("after.laz"));
    let auto = dir.path().join("auto");
    let off = dir.path().join("off");
    assert!(common::run_compare(&b, &a, &auto, &[]).status.success());
    assert!(common::run_compare(&b, &a, &off, &["--align", "off"])
        .status
        .success());
    let summary: Value =
        serde_json::from_slice(&std::fs::read(auto.join("summary.json")).unwrap()).unwrap();
    let alignment = summary["alignment"].clone();
    eprintln!("{alignment}");
    assert_eq!(alignment["applied"], false, "{alignment}");
    let reason = alignment["reason"].as_str().unwrap();
    assert!(reason.starts_with("not applied"), "{reason}");
    for f in files {
        assert!(
            std::fs::read(auto.join(f)).unwrap() == std::fs::read(off.join(f)).unwrap(),
            "{f} differs between --align auto (not applied) and --align off"
        );
    }
    let off_summary: Value =
        serde_json::from_slice(&std::fs::read(off.join("summary.json")).unwrap()).unwrap();
    assert!(off_summary.get("alignment").is_none());
    alignment
}

#[test]
fn a_registered_cliff_is_not_aligned_and_its_results_are_those_of_align_off() {
    not_aligned(
        &[],
        &[
            "m3c2.laz",
            "events.geojson",
            "events.csv",
            "event_regions.geojson",
        ],
    );
}

/// A slow landslide under the whole cliff (`synth --creep 0.1`: every point of the after survey
/// settles by 2.5 to 10 cm, by amounts varying smoothly over the scene; the face, vertical, shows
/// none of it): a rigid fit can hold still the places whose settling happens to agree, but not
/// the ground as a whole, and a misregistration removed would. Not applied, the reason says so,
/// and the results are those of `--align off`.
#[test]
fn a_slow_landslide_is_not_taken_for_a_misregistration() {
    let alignment = not_aligned(
        &["--creep", "0.1"],
        &["m3c2.laz", "events.geojson", "events.csv"],
    );
    let reason = alignment["reason"].as_str().unwrap();
    assert!(reason.contains("at rest"), "{reason}");
    assert!(
        alignment["at_rest_share"].as_f64().unwrap() < 0.5,
        "{alignment}"
    );
}

/// Issue 43, item 4: stable areas that see only part of the motion. The cliff shifted 8 cm along
/// its face and turned 0.1° about the vertical; the user's stable areas are flat rectangles on
/// the plateau and the beach (ground that truly does not change), which see the vertical and the
/// tilts but neither horizontal shift nor the turn. The rest must not be left in silently: every
/// planted event within 2 % and inside its interval ([`judge`]), as without `--stable`.
#[test]
fn flat_stable_areas_on_a_turned_cliff_leave_nothing_hidden() {
    let dir = common::tempdir();
    let data = dir.path().join("data");
    let truth = synth(
        "cliff",
        &["--shift", "0.08,0,0", "--turn", "0,0,0.1"],
        &data,
    );
    // The plateau (y 5000003..5000008) and the beach (y 4999982..4999992) along the face.
    let rect = |y0: f64, y1: f64| {
        serde_json::json!({"type": "Feature", "properties": {}, "geometry": {"type": "Polygon",
            "coordinates": [[[500005.0, y0], [500055.0, y0], [500055.0, y1], [500005.0, y1], [500005.0, y0]]]}})
    };
    let areas = serde_json::json!({"type": "FeatureCollection",
        "features": [rect(4999982.0, 4999992.0), rect(5000003.0, 5000008.0)]});
    let stable = dir.path().join("stable.geojson");
    std::fs::write(&stable, areas.to_string()).unwrap();
    let res = dir.path().join("res");
    let found = compare_with(
        &data.join("before.laz"),
        &data.join("after.laz"),
        &res,
        &["--stable", stable.to_str().unwrap()],
    );
    judge("cliff turned, flat stable areas", &planted(&truth), &found);
    let summary: Value =
        serde_json::from_slice(&std::fs::read(res.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["stable"]["source"], "user", "{}", summary["stable"]);
}

/// Issue 43, item 4: a survey off by 2.6 m (another datum, a georeferencing error) is no
/// misregistration to align quietly and no change: the run stops (exit 2) naming the survey and
/// what to do; with `--align on` it is aligned and every planted event is within 2 %.
#[test]
fn a_survey_off_by_metres_is_refused_by_default_and_aligned_when_asked() {
    let dir = common::tempdir();
    let data = dir.path().join("data");
    let truth = synth("cliff", &["--shift", "1.5,-2.0,0.8"], &data);
    let (b, a) = (data.join("before.laz"), data.join("after.laz"));
    let o = common::run_compare(&b, &a, &dir.path().join("auto"), &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("after.laz") && err.contains("--align on"),
        "{err}"
    );
    assert!(!dir.path().join("auto").join("events.geojson").exists());
    let res = dir.path().join("on");
    let found = compare_with(&b, &a, &res, &["--align", "on"]);
    judge("cliff off by 2.6 m, --align on", &planted(&truth), &found);
}

/// Issue "Stable ground the user knows", item 3: a beach where most of the sand moved (60 cos²
/// bumps and dents of 0.1 to 1 m over 6 m cells: 73 % of the beach) below a sea wall and a road
/// that did not, with a pothole (−0.32 m³, 8 cm deep) and a heap (+0.21 m³, 10 cm) on the road
/// that only the surveys' true level of detection finds. With the automatic stable ground and
/// with `--stable` over the wall's top and the road: every planted change within 2 %, inside its
/// interval, no stray event; τ within 10 % between the two (the sand does not inflate the
/// automatic stable ground on this scene), and below the road changes' depths by far (≤ 1 cm).
#[test]
fn a_moving_beach_below_a_sea_wall_with_and_without_stable_areas() {
    let dir = common::tempdir();
    let data = dir.path().join("data");
    let truth = synth("beach", &[], &data);
    // The wall's top (its seaward face at local y = 40 left out) and the road, in the survey's
    // frame: the scene's local origin is its bounds' minimum.
    let (x0, y0) = (
        truth.events[0].centre[0] - 3.0,
        truth.events[0].centre[1] - 5.0,
    );
    let rect = |a: f64, b: f64, c: f64, d: f64| {
        serde_json::json!([[
            [x0 + a, y0 + b],
            [x0 + c, y0 + b],
            [x0 + c, y0 + d],
            [x0 + a, y0 + d],
            [x0 + a, y0 + b]
        ]])
    };
    let areas = serde_json::json!({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": rect(0.0, 40.3, 60.0, 41.5)}},
        {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": rect(0.0, 41.5, 60.0, 46.0)}}]});
    let file = dir.path().join("stable.geojson");
    std::fs::write(&file, areas.to_string()).unwrap();
    let (b, a) = (data.join("before.laz"), data.join("after.laz"));
    let mut tau = Vec::new();
    for (label, extra) in [
        ("beach", vec![]),
        ("beach --stable", vec!["--stable", file.to_str().unwrap()]),
    ] {
        let res = dir.path().join(label.replace(' ', "_"));
        let found = compare_with(&b, &a, &res, &extra);
        judge(label, &planted(&truth), &found);
        let s: Value =
            serde_json::from_str(&std::fs::read_to_string(res.join("summary.json")).unwrap())
                .unwrap();
        let source = if extra.is_empty() {
            "automatic"
        } else {
            "user"
        };
        assert_eq!(s["stable"]["source"], source);
        tau.push(s["parameters"]["threshold"]["value"].as_f64().unwrap());
    }
    eprintln!(
        "τ automatic {:.4} m, with the areas {:.4} m",
        tau[0], tau[1]
    );
    assert!((tau[0] / tau[1] - 1.0).abs() < 0.1, "{tau:?}");
    assert!(tau.iter().all(|&t| t <= 0.01), "{tau:?}");
}
