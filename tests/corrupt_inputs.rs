//! A probe corpus of damaged real files: header fields set to hostile values, truncations at
//! many offsets and single bit flips in the header, the VLRs and the point data of a real LAS
//! (autzen 2010) and a real LAZ (St Leonards). For every variant `talus info` (which reads
//! every point: the spacing is measured over all of them) and, for a deterministic share of the
//! variants, `talus compare` must either succeed with sane results (every point within the
//! header's bounds) or fail with exit code 2 and exactly one line on stderr naming the file;
//! never a panic, never exit 1, never hang.
//!
//! The variants are chosen by a fixed seed, so a failure names a variant that can be made again.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::Rng;

/// Longest a single run may take before it counts as a hang.
const TIMEOUT: Duration = Duration::from_secs(30);

/// LAS 1.4 R15 Table 3: byte offsets of the public header's fields.
mod field {
    pub const VERSION_MAJOR: usize = 24;
    pub const VERSION_MINOR: usize = 25;
    pub const HEADER_SIZE: usize = 94;
    pub const OFFSET_TO_POINTS: usize = 96;
    pub const NUMBER_OF_VLRS: usize = 100;
    pub const POINT_FORMAT: usize = 104;
    pub const RECORD_LENGTH: usize = 105;
    pub const LEGACY_COUNT: usize = 107;
    pub const SCALE: usize = 131;
    pub const OFFSET: usize = 155;
    /// max x, min x, max y, min y, max z, min z
    pub const BOUNDS: usize = 179;
    pub const START_OF_EVLRS: usize = 235;
    pub const NUMBER_OF_EVLRS: usize = 243;
    pub const COUNT: usize = 247;
}

struct Variant {
    name: String,
    bytes: Vec<u8>,
    /// Also run `talus compare` on it.
    compare: bool,
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn f64_at(b: &[u8], at: usize) -> f64 {
    f64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

/// How many variants of which kinds.
struct Plan {
    /// Bit flips per region (header, VLRs, point data).
    flips: usize,
    cuts: usize,
    /// Also the scale, offset and bounds fields (read by the same code for LAS and LAZ).
    transforms: bool,
    /// Run compare on every n-th variant.
    compare_every: usize,
}

/// The variants of `good`: header fields, truncations, bit flips (positions from `seed`).
fn variants(good: &[u8], seed: u64, plan: &Plan) -> Vec<Variant> {
    let mut out = Vec::new();
    let mut put = |name: String, bytes: Vec<u8>| {
        out.push(Variant {
            name,
            bytes,
            compare: false,
        })
    };
    let set = |at: usize, value: &[u8]| {
        let mut b = good.to_vec();
        b[at..at + value.len()].copy_from_slice(value);
        b
    };
    let points_at = u32_at(good, field::OFFSET_TO_POINTS) as usize;
    let len = good.len() as u64;
    for v in [0u32, 1, 1 << 31, u32::MAX] {
        put(
            format!("legacy_count_{v}"),
            set(field::LEGACY_COUNT, &v.to_le_bytes()),
        );
    }
    for v in [0u64, 1, 1 << 32, u64::MAX] {
        put(format!("count_{v}"), set(field::COUNT, &v.to_le_bytes()));
    }
    for v in [
        0,
        1,
        227,
        375,
        points_at as u32 - 1,
        points_at as u32 + 1,
        len as u32,
        u32::MAX,
    ] {
        put(
            format!("offset_to_points_{v}"),
            set(field::OFFSET_TO_POINTS, &v.to_le_bytes()),
        );
    }
    for v in [0u32, 2, 1000, u32::MAX] {
        put(
            format!("vlrs_{v}"),
            set(field::NUMBER_OF_VLRS, &v.to_le_bytes()),
        );
    }
    for v in [0u16, 100, 226, 400, u16::MAX] {
        put(
            format!("header_size_{v}"),
            set(field::HEADER_SIZE, &v.to_le_bytes()),
        );
    }
    for v in [0u8, 1, 3, 6, 10, 11, 127, 0x80, 0xC7, 255] {
        put(format!("point_format_{v}"), set(field::POINT_FORMAT, &[v]));
    }
    for v in [0u16, 1, 19, 20, 1000, u16::MAX] {
        put(
            format!("record_length_{v}"),
            set(field::RECORD_LENGTH, &v.to_le_bytes()),
        );
    }
    for (major, minor) in [(0, 0), (1, 0), (1, 1), (1, 5), (2, 0), (255, 255)] {
        let mut b = good.to_vec();
        b[field::VERSION_MAJOR] = major;
        b[field::VERSION_MINOR] = minor;
        put(format!("version_{major}.{minor}"), b);
    }
    for axis in (0..3).filter(|_| plan.transforms) {
        let scale = f64_at(good, field::SCALE + 8 * axis);
        for v in [
            0.0,
            -scale,
            1e300,
            f64::NAN,
            f64::INFINITY,
            5e-324,
            1e-300,
            scale * 2.0,
        ] {
            put(
                format!("scale{axis}_{v:e}"),
                set(field::SCALE + 8 * axis, &v.to_le_bytes()),
            );
        }
        let offset = f64_at(good, field::OFFSET + 8 * axis);
        for v in [f64::NAN, 1e300, -1e15, offset + 1000.0] {
            put(
                format!("offset{axis}_{v:e}"),
                set(field::OFFSET + 8 * axis, &v.to_le_bytes()),
            );
        }
    }
    for k in (0..6).filter(|_| plan.transforms) {
        let bound = f64_at(good, field::BOUNDS + 8 * k);
        for v in [
            0.0,
            1e300,
            -1e300,
            f64::NAN,
            bound + if k % 2 == 0 { -1.0 } else { 1.0 },
        ] {
            put(
                format!("bound{k}_{v:e}"),
                set(field::BOUNDS + 8 * k, &v.to_le_bytes()),
            );
        }
    }
    for v in [0u64, len - 1, len + 1, u64::MAX] {
        put(
            format!("evlr_start_{v}"),
            set(field::START_OF_EVLRS, &v.to_le_bytes()),
        );
    }
    for v in [1u32, 1000, u32::MAX] {
        put(
            format!("evlrs_{v}"),
            set(field::NUMBER_OF_EVLRS, &v.to_le_bytes()),
        );
    }
    let mut rng = Rng::new(seed);
    for _ in 0..plan.cuts {
        let at = (rng.next_u64() % len) as usize;
        put(format!("cut_{at}"), good[..at].to_vec());
    }
    let header_size = usize::from(u16::from_le_bytes([good[94], good[95]]));
    for (region, lo, hi) in [
        ("header", 0, header_size),
        ("vlrs", header_size, points_at),
        ("points", points_at, good.len()),
    ] {
        for _ in 0..plan.flips.min(8 * (hi - lo)) {
            let at = lo + (rng.next_u64() % (hi - lo) as u64) as usize;
            let bit = rng.next_u64() % 8;
            let mut b = good.to_vec();
            b[at] ^= 1 << bit;
            put(format!("flip_{region}_{at}_{bit}"), b);
        }
    }
    out
}

/// Run talus with `args`; None when it did not finish within [`TIMEOUT`].
fn run(args: &[&str]) -> Option<std::process::Output> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_talus"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Drain the pipes while waiting, so a chatty child cannot block on a full pipe.
    let out = child.stdout.take().unwrap();
    let err = child.stderr.take().unwrap();
    let read = |mut r: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            let _ = r.read_to_end(&mut v);
            v
        })
    };
    let (out, err) = (read(Box::new(out)), read(Box::new(err)));
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    Some(std::process::Output {
        status,
        stdout: out.join().unwrap(),
        stderr: err.join().unwrap(),
    })
}

/// The verdict on one run: None when it is acceptable, else what is wrong.
fn judge(
    file: &Path,
    o: Option<std::process::Output>,
    ok: impl FnOnce(&[u8]) -> Option<String>,
) -> Option<String> {
    let Some(o) = o else {
        return Some(format!("no answer within {TIMEOUT:?}"));
    };
    let err = String::from_utf8_lossy(&o.stderr);
    let name = file.file_name().unwrap().to_str().unwrap();
    if err.contains("panicked") {
        return Some(format!("panic: {err}"));
    }
    match o.status.code() {
        Some(0) => ok(&o.stdout),
        Some(2) if err.trim().lines().count() == 1 && err.contains(name) => None,
        Some(2) => Some(format!("exit 2 but not one line naming {name}: {err}")),
        code => Some(format!("exit {code:?}: {err}")),
    }
}

/// What must hold when `talus info --json` accepted a variant: the bounds are the header's
/// (read here from the bytes), finite and ordered, and every point the reader yields lies in
/// them (half a scale step of slack); a positive spacing, or none and why.
fn sane_info(path: &Path, bytes: &[u8], stdout: &[u8]) -> Option<String> {
    let v: serde_json::Value = match serde_json::from_slice(stdout) {
        Ok(v) => v,
        Err(e) => return Some(format!("info printed no JSON: {e}")),
    };
    let r = &v[0];
    // A file info describes without a spacing says why (issue 44: too few distinct positions,
    // or none of the classes compared), and derives nothing.
    let unmeasured = r["spacing"].is_null()
        && r["derived"].is_null()
        && r["spacing_note"].as_str().is_some_and(|n| !n.is_empty());
    let spacing = r["spacing"]["effective_spacing"]
        .as_f64()
        .unwrap_or(f64::NAN);
    let measured = spacing > 0.0 && spacing.is_finite();
    if !(unmeasured || measured) {
        return Some(format!("spacing {spacing}"));
    }
    let (info, points) = match talus::io::read_all(path) {
        Ok(x) => x,
        Err(e) => return Some(format!("info accepted it but the reader refuses it: {e}")),
    };
    let mut min = [0.0; 3];
    let mut max = [0.0; 3];
    for k in 0..3 {
        max[k] = f64_at(bytes, field::BOUNDS + 16 * k);
        min[k] = f64_at(bytes, field::BOUNDS + 16 * k + 8);
        if !(min[k].is_finite() && max[k].is_finite() && min[k] <= max[k]) {
            return Some(format!("accepted header bounds {min:?} .. {max:?}"));
        }
    }
    if info.bounds.min != min || info.bounds.max != max {
        return Some(format!(
            "reported bounds {:?} are not the header's",
            info.bounds
        ));
    }
    if points.len() as u64 != info.point_count || r["points"].as_u64() != Some(info.point_count) {
        return Some(format!(
            "{} points read, {} promised",
            points.len(),
            info.point_count
        ));
    }
    let scale = info.scale.unwrap_or([0.0; 3]);
    for (i, p) in points.iter().enumerate() {
        for k in 0..3 {
            let slack = scale[k] + 1e-9 * max[k].abs().max(min[k].abs());
            if !(p[k] >= min[k] - slack && p[k] <= max[k] + slack) {
                return Some(format!("point {i} at {p:?} outside the header's bounds"));
            }
        }
    }
    None
}

/// Probe every variant of `good`; `other` is the second epoch for compare.
fn probe(good: &Path, other: &Path, plan: Plan) {
    let tmp = common::tempdir();
    let bytes = std::fs::read(good).unwrap();
    let ext = good.extension().unwrap().to_str().unwrap();
    let mut all = variants(&bytes, 14, &plan);
    for (i, v) in all.iter_mut().enumerate() {
        v.compare = i % plan.compare_every == 0;
    }
    let start = Instant::now();
    let mut failures = Vec::new();
    let (mut accepted, mut refused) = (0, 0);
    for v in &all {
        let file: PathBuf = tmp.path().join(format!("{}.{ext}", v.name));
        std::fs::write(&file, &v.bytes).unwrap();
        let f = file.to_str().unwrap();
        let o = run(&["info", "--json", f]);
        let exit0 = o.as_ref().is_some_and(|o| o.status.success());
        if let Some(problem) = judge(&file, o, |out| sane_info(&file, &v.bytes, out)) {
            failures.push(format!("{}: info: {problem}", v.name));
        }
        if exit0 {
            accepted += 1;
        } else {
            refused += 1;
        }
        if v.compare {
            let out = tmp.path().join(format!("out_{}", v.name));
            let o = run(&[
                "compare",
                f,
                other.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ]);
            if let Some(problem) = judge(&file, o, |_| {
                (!out.join("summary.json").is_file()).then(|| "no summary.json".to_string())
            }) {
                failures.push(format!("{}: compare: {problem}", v.name));
            }
            let _ = std::fs::remove_dir_all(&out);
        }
        std::fs::remove_file(&file).unwrap();
    }
    eprintln!(
        "{}: {} variants ({accepted} read, {refused} refused) in {:.1} s",
        good.display(),
        all.len(),
        start.elapsed().as_secs_f64()
    );
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn damaged_las_files_are_read_or_refused_cleanly() {
    let dir = common::data("autzen-bmx");
    probe(
        &dir.join("autzen-bmx-2010.las"),
        &dir.join("autzen-bmx-2023.las"),
        Plan {
            flips: 60,
            cuts: 40,
            transforms: true,
            compare_every: 3,
        },
    );
}

#[test]
fn damaged_laz_files_are_read_or_refused_cleanly() {
    let dir = common::data("st-leonards");
    probe(
        &dir.join("leo_20190731_dsm_resampled_1m.laz"),
        &dir.join("leo_20190328_dsm_resampled_1m.laz"),
        // 90k points: each run measures their spacing, so fewer variants than for the LAS.
        Plan {
            flips: 20,
            cuts: 12,
            transforms: false,
            compare_every: 40,
        },
    );
}
