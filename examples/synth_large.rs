//! Write the `large` synthetic scene for a measurement of time and peak memory:
//! `cargo run --release --example synth_large -- POINTS OUT_DIR` then, e.g.,
//! `/usr/bin/time -v target/release/examples/synth_large 10000000 /tmp/large`.

use std::path::PathBuf;
use std::time::Instant;

use talus::synth::{synth, SceneKind, SynthOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let points: u64 = args.next().as_deref().unwrap_or("10000000").parse()?;
    let out = PathBuf::from(args.next().unwrap_or_else(|| "synth-large".into()));
    let opts = SynthOptions {
        points: Some(points),
        ..SynthOptions::default()
    };
    let t = Instant::now();
    let truth = synth(SceneKind::Large, &opts, &out)?;
    println!(
        "large: {} + {} points, {} events, {:.1} s",
        truth.points[0],
        truth.points[1],
        truth.events.len(),
        t.elapsed().as_secs_f64()
    );
    Ok(())
}
