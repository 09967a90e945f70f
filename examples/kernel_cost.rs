//! Cost probe of the M3C2 kernel on the column grid, for choosing the column width: times the
//! normal and cylinder queries (as M3C2 makes them: the projections collected, one surface kept)
//! of the core points of a rough surface, one thread. Run it under `valgrind --tool=callgrind`
//! for instruction counts that ignore the machine's load.
//!
//! `cargo run --release --example kernel_cost -- CELL [DENSITY NORMAL_RADIUS CYL_RADIUS HALFLEN]`
//! (lengths in metres, DENSITY in points per m²; defaults: the py4dgeo benchmark's 100 points
//! per m², normal radius 1.0, cylinder radius 0.5, half-length 3.0, over 100 m × 100 m; the
//! 120M-point synthetic pair has 46 points per m², 0.59, 0.44 and 4.4).

use std::time::Instant;

use talus::io::Point3;
use talus::m3c2::{cylinder, normals};
use talus::spatial::Columns;

/// `n` points of a rough surface over `side` × `side` metres.
fn surface(n: usize, side: f64, seed: u64) -> Vec<Point3> {
    let mut r = talus::rng::SplitMix64::new(seed);
    let mut u = move || r.uniform();
    (0..n)
        .map(|_| {
            let (x, y) = (u() * side, u() * side);
            [x, y, height(x, y) + 0.005 * u()]
        })
        .collect()
}

fn height(x: f64, y: f64) -> f64 {
    2.0 * (x / 13.0).sin() * (y / 17.0).cos() + 0.3 * (x / 2.1).sin() * (y / 1.7).sin()
}

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .map(|s| s.parse().expect("arguments: numbers"))
        .collect();
    let arg = |k: usize, default: f64| args.get(k).copied().unwrap_or(default);
    let cell = arg(0, 0.5);
    let (density, normal_radius, r, h) = (arg(1, 100.0), arg(2, 1.0), arg(3, 0.5), arg(4, 3.0));
    let side = 100.0;
    let n = (density * side * side) as usize;
    let (before, after) = (surface(n, side, 1), surface(n, side, 2));
    let t = Instant::now();
    let b = Columns::new(&before, [0.0; 3], cell);
    let a = Columns::new(&after, [0.0; 3], cell);
    println!(
        "index: {:.3} s for 2 x {n} points",
        t.elapsed().as_secs_f64()
    );
    let per_side = 316;
    let step = (side - 0.6) / per_side as f64;
    let cores: Vec<Point3> = (0..per_side * per_side)
        .map(|k| {
            let (x, y) = (
                0.3 + (k % per_side) as f64 * step,
                0.3 + (k / per_side) as f64 * step,
            );
            [x, y, height(x, y)]
        })
        .collect();
    let t = Instant::now();
    let ns: Vec<Point3> = cores
        .iter()
        .map(|q| normals::normal_at(&b, q, normal_radius).map_or([f64::NAN; 3], |x| x.0))
        .collect();
    let tn = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut total = 0u64;
    let (mut p1, mut p2) = (
        cylinder::Projections::default(),
        cylinder::Projections::default(),
    );
    for (q, n) in cores.iter().zip(&ns) {
        p1.collect(&b, q, n, r, h);
        let (c1, span) = p1.surface(2.0 * r, (0.0, 0.0));
        p2.collect(&a, q, n, r, h);
        let (c2, _) = p2.surface(2.0 * r, span);
        total += u64::from(c1.count + c2.count);
    }
    let tc = t.elapsed().as_secs_f64();
    let per = |s: f64| s / cores.len() as f64 * 1e6;
    println!(
        "cell {cell}: normal {:.2} µs, two cylinders {:.2} µs per core point ({total} points)",
        per(tn),
        per(tc)
    );
}
