//! Rock faces scanned alone from far away (SPEC.md §1 "Orientation on real surveys"), the way
//! terrestrial deliveries of a face come: no beach in front, no plateau behind, overhangs,
//! ledges and bays. Every event's sign and volume against the truth and against a DEM of
//! difference along the face's normal written here (both epochs gridded on the face's plane):
//! - `synth face`: a 70° face from a scanner 300 m away — decided by the face's lean;
//! - `synth face-vertical`: the same face upright — the data cannot tell which side is out:
//!   every event says so and stays out of the totals, and the scanner's position decides it;
//! - the Trier rock face (tests/data/trier: the real site's face as a mesh, the real scanner's
//!   position, a 14.9 m³ block planted and removed), scanned here from that position.

mod common;

use std::path::Path;

use serde_json::Value;
use talus::io::mesh_ply::read_ply_mesh;

type V3 = [f64; 3];

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The points of a LAS/LAZ file (global coordinates).
fn points(path: &Path) -> Vec<V3> {
    talus::io::read_all(path).unwrap().1
}

/// A frame on the plane fitted to `pts` (least squares: the covariance's smallest
/// eigenvector), its normal turned toward `viewer`: (origin, strike u, dip v, normal n).
fn face_frame(pts: &[V3], viewer: V3) -> (V3, V3, V3, V3) {
    let n = pts.len() as f64;
    let c: V3 = std::array::from_fn(|k| pts.iter().map(|p| p[k]).sum::<f64>() / n);
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    for p in pts {
        let d = nalgebra::Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
        m += d * d.transpose();
    }
    let e = nalgebra::SymmetricEigen::new(m);
    let k = e.eigenvalues.imin();
    let mut nn: V3 = std::array::from_fn(|i| e.eigenvectors[(i, k)]);
    if dot(nn, [viewer[0] - c[0], viewer[1] - c[1], viewer[2] - c[2]]) < 0.0 {
        nn = nn.map(|x| -x);
    }
    // Strike: horizontal, across the normal; dip: across both.
    let h = (nn[0] * nn[0] + nn[1] * nn[1]).sqrt();
    let u = [-nn[1] / h, nn[0] / h, 0.0];
    let v = [
        nn[1] * u[2] - nn[2] * u[1],
        nn[2] * u[0] - nn[0] * u[2],
        nn[0] * u[1] - nn[1] * u[0],
    ];
    (c, u, v, nn)
}

/// The DEM of difference along the face's normal over the disc of radius `r` about `centre`:
/// each epoch gridded on the face's plane in cells of `cell`, a cell's offset along the normal
/// interpolated from the points within `reach` of its centre (inverse squared distance, as DEMs
/// are gridded: a scan's shadows narrower than `reach` are bridged); cells either epoch leaves
/// empty are left out. Positive: material gained.
fn face_dod(
    before: &[V3],
    after: &[V3],
    frame: (V3, V3, V3, V3),
    centre: V3,
    r: f64,
    (cell, reach): (f64, f64),
) -> f64 {
    let (o, u, v, n) = frame;
    let at = |p: &V3| {
        let d = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        [dot(d, u), dot(d, v), dot(d, n)]
    };
    let c = at(&centre);
    let k = (2.0 * r / cell).ceil() as usize;
    // Each epoch's points near the disc, bucketed by cells of `reach`.
    let buckets = |pts: &[V3]| {
        let mut b: std::collections::HashMap<(i64, i64), Vec<V3>> = Default::default();
        for p in pts {
            let q = at(p);
            let (x, y) = (q[0] - c[0], q[1] - c[1]);
            if x.abs() <= r + reach && y.abs() <= r + reach {
                let key = ((x / reach).floor() as i64, (y / reach).floor() as i64);
                b.entry(key).or_default().push([x, y, q[2]]);
            }
        }
        b
    };
    let offset = |b: &std::collections::HashMap<(i64, i64), Vec<V3>>, x: f64, y: f64| {
        let (i, j) = ((x / reach).floor() as i64, (y / reach).floor() as i64);
        let (mut sw, mut swz) = (0.0, 0.0);
        for di in -1..=1 {
            for dj in -1..=1 {
                for q in b.get(&(i + di, j + dj)).into_iter().flatten() {
                    let d2 = (q[0] - x).powi(2) + (q[1] - y).powi(2);
                    if d2 <= reach * reach {
                        let w = 1.0 / d2.max(1e-6);
                        sw += w;
                        swz += w * q[2];
                    }
                }
            }
        }
        (sw > 0.0).then(|| swz / sw)
    };
    let (b0, b1) = (buckets(before), buckets(after));
    let mut vol = 0.0;
    for j in 0..k {
        for i in 0..k {
            let (x, y) = ((i as f64 + 0.5) * cell - r, (j as f64 + 0.5) * cell - r);
            if x.hypot(y) > r {
                continue;
            }
            if let (Some(a), Some(b)) = (offset(&b0, x, y), offset(&b1, x, y)) {
                vol += (b - a) * cell * cell;
            }
        }
    }
    vol
}

/// The events of a result (events.geojson's features' properties and centroids).
fn events(res: &Path) -> Vec<(V3, Value)> {
    let fc: Value =
        serde_json::from_str(&std::fs::read_to_string(res.join("events.geojson")).unwrap())
            .unwrap();
    fc["features"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let c = &f["geometry"]["coordinates"];
            (
                std::array::from_fn(|k| c[k].as_f64().unwrap()),
                f["properties"].clone(),
            )
        })
        .collect()
}

/// talus's events within `r` of `centre`: their summed volume and properties.
fn near(events: &[(V3, Value)], centre: V3, r: f64) -> (f64, Vec<Value>) {
    let mine: Vec<Value> = events
        .iter()
        .filter(|(c, _)| {
            let d = [c[0] - centre[0], c[1] - centre[1], c[2] - centre[2]];
            dot(d, d).sqrt() <= r
        })
        .map(|(_, p)| p.clone())
        .collect();
    let v = mine
        .iter()
        .map(|p| p["volume_m3"].as_f64().unwrap_or(0.0))
        .sum();
    (v, mine)
}

fn summary(res: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(res.join("summary.json")).unwrap()).unwrap()
}

/// `talus synth SCENE` and `talus compare` of it with `extra`: the truth, the result folder and
/// the two epochs' points.
fn face_run(
    dir: &Path,
    scene: &str,
    extra: &[&str],
) -> (Value, std::path::PathBuf, Vec<V3>, Vec<V3>) {
    let s = dir.join(scene);
    common::run_ok(&["synth", scene, "--out", s.to_str().unwrap()]);
    let truth: Value =
        serde_json::from_str(&std::fs::read_to_string(s.join("truth.json")).unwrap()).unwrap();
    let res = dir.join(format!("res-{scene}"));
    let mut args: Vec<String> = vec![
        "compare".into(),
        s.join("before.laz").to_str().unwrap().to_string(),
        s.join("after.laz").to_str().unwrap().to_string(),
        "--out".into(),
        res.to_str().unwrap().to_string(),
    ];
    args.extend(extra.iter().map(|a| a.to_string()));
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    common::run_ok(&refs);
    (
        truth,
        res,
        points(&s.join("before.laz")),
        points(&s.join("after.laz")),
    )
}

/// Every planted event of a face scene found with the right sign, its volume within `tol` of
/// the truth and within 5 % of the DEM of difference along the face's normal; a table on stderr.
fn judge(truth: &Value, res: &Path, before: &[V3], after: &[V3], tol: f64) -> Vec<Vec<Value>> {
    let scanner: V3 = std::array::from_fn(|k| truth["scanner"][k].as_f64().unwrap());
    let frame = face_frame(before, scanner);
    let found = events(res);
    let mut out = Vec::new();
    eprintln!(
        "{:>3} {:>9} {:>9} {:>9} {:>7}",
        "id", "truth", "DoD", "talus", "err %"
    );
    for e in truth["events"].as_array().unwrap() {
        let c: V3 = std::array::from_fn(|k| e["centre"][k].as_f64().unwrap());
        let r = e["radius_m"].as_f64().unwrap();
        let want = e["volume_m3"].as_f64().unwrap();
        let dod = face_dod(before, after, frame, c, r + 1.0, (0.15, 0.3));
        let (got, mine) = near(&found, c, r + 1.0);
        eprintln!(
            "{:>3} {want:>9.3} {dod:>9.3} {got:>9.3} {:>7.2}",
            e["id"],
            100.0 * (got - want) / want.abs()
        );
        assert!(!mine.is_empty(), "event {} not found", e["id"]);
        assert!(
            got.signum() == want.signum(),
            "event {}: {got} for {want}",
            e["id"]
        );
        assert!(
            (got - want).abs() <= tol * want.abs(),
            "event {}: {got} for {want}",
            e["id"]
        );
        assert!(
            (got - dod).abs() <= 0.05 * dod.abs(),
            "event {}: {got}, the DoD {dod}",
            e["id"]
        );
        out.push(mine);
    }
    out
}

#[test]
fn a_face_scanned_alone_has_every_event_signed_and_measured() {
    let dir = common::tempdir();
    let (truth, res, before, after) = face_run(dir.path(), "face", &[]);
    for mine in judge(&truth, &res, &before, &after, 0.03) {
        for p in mine {
            assert_eq!(p["sign_known"], true, "{p}");
            assert_eq!(p["complete"], true, "{p}");
        }
    }
    // The totals are the planted ones.
    let s = summary(&res);
    let (g, l) = (
        s["total_gain_m3"].as_f64().unwrap(),
        s["total_loss_m3"].as_f64().unwrap(),
    );
    let (tg, tl) = (
        truth["total_gain_m3"].as_f64().unwrap(),
        truth["total_loss_m3"].as_f64().unwrap(),
    );
    assert!(
        (g - tg).abs() <= 0.03 * tg && (l - tl).abs() <= 0.03 * tl.abs(),
        "{g} {l}"
    );
}

#[test]
fn a_vertical_face_alone_says_its_signs_are_unknown_until_the_scanner_is_given() {
    let dir = common::tempdir();
    let (truth, res, _, _) = face_run(dir.path(), "face-vertical", &[]);
    let found = events(&res);
    assert!(!found.is_empty());
    for (_, p) in &found {
        assert_eq!(p["sign_known"], false, "{p}");
        assert_eq!(p["complete"], false, "{p}");
        let note = p["volume_note"].as_str().unwrap();
        assert!(note.contains("--orientation toward"), "{note}");
    }
    // Nothing of unknown sign is summed as a gain or a loss.
    let s = summary(&res);
    assert_eq!(s["total_gain_m3"].as_f64().unwrap(), 0.0);
    assert_eq!(s["total_loss_m3"].as_f64().unwrap(), 0.0);
    // The scanner's position decides every sign.
    let sc: Vec<String> = (0..3)
        .map(|k| truth["scanner"][k].as_f64().unwrap().to_string())
        .collect();
    let toward = format!("toward:{}", sc.join(","));
    let dir2 = common::tempdir();
    let (truth, res, before, after) =
        face_run(dir2.path(), "face-vertical", &["--orientation", &toward]);
    for mine in judge(&truth, &res, &before, &after, 0.03) {
        for p in mine {
            assert_eq!(p["sign_known"], true, "{p}");
        }
    }
}

/// The Trier scene's meshes (tests/data/trier) and its scanner.
struct Trier {
    terrain: talus::volume::Mesh,
    rock: talus::volume::Mesh,
    release: talus::volume::Mesh,
    deposits: talus::volume::Mesh,
}

/// The real scanner's position in the mesh frame (the project's survey template).
const TRIER_SCANNER: V3 = [26.5, -240.015, 135.411];
/// The meshes' frame moved to where the site is (UTM 32N), so that the files carry real
/// coordinates.
const TRIER_OFFSET: V3 = [330_573.107, 5_516_025.929, 0.0];

fn trier() -> Trier {
    let d = common::data("trier");
    let m = |f: &str| read_ply_mesh(&d.join(f)).unwrap();
    Trier {
        terrain: m("terrain.ply"),
        rock: m("rock.ply"),
        release: m("release.ply"),
        deposits: m("deposits.ply"),
    }
}

#[test]
fn the_trier_face_scanned_alone_loses_its_block() {
    let t = trier();
    // The face only: what lies above the slope the debris falls onto (z ≥ 163).
    let keep = |p: &V3| p[2] >= 163.0;
    let step = 0.1 / 340.0;
    let before = common::scan::scan(
        &[&t.terrain, &t.rock],
        TRIER_SCANNER,
        step,
        [0.25, 0.5],
        0.005,
        1,
        keep,
    );
    let after = common::scan::scan(
        &[&t.terrain, &t.release, &t.deposits],
        TRIER_SCANNER,
        step,
        [0.7, 0.1],
        0.005,
        2,
        keep,
    );
    let shift = |v: Vec<V3>| -> Vec<V3> {
        v.into_iter()
            .map(|p| std::array::from_fn(|k| p[k] + TRIER_OFFSET[k]))
            .collect()
    };
    let dir = common::tempdir();
    let (b, a) = (dir.path().join("before.laz"), dir.path().join("after.laz"));
    common::write_cloud(&b, &shift(before));
    common::write_cloud(&a, &shift(after));
    // The truth: the volume between the two meshes' surfaces seen from the scanner.
    let rock_centre = [56.45, 100.3, 169.6];
    let view = std::array::from_fn(|k| TRIER_SCANNER[k] - rock_centre[k]);
    let (want, area) = common::scan::volume_between(
        &[&t.terrain, &t.rock],
        &[&t.terrain, &t.release, &t.deposits],
        view,
        rock_centre,
        6.0,
        0.02,
    );
    eprintln!("trier: the block's volume between the meshes {want:.3} m³ over {area:.1} m²");
    // The closed block holds 14.9 m³; what lies between the surfaces the scanner can see of it
    // is most of that (its far side, against the scar, is a graph along the view but for a
    // rim).
    assert!((want + 14.9).abs() < 0.1 * 14.9, "{want}");
    let res = dir.path().join("res");
    let o = common::run_compare(&b, &a, &res, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));
    let centre = std::array::from_fn(|k| rock_centre[k] + TRIER_OFFSET[k]);
    let (got, mine) = near(&events(&res), centre, 6.0);
    eprintln!(
        "trier: talus {got:.3} m³ in {} event(s): {mine:?}",
        mine.len()
    );
    assert!(got < 0.0, "the block's loss came out {got}");
    assert!(
        (got - want).abs() <= 0.05 * want.abs(),
        "{got} against {want}"
    );
    for p in &mine {
        assert_eq!(p["sign_known"], true, "{p}");
    }
}
