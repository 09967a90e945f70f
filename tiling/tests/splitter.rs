//! The splitter against a brute-force reference: every tile file must hold exactly the input
//! points inside its halo box, in input order, with `owned` = 1 exactly where the tile owns the
//! point, whatever the push chunk size and memory budget (a tiny budget forces many flushes).

use talus_tiling::{
    read_tile, tile_path, BoundsXY, ColumnData, TileGrid, TileId, TileSplitter, OWNED_COLUMN,
};

fn points(n: usize) -> Vec<[f64; 3]> {
    let mut s: u64 = 42;
    let mut next = || {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut v: Vec<[f64; 3]> = (0..n)
        .map(|_| {
            let (x, y) = (next() * 100.0, next() * 60.0);
            [x, y, (x * 0.1).sin() + 0.01 * next()]
        })
        .collect();
    // Points exactly on tile edges and halo limits (tile size 10, halo 3) and the grid corners.
    for k in 0..=10 {
        let e = f64::from(k) * 10.0;
        v.extend([
            [e, 30.0, 1.0],
            [e - 3.0, 5.0, 2.0],
            [e + 3.0, 59.0, 3.0],
            [e, 60.0, 4.0],
        ]);
    }
    v.push([100.0, 60.0, 5.0]);
    v.push([0.0, 0.0, 6.0]);
    v
}

/// What tile `id` must contain, by brute force over the input.
fn reference(grid: &TileGrid, halo: f64, pts: &[[f64; 3]], id: TileId) -> (Vec<[u64; 3]>, Vec<u8>) {
    let bx = grid.halo_box(id, halo);
    let mut xyz = vec![];
    let mut owned = vec![];
    for p in pts {
        if bx.contains(p[0], p[1]) {
            xyz.push([p[0].to_bits(), p[1].to_bits(), p[2].to_bits()]);
            owned.push(u8::from(grid.owner(p[0], p[1]) == id));
        }
    }
    (xyz, owned)
}

fn run(
    dir: &std::path::Path,
    grid: TileGrid,
    halo: f64,
    pts: &[[f64; 3]],
    chunk: usize,
    budget: u64,
) {
    let mut s = TileSplitter::new(dir, grid, halo, budget).unwrap();
    for c in pts.chunks(chunk) {
        s.push(c).unwrap();
    }
    let written = s.finish().unwrap();
    assert!(!dir.join("segments").exists());
    let mut owned_total = 0u64;
    for id in grid.tiles() {
        let (want_xyz, want_owned) = reference(&grid, halo, pts, id);
        let path = tile_path(dir, id);
        if want_xyz.is_empty() {
            assert!(!path.exists(), "{id}: empty tile written");
            assert!(!written.iter().any(|(w, _)| *w == id));
            continue;
        }
        let t = read_tile(&path).unwrap();
        let got: Vec<[u64; 3]> = (0..t.len())
            .map(|i| [t.x[i].to_bits(), t.y[i].to_bits(), t.z[i].to_bits()])
            .collect();
        assert_eq!(got, want_xyz, "{id} chunk {chunk} budget {budget}");
        match t.column(OWNED_COLUMN) {
            Some(ColumnData::U8(o)) => {
                assert_eq!(o, &want_owned, "{id}");
                owned_total += o.iter().map(|&b| u64::from(b)).sum::<u64>();
            }
            other => panic!("owned column missing: {other:?}"),
        }
        assert!(written.contains(&(id, want_xyz.len() as u64)));
    }
    // Every input point is owned by exactly one tile.
    assert_eq!(owned_total, pts.len() as u64);
}

#[test]
fn output_is_the_brute_force_set_for_any_chunking_and_budget() {
    let pts = points(20_000);
    let grid = TileGrid::new([0.0, 0.0], 10.0, 10, 6).unwrap();
    let halo = 3.0;
    let dir = tempfile::tempdir().unwrap();
    for (chunk, budget) in [
        (pts.len(), 1 << 30), // everything in memory, no flush
        (1, 4096),            // one point per push, a flush every few points
        (997, 50_000),
        (5000, 300_000),
    ] {
        run(dir.path(), grid, halo, &pts, chunk, budget);
    }
}

#[test]
fn single_tile_plan_and_stale_files_are_cleared() {
    let pts = points(3000);
    let grid = TileGrid::plan(
        BoundsXY::new([0.0, 0.0], [100.0, 60.0]),
        0.5,
        3.0,
        1 << 30,
        100,
    )
    .unwrap();
    assert_eq!(grid.len(), 1);
    let dir = tempfile::tempdir().unwrap();
    // Leftovers of an interrupted earlier split with another grid.
    std::fs::write(dir.path().join("t_0042_0007.tile"), b"stale").unwrap();
    std::fs::create_dir_all(dir.path().join("segments")).unwrap();
    std::fs::write(dir.path().join("segments/t_0000_0000.seg"), b"garbage").unwrap();
    run(dir.path(), grid, 3.0, &pts, 100, 10_000);
    assert!(!dir.path().join("t_0042_0007.tile").exists());
}
