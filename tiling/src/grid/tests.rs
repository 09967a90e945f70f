use super::*;

/// The crate's seeded generator, as the tests draw from it.
struct Rng(talus_base::rng::SplitMix64);
impl Rng {
    fn unit(&mut self) -> f64 {
        self.0.uniform()
    }
}

/// Test points: uniform ones, plus points exactly on every tile edge and one ulp either side,
/// plus points exactly `halo` away from edges (the closed halo boundary).
fn probe_points(grid: &TileGrid, halo: f64, rng: &mut Rng) -> Vec<[f64; 2]> {
    let o = grid.origin();
    let s = grid.tile_size();
    let w = s * f64::from(grid.cols());
    let h = s * f64::from(grid.rows());
    let mut pts: Vec<[f64; 2]> = (0..3000)
        .map(|_| [o[0] + rng.unit() * w, o[1] + rng.unit() * h])
        .collect();
    let mut xs = vec![];
    for k in 0..=grid.cols() {
        let e = o[0] + f64::from(k) * s;
        for v in [e, e - halo, e + halo] {
            xs.extend([v, next_down(v), next_up(v)]);
        }
    }
    let mut ys = vec![];
    for k in 0..=grid.rows() {
        let e = o[1] + f64::from(k) * s;
        for v in [e, e - halo, e + halo] {
            ys.extend([v, next_down(v), next_up(v)]);
        }
    }
    for &x in &xs {
        pts.push([x, o[1] + rng.unit() * h]);
        for &y in ys.iter().step_by(7) {
            pts.push([x, y]);
        }
    }
    for &y in &ys {
        pts.push([o[0] + rng.unit() * w, y]);
    }
    pts
}

fn next_up(v: f64) -> f64 {
    if v == 0.0 {
        return f64::from_bits(1);
    }
    if v > 0.0 {
        f64::from_bits(v.to_bits() + 1)
    } else {
        f64::from_bits(v.to_bits() - 1)
    }
}
fn next_down(v: f64) -> f64 {
    -next_up(-v)
}

/// Independent statement of ownership: half-open squares, the last column/row closed at the top,
/// nothing outside the grid's closed extent.
fn brute_owns(grid: &TileGrid, id: TileId, x: f64, y: f64) -> bool {
    let sq = grid.square(id);
    let in_x = x >= sq.min[0] && (x < sq.max[0] || (id.col + 1 == grid.cols() && x == sq.max[0]));
    let in_y = y >= sq.min[1] && (y < sq.max[1] || (id.row + 1 == grid.rows() && y == sq.max[1]));
    in_x && in_y
}

fn grids() -> Vec<TileGrid> {
    vec![
        TileGrid::new([0.0, 0.0], 10.0, 5, 3).unwrap(),
        // Awkward origin and size: edges are not exactly representable sums.
        TileGrid::new([512_345.67, 5_123_456.1], 33.3, 7, 4).unwrap(),
        TileGrid::new([-1.0, -2.5], 0.1, 9, 11).unwrap(),
        TileGrid::new([3.0, 4.0], 7.0, 1, 1).unwrap(),
    ]
}

#[test]
fn ownership_partitions_points_exactly() {
    let mut rng = Rng(talus_base::rng::SplitMix64::new(7));
    for grid in grids() {
        for [x, y] in probe_points(&grid, 0.0, &mut rng) {
            let owners: Vec<TileId> = grid
                .tiles()
                .filter(|&id| brute_owns(&grid, id, x, y))
                .collect();
            let inside_extent = x >= grid.origin()[0]
                && y >= grid.origin()[1]
                && x <= grid
                    .square(TileId {
                        col: grid.cols() - 1,
                        row: 0,
                    })
                    .max[0]
                && y <= grid
                    .square(TileId {
                        col: 0,
                        row: grid.rows() - 1,
                    })
                    .max[1];
            if inside_extent {
                assert_eq!(owners.len(), 1, "{x},{y} owned by {owners:?}");
                assert_eq!(grid.owner(x, y), owners[0], "{x},{y}");
            } else {
                // Outside the grid: the owner of the point clamped onto the grid's edge.
                let [cx, cy] = grid.clamp_point(x, y);
                assert!(brute_owns(&grid, grid.owner(x, y), cx, cy), "{x},{y}");
            }
        }
    }
}

#[test]
fn halo_membership_is_exactly_the_halo_box_set() {
    let mut rng = Rng(talus_base::rng::SplitMix64::new(11));
    for grid in grids() {
        for halo in [0.0, grid.tile_size() * 0.3, grid.tile_size() * 1.7] {
            for [x, y] in probe_points(&grid, halo, &mut rng) {
                let got: Vec<TileId> = grid.tiles_touching(x, y, halo).collect();
                // Outside the grid the contract is "as if clamped onto its edge".
                let [cx, cy] = grid.clamp_point(x, y);
                let want: Vec<TileId> = grid
                    .tiles()
                    .filter(|&id| grid.halo_box(id, halo).contains(cx, cy))
                    .collect();
                assert_eq!(got, want, "point {x},{y} halo {halo}");
                assert!(got.contains(&grid.owner(x, y)), "point {x},{y}");
            }
        }
    }
}

#[test]
fn names_and_order_are_stable() {
    let a = TileId { col: 3, row: 12 };
    assert_eq!(a.name(), "t_0003_0012");
    assert_eq!(a.to_string(), "t_0003_0012");
    let grid = TileGrid::new([0.0, 0.0], 1.0, 3, 2).unwrap();
    let ids: Vec<TileId> = grid.tiles().collect();
    let mut sorted = ids.clone();
    sorted.sort();
    assert_eq!(ids, sorted);
    let mut names: Vec<String> = ids.iter().map(|i| i.name()).collect();
    let before = names.clone();
    names.sort();
    assert_eq!(names, before);
}

#[test]
fn plan_small_cloud_is_one_tile_covering_bounds() {
    let b = BoundsXY::new([100.0, 200.0], [150.0, 230.0]);
    // 1500 m² × 10 pts/m² × 200 B = 3 MB, far below a quarter of 2 GiB.
    let g = TileGrid::plan(b, 10.0, 5.0, 2 << 30, 200).unwrap();
    assert_eq!((g.cols(), g.rows()), (1, 1));
    let sq = g.square(TileId { col: 0, row: 0 });
    assert!(sq.contains(100.0, 200.0) && sq.contains(150.0, 230.0));
    // A single point still gives a valid grid.
    let p = BoundsXY::new([1.0, 1.0], [1.0, 1.0]);
    let g = TileGrid::plan(p, 1.0, 0.0, 1 << 20, 100).unwrap();
    assert_eq!(g.len(), 1);
    assert_eq!(g.owner(1.0, 1.0), TileId { col: 0, row: 0 });
}

#[test]
fn plan_large_cloud_is_the_largest_tile_within_the_budget_fraction() {
    let b = BoundsXY::new([0.0, 0.0], [10_000.0, 6_000.0]);
    let (density, halo, budget, bpp) = (100.0, 5.0, 2u64 << 30, 100u64);
    let g = TileGrid::plan(b, density, halo, budget, bpp).unwrap();
    let limit = TILE_BUDGET_FRACTION * budget as f64;
    // Analytic: density·(s+2h)²·bpp = limit  ⇒  s = sqrt(limit/(density·bpp)) − 2h.
    let s = (limit / (density * bpp as f64)).sqrt() - 2.0 * halo;
    assert!((g.tile_size() - s).abs() <= 1e-9 * s);
    assert!(g.tile_bytes_estimate(density, halo, bpp) <= limit * (1.0 + 1e-12));
    assert!(g.tile_size() >= 4.0 * halo);
    // The grid covers the bounds.
    let last = g.square(TileId {
        col: g.cols() - 1,
        row: g.rows() - 1,
    });
    assert!(last.max[0] >= 10_000.0 && last.max[1] >= 6_000.0);
    assert_eq!(g.cols(), (10_000.0 / s).ceil() as u32);
    // Very dense: never below 4·halo.
    let g = TileGrid::plan(b, 1e6, halo, budget, bpp).unwrap();
    assert_eq!(g.tile_size(), 4.0 * halo);
}

#[test]
fn plan_rejects_bad_parameters() {
    let b = BoundsXY::new([0.0, 0.0], [1.0, 1.0]);
    assert!(TileGrid::plan(b, 1.0, -1.0, 1, 1).is_err());
    assert!(TileGrid::plan(b, 1.0, 1.0, 0, 1).is_err());
    assert!(TileGrid::plan(BoundsXY::new([0.0, f64::NAN], [1.0, 1.0]), 1.0, 1.0, 1, 1).is_err());
    assert!(TileGrid::plan(BoundsXY::new([2.0, 0.0], [1.0, 1.0]), 1.0, 1.0, 1, 1).is_err());
}
