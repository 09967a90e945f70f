//! Measure tile-file compression on a realistic noisy terrain sample and split throughput.
//!
//! `cargo run --release -p talus-tiling --example measure [split_points]`
//!
//! The sample imitates an airborne scan stored as LAS: scan lines 0.25 m apart, points 0.2 m
//! apart along a line with jitter, rolling terrain plus 3 cm roughness and sparse vegetation
//! returns, coordinates quantised the way LAS stores them (integers × 0.001 + offset).

use std::time::Instant;
use talus_base::rng::SplitMix64;
use talus_tiling::{
    read_tile, write_tile_with, BoundsXY, Quantisation, TileColumns, TileGrid, TileSplitter,
    WriteOptions,
};

const SCALE: [f64; 3] = [0.001, 0.001, 0.001];
const OFFSET: [f64; 3] = [500_000.0, 5_100_000.0, 0.0];

fn las(v: f64, axis: usize) -> f64 {
    let k = ((v - OFFSET[axis]) / SCALE[axis]).round() as i32;
    SCALE[axis] * f64::from(k) + OFFSET[axis]
}

/// Terrain points `start..start + n` in scan order: lines of `per_line` points.
fn terrain(start: usize, n: usize, per_line: usize, rng: &mut SplitMix64) -> Vec<[f64; 3]> {
    (start..start + n)
        .map(|i| {
            let (line, j) = ((i / per_line) as f64, (i % per_line) as f64);
            let x = 512_000.0 + j * 0.2 + 0.05 * rng.normal();
            let y = 5_123_000.0 + line * 0.25 + 0.05 * rng.normal();
            let (u, v) = (x - 512_000.0, y - 5_123_000.0);
            let mut z =
                300.0 + 8.0 * (u / 37.0).sin() * (v / 23.0).cos() + 0.05 * u + 0.03 * rng.normal();
            if rng.uniform() < 0.05 {
                z += 2.0 + 10.0 * rng.uniform(); // vegetation return
            }
            [las(x, 0), las(y, 1), las(z, 2)]
        })
        .collect()
}

/// CPU seconds this thread has run (Linux schedstat), so figures survive a busy shared machine
/// where wall time mostly measures waiting for a core. NaN where unavailable.
fn cpu_s() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns / 1e9)
}

fn main() {
    let split_n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(10_000_000);
    let dir = std::env::temp_dir().join(format!("talus-tiling-measure-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut rng = SplitMix64::new(1);

    let n = 1_000_000;
    let pts = terrain(0, n, 1000, &mut rng);
    let cols = TileColumns {
        x: pts.iter().map(|p| p[0]).collect(),
        y: pts.iter().map(|p| p[1]).collect(),
        z: pts.iter().map(|p| p[2]).collect(),
        extra: vec![],
    };
    println!("compression, {n} points (x, y, z only), bytes/point (raw: 24):");
    let path = dir.join("sample.tile");
    for quantise in [
        None,
        Some(Quantisation {
            scale: SCALE,
            offset: OFFSET,
        }),
    ] {
        for shuffle in [false, true] {
            for level in [1, 3] {
                let opts = WriteOptions {
                    level,
                    shuffle_f64: shuffle,
                    shuffle_f32: shuffle,
                    shuffle_int: shuffle,
                    quantise,
                };
                let c0 = cpu_s();
                write_tile_with(&path, &cols, &opts).expect("write");
                let tw = cpu_s() - c0;
                let c1 = cpu_s();
                let back = read_tile(&path).expect("read");
                let tr = cpu_s() - c1;
                assert_eq!(back.z.len(), n);
                let size = std::fs::metadata(&path).expect("size").len();
                println!(
                    "  quantised={:<5} shuffle={:<5} level={}  {:6.2} B/pt  write {:5.1} Mpt/CPU-s  read {:5.1} Mpt/CPU-s",
                    quantise.is_some(),
                    shuffle,
                    level,
                    size as f64 / n as f64,
                    n as f64 / tw / 1e6,
                    n as f64 / tr / 1e6
                );
            }
        }
    }

    // Split throughput: `split_n` points over ~1.4 km × 1 km, 1M-point pushes.
    let per_line = 7000;
    let lines = split_n.div_ceil(per_line);
    let bounds = BoundsXY::new(
        [512_000.0 - 1.0, 5_123_000.0 - 1.0],
        [
            512_000.0 + per_line as f64 * 0.2 + 1.0,
            5_123_000.0 + lines as f64 * 0.25 + 1.0,
        ],
    );
    let density = split_n as f64 / (bounds.extent()[0] * bounds.extent()[1]);
    let las = WriteOptions {
        quantise: Some(Quantisation {
            scale: SCALE,
            offset: OFFSET,
        }),
        ..WriteOptions::default()
    };
    for (budget, opts) in [
        (256u64 << 20, WriteOptions::default()),
        (32 << 20, WriteOptions::default()),
        (256 << 20, las),
    ] {
        // A tile budget giving ~16 tiles, a 2 m halo.
        let grid = TileGrid::plan(bounds, density, 2.0, 4 << 30, 1000).expect("plan");
        let split_dir = dir.join("split");
        let mut s = TileSplitter::new(&split_dir, grid, 2.0, budget)
            .expect("splitter")
            .with_options(opts);
        let mut rng = SplitMix64::new(2);
        let t0 = Instant::now();
        let c0 = cpu_s();
        let mut gen = 0.0;
        let mut gen_cpu = 0.0;
        let mut done = 0;
        while done < split_n {
            let m = (split_n - done).min(1_000_000);
            let tg = Instant::now();
            let cg = cpu_s();
            let chunk = terrain(done, m, per_line, &mut rng);
            gen += tg.elapsed().as_secs_f64();
            gen_cpu += cpu_s() - cg;
            s.push(&chunk).expect("push");
            done += m;
        }
        let tp = t0.elapsed().as_secs_f64() - gen;
        let cp = cpu_s() - c0 - gen_cpu;
        let t1 = Instant::now();
        let c1 = cpu_s();
        let tiles = s.finish().expect("finish");
        let tf = t1.elapsed().as_secs_f64();
        let cf = cpu_s() - c1;
        let stored: u64 = tiles.iter().map(|(_, c)| c).sum();
        let bytes: u64 = std::fs::read_dir(&split_dir)
            .expect("ls")
            .filter_map(|e| e.ok()?.metadata().ok())
            .map(|m| m.len())
            .sum();
        println!(
            "split {split_n} points, budget {} MiB, quantised {}: {} tiles ({}x{}, side {:.1} m), {} stored points (halo dup {:.3}), push {:.2} s wall / {:.2} s CPU, finish {:.2} s wall / {:.2} s CPU, total {:.1} Mpt/s wall, {:.1} Mpt/CPU-s, {:.2} B/stored pt",
            budget >> 20,
            opts.quantise.is_some(),
            tiles.len(),
            grid.cols(),
            grid.rows(),
            grid.tile_size(),
            stored,
            stored as f64 / split_n as f64,
            tp,
            cp,
            tf,
            cf,
            split_n as f64 / (tp + tf) / 1e6,
            split_n as f64 / (cp + cf) / 1e6,
            bytes as f64 / stored as f64
        );
        std::fs::remove_dir_all(&split_dir).expect("cleanup");
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
