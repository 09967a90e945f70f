//! Criterion benches of the inner loops on a rough 1M-point surface: neighbourhood queries (the
//! kd-tree of the later stages, the column grid of M3C2) and M3C2 per core point (the column
//! grid's cylinder query against the circumscribed-sphere query).
//!
//! `cargo bench --bench neighbourhood`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use talus::io::Point3;
use talus::m3c2::{self, cylinder, M3c2Params, Orientation};
use talus::spatial::{Columns, Index};

/// A rough surface over 100 m × 100 m: a few octaves of waves plus 5 mm noise.
fn surface(n: usize, seed: u64) -> Vec<Point3> {
    let mut r = talus::rng::SplitMix64::new(seed);
    (0..n)
        .map(|_| {
            let (x, y) = (r.uniform() * 100.0, r.uniform() * 100.0);
            let z = 2.0 * (x / 13.0).sin() * (y / 17.0).cos()
                + 0.3 * (x / 2.1).sin() * (y / 1.7).sin()
                + 0.05 * (x / 0.31).cos()
                + 0.005 * (r.uniform() - 0.5);
            [x, y, z]
        })
        .collect()
}

fn benches(c: &mut Criterion) {
    let before = surface(1_000_000, 1);
    let after = surface(1_000_000, 2);
    let tree = Index::new(&before, [50.0, 50.0, 0.0]);
    // 1000 core points in Morton-like (row) order, as the pipeline queries them.
    let mut cores: Vec<Point3> = before
        .iter()
        .step_by(1000)
        .map(|p| tree.to_local(p))
        .collect();
    cores.sort_by(|p, q| (p[1] as i64, p[0] as i64).cmp(&(q[1] as i64, q[0] as i64)));
    let params = M3c2Params {
        normal_radius: 1.0,
        cyl_radius: 0.5,
        cyl_halflen: 3.0,
        min_points: 1,
        orientation: Orientation::Up,
        point_spacing: 0.1,
        walk: m3c2::Walk::Off,
    };
    let cell = m3c2::column_width(&params);
    let b = Columns::new(&before, [50.0, 50.0, 0.0], cell);
    let a = Columns::new(&after, [50.0, 50.0, 0.0], cell);
    let (normals, _) = m3c2::normals(&b, &cores, &params, None);

    let mut g = c.benchmark_group("neighbourhood");
    g.bench_function("kd-tree sphere r=1.0, 1000 queries", |bench| {
        bench.iter(|| {
            let mut n = 0usize;
            for q in &cores {
                tree.for_each_within(q, 1.0, |_, _| n += 1);
            }
            black_box(n)
        })
    });
    g.bench_function("columns sphere r=1.0, 1000 queries", |bench| {
        bench.iter(|| {
            let mut n = 0usize;
            for q in &cores {
                b.for_each_within(q, 1.0, |_| n += 1);
            }
            black_box(n)
        })
    });
    g.bench_function("knn k=30, 1000 queries", |bench| {
        bench.iter(|| {
            for q in &cores {
                black_box(tree.nearest(q, 30));
            }
        })
    });
    g.finish();

    let mut g = c.benchmark_group("m3c2 per core point");
    g.bench_function("normal r=1.0, 1000 cores", |bench| {
        bench.iter(|| {
            for q in &cores {
                black_box(m3c2::normals::normal_at(&b, q, 1.0));
            }
        })
    });
    g.bench_function(
        "cylinder columns r=0.5 h=3, 1000 cores x 2 epochs",
        |bench| {
            bench.iter(|| {
                for (q, n) in cores.iter().zip(&normals) {
                    black_box(cylinder::cylinder_stats(&b, q, n, 0.5, 3.0));
                    black_box(cylinder::cylinder_stats(&a, q, n, 0.5, 3.0));
                }
            })
        },
    );
    g.bench_function(
        "cylinder sphere r=0.5 h=3, 1000 cores x 2 epochs",
        |bench| {
            bench.iter(|| {
                for (q, n) in cores.iter().zip(&normals) {
                    black_box(cylinder::cylinder_stats_sphere(&b, q, n, 0.5, 3.0));
                    black_box(cylinder::cylinder_stats_sphere(&a, q, n, 0.5, 3.0));
                }
            })
        },
    );
    g.finish();
}

criterion_group! {
    name = group;
    config = Criterion::default().sample_size(10);
    targets = benches
}
criterion_main!(group);
