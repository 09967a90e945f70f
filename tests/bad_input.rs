//! Bad input: one clear line naming the file and the problem, exit code 2, nothing left behind.

mod common;

use std::path::{Path, PathBuf};

use common::{Rng, OFFSET};
use talus::io::Point3;

fn plane(seed: u64, n: usize, dx: f64) -> Vec<Point3> {
    let mut r = Rng::new(seed);
    (0..n)
        .map(|_| {
            [
                OFFSET[0] + dx + r.uniform() * 10.0,
                OFFSET[1] + r.uniform() * 10.0,
                OFFSET[2] + 0.002 * r.normal(),
            ]
        })
        .collect()
}

struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new() -> Self {
        let c = Case {
            dir: common::tempdir(),
        };
        common::write_cloud(&c.p("good1.las"), &plane(1, 2000, 0.0));
        common::write_cloud(&c.p("good2.las"), &plane(2, 2000, 0.0));
        c
    }
    fn p(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    fn out(&self) -> PathBuf {
        self.p("out")
    }
    /// Run compare; assert exit code 2, a one-line message containing `needles`, no output.
    fn fails(&self, before: &Path, after: &Path, extra: &[&str], needles: &[&str]) {
        let out = self.out();
        let o = common::run_compare(before, after, &out, extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "stderr: {err}");
        assert_eq!(err.trim().lines().count(), 1, "not one line: {err}");
        for n in needles {
            assert!(err.contains(n), "'{n}' not in: {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{} was left behind", out.display());
    }
}

#[test]
fn missing_file() {
    let c = Case::new();
    let missing = c.p("nope.las");
    c.fails(&missing, &c.p("good2.las"), &[], &["nope.las"]);
}

#[test]
fn not_a_point_cloud() {
    let c = Case::new();
    let f = c.p("picture.png");
    std::fs::write(&f, b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\0\x01binary junk").unwrap();
    c.fails(&f, &c.p("good2.las"), &[], &["picture.png"]);
}

#[test]
fn truncated_las() {
    let c = Case::new();
    let f = c.p("cut.las");
    let bytes = std::fs::read(c.p("good1.las")).unwrap();
    std::fs::write(&f, &bytes[..bytes.len() - 1000]).unwrap();
    c.fails(&c.p("good2.las"), &f, &[], &["cut.las"]);
}

#[test]
fn truncated_laz() {
    let c = Case::new();
    let full = c.p("full.laz");
    common::write_cloud(&full, &plane(3, 20_000, 0.0));
    let bytes = std::fs::read(&full).unwrap();
    let f = c.p("cut.laz");
    std::fs::write(&f, &bytes[..bytes.len() / 2]).unwrap();
    c.fails(&f, &c.p("good2.las"), &[], &["cut.laz"]);
}

#[test]
fn zero_points() {
    let c = Case::new();
    let f = c.p("empty.las");
    common::write_cloud(&f, &[]);
    c.fails(&f, &c.p("good2.las"), &[], &["empty.las"]);
}

#[test]
fn nan_and_infinite_coordinates() {
    let c = Case::new();
    let mut pts = plane(4, 500, 0.0);
    pts[100][2] = f64::NAN;
    let f = c.p("nan.xyz");
    common::write_text(&f, "X,Y,Z\n", &pts);
    c.fails(&c.p("good1.las"), &f, &[], &["nan.xyz"]);
    let mut pts = plane(5, 500, 0.0);
    pts[7][0] = f64::INFINITY;
    let f = c.p("inf.xyz");
    common::write_text(&f, "X,Y,Z\n", &pts);
    c.fails(&f, &c.p("good2.las"), &[], &["inf.xyz"]);
}

#[test]
fn epochs_that_do_not_overlap() {
    let c = Case::new();
    let far = c.p("far.las");
    common::write_cloud(&far, &plane(6, 2000, 1000.0));
    c.fails(&c.p("good1.las"), &far, &[], &["do not overlap"]);
}

#[test]
fn non_positive_radii() {
    let c = Case::new();
    let (b, a) = (c.p("good1.las"), c.p("good2.las"));
    c.fails(&b, &a, &["--cyl-radius", "0"], &["--cyl-radius"]);
    c.fails(&b, &a, &["--normal-radius=-1"], &["--normal-radius"]);
    c.fails(&b, &a, &["--cyl-halflen", "nan"], &["--cyl-halflen"]);
}

#[test]
fn core_points_without_xyz() {
    let c = Case::new();
    let f = c.p("cores.csv");
    std::fs::write(&f, "name,value\nalpha,beta\ngamma,delta\n").unwrap();
    c.fails(
        &c.p("good1.las"),
        &c.p("good2.las"),
        &["--core-points", f.to_str().unwrap()],
        &["cores.csv"],
    );
}

#[test]
fn unwritable_output() {
    let c = Case::new();
    // A file where the output directory's parent should be.
    let blocker = c.p("blocker");
    std::fs::write(&blocker, b"x").unwrap();
    let out = blocker.join("out");
    let o = common::run(&[
        "compare",
        c.p("good1.las").to_str().unwrap(),
        c.p("good2.las").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("blocker"), "{err}");
}

#[test]
fn a_good_pair_works() {
    let c = Case::new();
    let out = c.out();
    let o = common::run(&[
        "compare",
        c.p("good1.las").to_str().unwrap(),
        c.p("good2.las").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("m3c2.laz").exists() && out.join("summary.json").exists());
}

/// The LAS 1.2–1.4 public header's fields used below (LAS 1.4 R15 Table 3): byte offsets.
const OFFSET_TO_POINTS: usize = 96;
const RECORD_LENGTH: usize = 105;
const SCALE_X: usize = 131;
const MAX_Z: usize = 211;

fn read_u32(b: &[u8], at: usize) -> usize {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize
}

fn put_f64(b: &mut [u8], at: usize, v: f64) {
    b[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

/// Byte offset of point `i`'s record in an uncompressed LAS file.
fn record(b: &[u8], i: usize) -> usize {
    read_u32(b, OFFSET_TO_POINTS)
        + i * usize::from(u16::from_le_bytes([b[RECORD_LENGTH], b[RECORD_LENGTH + 1]]))
}

#[test]
fn las_point_outside_the_header_bounds() {
    let c = Case::new();
    let mut b = std::fs::read(c.p("good1.las")).unwrap();
    // Point 1234's Z record (bytes 8..12 of every point format) far above the header's max z.
    let z = record(&b, 1234) + 8;
    b[z..z + 4].copy_from_slice(&2_000_000_000i32.to_le_bytes());
    let f = c.p("spike.las");
    std::fs::write(&f, b).unwrap();
    c.fails(
        &f,
        &c.p("good2.las"),
        &[],
        &[
            "spike.las",
            "point 1234",
            "z = ",
            "above the header's maximum z",
        ],
    );
}

#[test]
fn laz_points_outside_the_header_bounds() {
    // Compressed points cannot be edited in place, so the header's bounds are narrowed instead:
    // the decoded points then lie outside them, as garbage decoded from a damaged chunk does.
    let c = Case::new();
    let full = c.p("full.laz");
    common::write_cloud(&full, &plane(3, 20_000, 0.0));
    let mut b = std::fs::read(&full).unwrap();
    put_f64(&mut b, MAX_Z, OFFSET[2]);
    let f = c.p("narrow.laz");
    std::fs::write(&f, b).unwrap();
    c.fails(
        &c.p("good1.las"),
        &f,
        &[],
        &[
            "narrow.laz",
            " has z = ",
            "above the header's maximum z 100.0 ",
        ],
    );
}

#[test]
fn absurd_las_scale_factors() {
    let c = Case::new();
    let good = std::fs::read(c.p("good1.las")).unwrap();
    for (i, scale) in [1e300, 0.0, f64::NAN, 5e-324, 1e-300, f64::INFINITY]
        .into_iter()
        .enumerate()
    {
        let mut b = good.clone();
        put_f64(&mut b, SCALE_X + 16, scale); // z
        let f = c.p(&format!("scale{i}.las"));
        std::fs::write(&f, b).unwrap();
        c.fails(
            &f,
            &c.p("good2.las"),
            &[],
            &[&format!("scale{i}.las"), "z scale factor"],
        );
    }
}

#[test]
fn negative_las_scale_factor_is_read() {
    // LAS 1.4 R15 only says coordinate = record × scale + offset: a negative scale with negated
    // records is the same cloud.
    let c = Case::new();
    let good = c.p("good1.las");
    let mut b = std::fs::read(&good).unwrap();
    let scale = f64::from_le_bytes(b[SCALE_X..SCALE_X + 8].try_into().unwrap());
    put_f64(&mut b, SCALE_X, -scale);
    for i in 0..2000 {
        let x = record(&b, i);
        let v = i32::from_le_bytes(b[x..x + 4].try_into().unwrap());
        b[x..x + 4].copy_from_slice(&(-v).to_le_bytes());
    }
    let f = c.p("mirrored.las");
    std::fs::write(&f, b).unwrap();
    let (_, want) = talus::io::read_all(&good).unwrap();
    let (info, got) = talus::io::read_all(&f).unwrap();
    assert_eq!(info.scale.unwrap()[0], scale);
    assert_eq!(got, want);
    let o = common::run(&["info", f.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `talus info --json FILE`'s report, which must succeed.
fn info_json(path: &Path) -> serde_json::Value {
    let o = common::run(&["info", "--json", path.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()[0].clone()
}

#[test]
fn every_point_twice_has_the_spacing_of_one_copy() {
    let c = Case::new();
    let once = plane(7, 2000, 0.0);
    let twice: Vec<Point3> = once.iter().flat_map(|p| [*p, *p]).collect();
    let f = c.p("twice.las");
    common::write_cloud(&f, &twice);
    let g = c.p("once.las");
    common::write_cloud(&g, &once);
    let (a, b) = (info_json(&f), info_json(&g));
    assert_eq!(a["points"], 4000);
    assert_eq!(
        a["spacing"]["effective_spacing"],
        b["spacing"]["effective_spacing"]
    );
    assert_eq!(a["spacing"]["spacing"], b["spacing"]["spacing"]);
    let o = common::run_compare(&f, &c.p("good2.las"), &c.out(), &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_cloud_at_one_position_is_refused() {
    let c = Case::new();
    let f = c.p("one_place.las");
    common::write_cloud(
        &f,
        &vec![[OFFSET[0] + 5.0, OFFSET[1] + 5.0, OFFSET[2]]; 500],
    );
    c.fails(
        &f,
        &c.p("good2.las"),
        &[],
        &["one_place.las", "all points coincide"],
    );
}

#[test]
fn a_byte_order_mark_is_skipped() {
    let c = Case::new();
    let pts = plane(8, 300, 0.0);
    let rows: String = pts
        .iter()
        .map(|p| format!("{:.4},{:.4},{:.4}\n", p[0], p[1], p[2]))
        .collect();
    let ply_rows: String = rows.replace(',', " ");
    let ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty double x\nproperty double y\n\
         property double z\nend_header\n{ply_rows}",
        pts.len()
    );
    for (name, body) in [
        ("header.csv", format!("X,Y,Z\n{rows}")),
        ("quoted.csv", format!("\"X\",\"Y\",\"Z\"\n{rows}")),
        ("plain.xyz", rows.clone()),
        ("cloud.ply", ply),
    ] {
        let plain = c.p(name);
        std::fs::write(&plain, &body).unwrap();
        let bom = c.p(&format!("bom_{name}"));
        std::fs::write(&bom, format!("\u{feff}{body}")).unwrap();
        let (want, got) = (info_json(&plain), info_json(&bom));
        assert_eq!(got["points"], 300, "{name}");
        assert_eq!(got["bounds"], want["bounds"], "{name}");
        assert_eq!(got["format_detail"], want["format_detail"], "{name}");
    }
}

#[test]
fn config_errors_name_the_file_and_key() {
    let c = Case::new();
    let (b, a) = (c.p("good1.las"), c.p("good2.las"));
    let cfg = c.p("cfg.toml");
    let cfg_arg = cfg.to_str().unwrap();
    for (text, needle) in [
        (
            "normal_radius = -1",
            "cfg.toml: normal_radius: must be a positive number, got -1",
        ),
        (
            "cyl_halflen = 1e300",
            "cfg.toml: cyl_halflen: 1e300 is beyond",
        ),
        (
            "reg_error = -0.5",
            "cfg.toml: reg_error: must be zero or positive",
        ),
        ("smooth_k = 0", "cfg.toml: smooth_k: must be at least 1"),
        ("threads = 100000", "cfg.toml: threads: 100000 is more than"),
        ("memory = \"lots\"", "cfg.toml: memory: cannot read 'lots'"),
        (
            "orientation = \"sideways\"",
            "cfg.toml: orientation: expected auto",
        ),
        (
            "eps = 1e6",
            "cfg.toml: eps: 1000000 is more than 10 times the data's extent",
        ),
        (
            "eps = 1\nbogus = 1",
            "cfg.toml: bad config: line 2: unknown field `bogus`",
        ),
    ] {
        std::fs::write(&cfg, text).unwrap();
        c.fails(&b, &a, &["--config", cfg_arg], &[needle]);
    }
    // A value given by flag names the flag, also when the config sets the same key.
    std::fs::write(&cfg, "normal_radius = 1\ncyl_radius = 2").unwrap();
    c.fails(
        &b,
        &a,
        &["--config", cfg_arg, "--normal-radius=-1"],
        &["--normal-radius: must be a positive number, got -1"],
    );
}

#[test]
fn absurd_lengths_are_refused_naming_the_flag() {
    // The cloud is 10 × 10; a cylinder of radius 1e6 used to run for hours (the volume grid over
    // a footprint grown by it), one of 1e300 to fail with an internal error.
    let c = Case::new();
    let (b, a) = (c.p("good1.las"), c.p("good2.las"));
    for (flag, value) in [
        ("--normal-radius", "1e300"),
        ("--cyl-radius", "1e300"),
        ("--cyl-radius", "1e6"),
        ("--cyl-halflen", "1e12"),
        ("--core-spacing", "1e300"),
        ("--smooth-sigma", "1e9"),
        ("--eps", "200"),
        ("--reg-error", "1e300"),
        ("--threshold", "1e300"),
    ] {
        c.fails(&b, &a, &[flag, value], &[&format!("{flag}: ")]);
    }
}

#[test]
fn absurd_thread_counts_are_refused() {
    let c = Case::new();
    let (b, a) = (c.p("good1.las"), c.p("good2.las"));
    c.fails(
        &b,
        &a,
        &["--threads", "100000"],
        &["--threads: 100000 is more than talus accepts (1024)"],
    );
    c.fails(
        &b,
        &a,
        &["--threads", "0"],
        &["--threads: must be at least 1"],
    );
}

#[test]
fn info_into_a_closed_pipe_does_not_panic() {
    // `talus info FILE | head -1`: the reader is gone before talus writes.
    let c = Case::new();
    let mut child = common::talus()
        .args(["info", "--json", c.p("good1.las").to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(o.status.code(), Some(0), "{err}");
}

#[test]
fn absurd_las_point_counts_and_bounds() {
    let c = Case::new();
    let good = std::fs::read(c.p("good1.las")).unwrap();
    // The LAS 1.4 point count (u64 at 247): its size arithmetic overflowed (a panic).
    let mut b = good.clone();
    b[247..255].copy_from_slice(&u64::MAX.to_le_bytes());
    let f = c.p("count.las");
    std::fs::write(&f, b).unwrap();
    c.fails(
        &f,
        &c.p("good2.las"),
        &[],
        &["count.las", "more than any file holds"],
    );
    // Max x (at 179) far beyond what 32-bit records at this scale and offset can reach: the
    // points all lie within it, but tiling a grid over it would not end.
    let mut b = good.clone();
    put_f64(&mut b, 179, 1e300);
    let f = c.p("wide.las");
    std::fs::write(&f, b).unwrap();
    c.fails(
        &f,
        &c.p("good2.las"),
        &[],
        &["wide.las", "bounds of x", "1e300", "can express"],
    );
}
