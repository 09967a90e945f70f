//! Instruction-count probe of the cylinder query for different segment lengths (run under
//! `valgrind --tool=callgrind`, which counts instructions whatever the machine's load):
//!
//! `cargo build --release --example kernel_cost && valgrind --tool=callgrind target/release/examples/kernel_cost 2.0 3.0 0.5`
//!
//! Arguments: segment length in units of r, half-length h, radius r.

use talus::io::Point3;
use talus::m3c2::cylinder::cylinder_stats_segmented;
use talus::spatial::Index;

fn main() {
    let a: Vec<f64> = std::env::args()
        .skip(1)
        .map(|s| s.parse().expect("number"))
        .collect();
    let (factor, h, r) = (a[0], a[1], a[2]);
    let mut s = 7u64;
    let mut u = move || {
        s = s.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    // 100 points per m² on a gently rough 40 m × 40 m surface.
    let pts: Vec<Point3> = (0..160_000)
        .map(|_| {
            let (x, y) = (u() * 40.0, u() * 40.0);
            [
                x,
                y,
                0.5 * (x / 5.0).sin() + 0.1 * (y / 1.3).cos() + 0.005 * u(),
            ]
        })
        .collect();
    let idx = Index::new(&pts, [20.0, 20.0, 0.0]);
    let mut total = 0u64;
    for p in pts.iter().step_by(8) {
        let q = idx.to_local(p);
        let st = cylinder_stats_segmented(&idx, &q, &[0.0, 0.0, 1.0], r, h, factor * r);
        total += st.count as u64;
    }
    println!("{total}");
}
