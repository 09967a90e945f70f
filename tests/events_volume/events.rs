//! The events' algorithms against brute force: the significance filter, smoothing, the PCA
//! box, DBSCAN, and the same results by blocks as for the whole cloud.

use super::*;

#[test]
fn filter_keeps_significant_points_only() {
    let d = [0.10, -0.10, 0.04, 0.10, f64::NAN, 0.05, 0.2];
    let lod = [0.05, 0.05, 0.01, 0.10, 0.01, 0.01, f64::NAN];
    assert_eq!(
        filter::kept(&d, &lod, 0.05),
        vec![true, true, false, false, false, true, false]
    );
    assert_eq!(filter::kept_indices(&d, &lod, 0.05), vec![0, 1, 5]);
}

fn random_cloud(n: usize, rng: &mut Rng) -> Vec<[f64; 3]> {
    (0..n)
        .map(|_| {
            [
                rng.range(0.0, 10.0),
                rng.range(0.0, 10.0),
                rng.range(0.0, 1.0),
            ]
        })
        .collect()
}

#[test]
fn smoothing_keeps_a_constant_field_constant() {
    let mut rng = Rng::new(10);
    let pts = random_cloud(2000, &mut rng);
    let d = vec![0.37; pts.len()];
    for s in smooth(&pts, &d, 30, 1.0).unwrap() {
        assert!((s - 0.37).abs() < 1e-12, "{s}");
    }
}

/// k nearest by (squared distance, index), brute force.
fn brute_smooth(pts: &[[f64; 3]], d: &[f64], k: usize, sigma: f64) -> Vec<f64> {
    pts.iter()
        .map(|p| {
            let mut nb: Vec<(f64, usize)> = pts
                .iter()
                .enumerate()
                .map(|(j, q)| ((0..3).map(|c| (p[c] - q[c]).powi(2)).sum(), j))
                .collect();
            nb.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let (mut num, mut den) = (0.0, 0.0);
            for &(r2, j) in nb.iter().take(k) {
                let w = (-r2 / (2.0 * sigma * sigma)).exp();
                num += w * d[j];
                den += w;
            }
            num / den
        })
        .collect()
}

#[test]
fn smoothing_matches_brute_force_including_ties() {
    let mut rng = Rng::new(11);
    // A regular grid: many equal distances, so the k-th neighbour is often a tie.
    let mut pts = Vec::new();
    for i in 0..15 {
        for j in 0..15 {
            pts.push([i as f64 * 0.5, j as f64 * 0.5, 0.0]);
        }
    }
    pts.extend(random_cloud(300, &mut rng));
    let d: Vec<f64> = (0..pts.len()).map(|_| rng.gauss()).collect();
    let fast = smooth(&pts, &d, 12, 0.7).unwrap();
    let slow = brute_smooth(&pts, &d, 12, 0.7);
    for (a, b) in fast.iter().zip(&slow) {
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
    }
}

#[test]
fn describe_gives_the_pca_box_of_a_tilted_rectangle() {
    let place = tilted(1.1, 0.4, [1000.0, 2000.0, 50.0]);
    let mut rng = Rng::new(12);
    let (mut pts, mut d, mut lod, mut nrm) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    // A 4 × 2 rectangle centred at local (1, −0.5), grid step 0.1 (41 × 21 points).
    for i in 0..=40 {
        for j in 0..=20 {
            pts.push(place.apply([1.0 - 2.0 + 0.1 * i as f64, -0.5 - 1.0 + 0.1 * j as f64, 0.0]));
            d.push(-0.2 - 0.1 * rng.uniform());
            lod.push(0.05);
            nrm.push(place.normal());
        }
    }
    let ev = describe(7, Kind::Loss, &pts, &d, &lod, &nrm, 0.1).unwrap();
    assert_eq!(ev.n_points, 41 * 21);
    assert!((ev.area_m2 - 861.0 * 0.01).abs() < 1e-9);
    assert!(ev.max_abs_distance <= 0.3 && ev.max_abs_distance > 0.29);
    assert!((ev.mean_lod95 - 0.05).abs() < 1e-12);
    let c = place.apply([1.0, -0.5, 0.0]);
    for (k, ck) in c.iter().enumerate() {
        assert!((ev.centroid[k] - ck).abs() < 1e-6);
        assert!((ev.obb.center[k] - ck).abs() < 1e-6);
    }
    let he = ev.obb.half_extents;
    assert!(
        (he[0] - 2.0).abs() < 1e-9 && (he[1] - 1.0).abs() < 1e-9 && he[2] < 1e-9,
        "{he:?}"
    );
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let [e1, e2, e3] = ev.obb.axes;
    assert!(
        dot(e1, place.e[0]).abs() > 1.0 - 1e-9,
        "first axis = long side"
    );
    assert!(
        dot(e3, place.normal()) > 1.0 - 1e-9,
        "third axis = outward normal"
    );
    // Right-handed: e1 × e2 = e3.
    let cr = [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ];
    for (a, b) in cr.iter().zip(&e3) {
        assert!((a - b).abs() < 1e-9);
    }
    // The box frame maps the corners to ±half extents.
    let corner = place.apply([3.0, 0.5, 0.0]);
    let l = ev.obb.to_local(&corner);
    assert!((l[0].abs() - 2.0).abs() < 1e-9 && (l[1].abs() - 1.0).abs() < 1e-9);
}

// ---------------------------------------------------------------- DBSCAN

/// DBSCAN straight from the definitions, O(n²): core = |N_eps| ≥ min_pts (itself
/// included); clusters = connected components of cores under the eps relation; a border
/// point joins the cluster of its core neighbour with the smallest index; clusters numbered
/// by their smallest member.
fn brute_dbscan(pts: &[[f64; 3]], eps: f64, min_pts: usize) -> Vec<u32> {
    let n = pts.len();
    let near = |i: usize, j: usize| {
        (0..3).map(|c| (pts[i][c] - pts[j][c]).powi(2)).sum::<f64>() <= eps * eps
    };
    let nb: Vec<Vec<usize>> = (0..n)
        .map(|i| (0..n).filter(|&j| near(i, j)).collect())
        .collect();
    let core: Vec<bool> = nb.iter().map(|v| v.len() >= min_pts).collect();
    let mut comp = vec![usize::MAX; n];
    let mut ncomp = 0;
    for s in 0..n {
        if !core[s] || comp[s] != usize::MAX {
            continue;
        }
        let mut stack = vec![s];
        comp[s] = ncomp;
        while let Some(p) = stack.pop() {
            for &q in &nb[p] {
                if core[q] && comp[q] == usize::MAX {
                    comp[q] = ncomp;
                    stack.push(q);
                }
            }
        }
        ncomp += 1;
    }
    for i in 0..n {
        if !core[i] {
            if let Some(&c) = nb[i].iter().filter(|&&j| core[j]).min() {
                comp[i] = comp[c];
            }
        }
    }
    let mut first = vec![usize::MAX; ncomp];
    for i in 0..n {
        if comp[i] != usize::MAX {
            first[comp[i]] = first[comp[i]].min(i);
        }
    }
    let mut order: Vec<usize> = (0..ncomp).collect();
    order.sort_by_key(|&c| first[c]);
    let mut label = vec![0u32; ncomp];
    for (k, &c) in order.iter().enumerate() {
        label[c] = k as u32 + 1;
    }
    (0..n)
        .map(|i| {
            if comp[i] == usize::MAX {
                0
            } else {
                label[comp[i]]
            }
        })
        .collect()
}

/// Blobs (some centred on tile corners of 2×2 and 3×3 splits of [0, 30]²), a diagonal chain
/// crossing several tiles, and uniform noise.
fn clustered(rng: &mut Rng) -> Vec<[f64; 3]> {
    let mut pts = Vec::new();
    let centres = [
        [15.0, 15.0, 1.0], // 2×2 corner
        [10.0, 10.0, 0.5], // 3×3 corners
        [20.0, 20.0, 1.5],
        [10.0, 20.0, 1.0],
        [5.0, 25.0, 0.0],
        [26.0, 4.0, 2.0],
    ];
    for c in centres {
        for _ in 0..150 {
            pts.push([
                c[0] + 0.9 * rng.gauss(),
                c[1] + 0.9 * rng.gauss(),
                c[2] + 0.3 * rng.gauss(),
            ]);
        }
    }
    // A chain along y = 5 crossing the tile borders x = 10, 15, 20, away from the blobs.
    for k in 0..100 {
        let t = k as f64 * 0.2;
        pts.push([2.0 + t + 0.05 * rng.gauss(), 5.0 + 0.05 * rng.gauss(), 1.0]);
    }
    for _ in 0..500 {
        pts.push([
            rng.range(0.0, 30.0),
            rng.range(0.0, 30.0),
            rng.range(0.0, 3.0),
        ]);
    }
    pts
}

/// `events::blocks::cluster` over blocks reaching `reach`, every point a member.
fn blocks_dbscan(pts: &[[f64; 3]], reach: f64, eps: f64, min_pts: usize) -> Vec<u32> {
    let blocks = talus::events::blocks::Blocks::new(pts, reach);
    talus::events::blocks::cluster(pts, &|_| true, eps, min_pts, &blocks).unwrap()
}

#[test]
fn dbscan_matches_brute_force() {
    let mut rng = Rng::new(13);
    let pts = clustered(&mut rng);
    let (eps, min_pts) = (1.0, 8);
    let whole = dbscan(&pts, eps, min_pts).unwrap();
    let brute = brute_dbscan(&pts, eps, min_pts);
    assert_eq!(whole, brute);
    let n_clusters = *whole.iter().max().unwrap();
    let n_noise = whole.iter().filter(|&&l| l == 0).count();
    assert!(n_clusters >= 7, "{n_clusters} clusters");
    assert!(n_noise > 100, "{n_noise} noise points");
}

#[test]
fn dbscan_by_blocks_equals_whole_cloud() {
    let mut rng = Rng::new(14);
    let pts = clustered(&mut rng);
    let (eps, min_pts) = (1.0, 8);
    let whole = dbscan(&pts, eps, min_pts).unwrap();
    for reach in [1.0, 1.7, 4.0, 40.0] {
        let by_blocks = blocks_dbscan(&pts, reach, eps, min_pts);
        assert_eq!(by_blocks, whole, "blocks reaching {reach}");
    }
    // The clusters really straddle blocks: points of one cluster in several blocks of 4.0 (the
    // side of those reaching 1.0), counted from the first point.
    let label = whole[150]; // first point of the blob at (10, 10)
    let mut cells = std::collections::HashSet::new();
    for (i, p) in pts.iter().enumerate() {
        if whole[i] == label {
            cells.insert([0, 1, 2].map(|k| ((p[k] - pts[0][k]) / 4.0).floor() as i64));
        }
    }
    assert!(cells.len() >= 3, "cluster spans {} blocks", cells.len());
    // Members only: the labels of a whole-cloud run over the members, the others noise.
    let member = |i: usize| i % 3 != 1;
    let sub: Vec<[f64; 3]> = (0..pts.len())
        .filter(|&i| member(i))
        .map(|i| pts[i])
        .collect();
    let mut expected = vec![0u32; pts.len()];
    let sub_labels = dbscan(&sub, eps, min_pts).unwrap();
    for (&l, i) in sub_labels.iter().zip((0..pts.len()).filter(|&i| member(i))) {
        expected[i] = l;
    }
    assert!(*expected.iter().max().unwrap() >= 5);
    let blocks = talus::events::blocks::Blocks::new(&pts, 1.3);
    let got = talus::events::blocks::cluster(&pts, &member, eps, min_pts, &blocks).unwrap();
    assert_eq!(got, expected);
}

/// Smoothing by blocks has the bits of the whole-cloud smoothing wherever a point's k nearest
/// lie within the reach; where they do not (isolated points), it takes those within the reach,
/// and the value moves by less than the weights beyond it (e^(−reach²/2σ²) each).
#[test]
fn smoothing_by_blocks_equals_whole_cloud_within_its_reach() {
    use talus::events::blocks::{smooth, Blocks};
    let mut rng = Rng::new(15);
    let mut pts = clustered(&mut rng);
    // A few isolated points, far from the others.
    for k in 0..6 {
        pts.push([50.0 + 7.0 * k as f64, 60.0, 1.0]);
    }
    let d: Vec<f64> = pts
        .iter()
        .map(|p| 0.1 * p[0].sin() + 0.05 * p[1] + rng.gauss() * 0.01)
        .collect();
    let (k, sigma) = (30, 0.5);
    let reach = 5.0 * sigma;
    let whole = talus::events::smooth::smooth(&pts, &d, k, sigma).unwrap();
    let mut far = 0;
    for blocks_reach in [reach, 4.0, 9.0] {
        let by_blocks =
            smooth(&pts, &d, k, sigma, reach, &Blocks::new(&pts, blocks_reach)).unwrap();
        far = 0;
        for i in 0..pts.len() {
            // The k-th nearest distance, by brute force.
            let mut r2: Vec<f64> = pts
                .iter()
                .map(|q| (0..3).map(|c| (pts[i][c] - q[c]).powi(2)).sum())
                .collect();
            r2.sort_by(|a, b| a.total_cmp(b));
            if r2[k - 1] <= reach * reach * (1.0 - 1e-9) {
                assert_eq!(by_blocks[i].to_bits(), whole[i].to_bits(), "point {i}");
            } else {
                far += 1;
                let bound = k as f64 * (-reach * reach / (2.0 * sigma * sigma)).exp();
                let spread = d.iter().fold(0.0f64, |m, x| m.max(x.abs())) * 2.0;
                assert!(
                    (by_blocks[i] - whole[i]).abs() <= bound * spread,
                    "point {i}"
                );
            }
        }
    }
    assert!(
        far >= 6,
        "{far} points with their k nearest beyond the reach"
    );
}

#[test]
fn signed_dbscan_separates_gain_and_loss() {
    // Two touching squares of points, one gaining, one losing: one cluster each.
    let mut pts = Vec::new();
    let mut s = Vec::new();
    for i in 0..40 {
        for j in 0..20 {
            pts.push([i as f64 * 0.25, j as f64 * 0.25, 0.0]);
            s.push(if i < 20 { 0.3 } else { -0.3 });
        }
    }
    let l = talus::events::dbscan::signed_dbscan(&pts, &s, 0.3, 4).unwrap();
    for (i, x) in l.iter().enumerate() {
        let want = if s[i] > 0.0 { Kind::Gain } else { Kind::Loss };
        assert_eq!(*x, Some((want, 1)), "point {i}");
    }
}
