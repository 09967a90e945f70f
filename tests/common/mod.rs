//! Shared helpers of the integration tests: deterministic random surfaces, writing clouds,
//! running `talus`.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use talus::io::las_out::ResultWriter;
use talus::io::{Crs, Point3};

/// splitmix64: a tiny deterministic generator for test surfaces.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// UTM-like offset so that the tests exercise large coordinates.
pub const OFFSET: Point3 = [500_000.0, 5_000_000.0, 100.0];

/// Write `points` (global coordinates) as LAS/LAZ by the extension.
pub fn write_cloud(path: &Path, points: &[Point3]) {
    let mut w = ResultWriter::create(path, &Crs::default(), &[], OFFSET).unwrap();
    for p in points {
        w.write(*p, &[]).unwrap();
    }
    w.finish().unwrap();
}

/// Write a text cloud "x y z" per line.
pub fn write_text(path: &Path, header: &str, points: &[Point3]) {
    let mut s = String::from(header);
    for p in points {
        s.push_str(&format!("{:.4},{:.4},{:.4}\n", p[0], p[1], p[2]));
    }
    std::fs::write(path, s).unwrap();
}

/// The talus binary built for these tests.
pub fn talus() -> Command {
    Command::new(env!("CARGO_BIN_EXE_talus"))
}

/// Run talus with `args`; returns the output.
pub fn run(args: &[&str]) -> Output {
    talus().args(args).output().expect("talus runs")
}

/// `talus compare BEFORE AFTER --out OUT EXTRA...`, whatever its outcome.
pub fn run_compare(before: &Path, after: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "compare",
        before.to_str().unwrap(),
        after.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

/// A fresh temporary directory.
pub fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

/// The shared data folder, or None (tests that need it then say so and skip).
pub fn shared_data(sub: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(sub);
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "SKIPPED: {} is missing (the shared data folder is not beside the checkout)",
            p.display()
        );
        None
    }
}
pub mod dod;
pub mod laspy;
