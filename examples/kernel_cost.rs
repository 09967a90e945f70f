//! Cost probe of the M3C2 kernel on the column grid, for choosing the column width: times the
//! normal and cylinder queries of 100k core points on a rough 1M-point surface, one thread.
//! Run it under `valgrind --tool=callgrind` for instruction counts that ignore the machine's load.
//!
//! `cargo run --release --example kernel_cost -- CELL` (CELL in metres; normal radius 1.0,
//! cylinder radius 0.5, half-length 3.0)

use std::time::Instant;

use talus::io::Point3;
use talus::m3c2::{cylinder, normals};
use talus::spatial::Columns;

fn surface(n: usize, seed: u64) -> Vec<Point3> {
    let mut s = seed;
    let mut u = move || {
        s = s.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            let (x, y) = (u() * 100.0, u() * 100.0);
            let z = 2.0 * (x / 13.0).sin() * (y / 17.0).cos()
                + 0.3 * (x / 2.1).sin() * (y / 1.7).sin()
                + 0.005 * u();
            [x, y, z]
        })
        .collect()
}

fn main() {
    let cell: f64 = std::env::args()
        .nth(1)
        .map(|s| s.parse().expect("CELL: a number"))
        .unwrap_or(0.25);
    let (before, after) = (surface(1_000_000, 1), surface(1_000_000, 2));
    let t = Instant::now();
    let b = Columns::new(&before, [0.0; 3], cell);
    let a = Columns::new(&after, [0.0; 3], cell);
    println!(
        "index: {:.3} s for 2 x 1M points",
        t.elapsed().as_secs_f64()
    );
    let cores: Vec<Point3> = (0..316 * 316)
        .map(|k| {
            let (x, y) = (
                0.3 + (k % 316) as f64 * 0.316,
                0.3 + (k / 316) as f64 * 0.316,
            );
            [
                x,
                y,
                2.0 * (x / 13.0).sin() * (y / 17.0).cos() + 0.3 * (x / 2.1).sin() * (y / 1.7).sin(),
            ]
        })
        .collect();
    let t = Instant::now();
    let ns: Vec<Point3> = cores
        .iter()
        .map(|q| normals::normal_at(&b, q, 1.0).map_or([f64::NAN; 3], |x| x.0))
        .collect();
    let tn = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut total = 0u64;
    for (q, n) in cores.iter().zip(&ns) {
        total += cylinder::cylinder_stats(&b, q, n, 0.5, 3.0).count as u64;
        total += cylinder::cylinder_stats(&a, q, n, 0.5, 3.0).count as u64;
    }
    let tc = t.elapsed().as_secs_f64();
    let per = |s: f64| s / cores.len() as f64 * 1e6;
    println!(
        "cell {cell}: normal {:.2} µs, two cylinders {:.2} µs per core point ({total} points)",
        per(tn),
        per(tc)
    );
}
