//! Bad input: one clear line naming the file and the problem, exit code 2, nothing left behind.

#[path = "../common/mod.rs"]
mod common;

use std::path::{Path, PathBuf};

use common::{Rng, OFFSET};
use talus::io::Point3;

mod dir_and_files;

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

/// [`plane`] raised by `dz`.
fn raised(seed: u64, n: usize, dz: f64) -> Vec<Point3> {
    plane(seed, n, 0.0)
        .into_iter()
        .map(|p| [p[0], p[1], p[2] + dz])
        .collect()
}

struct Case {
    dir: tempfile::TempDir,
}

/// A stage's line when its units finished (`talus: pass 2: normals and M3C2: ... peak ...`).
fn finished_stage(l: &str) -> bool {
    ["talus: pass ", "talus: alignment", "talus: orientation"]
        .iter()
        .any(|s| l.starts_with(s))
        && l.contains(" peak ")
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
        // One line, but for the lines of stages that finished while another unit met the bad
        // input (a survey's orientation field, done before the other survey's tiling failed).
        let lines: Vec<&str> = err.trim().lines().filter(|l| !finished_stage(l)).collect();
        assert_eq!(lines.len(), 1, "not one line: {err}");
        for n in needles {
            assert!(err.contains(n), "'{n}' not in: {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{} was left behind", out.display());
    }
    /// [`Case::fails`] on the two good epochs.
    fn fails_on_good(&self, extra: &[&str], needles: &[&str]) {
        self.fails(&self.p("good1.las"), &self.p("good2.las"), extra, needles);
    }
    /// As [`Case::fails`] for a failure found once M3C2 ran: the stages finished before it print
    /// their lines, then the error is one line, the last.
    fn fails_after_m3c2(&self, before: &Path, after: &Path, extra: &[&str], needles: &[&str]) {
        let out = self.out();
        let o = common::run_compare(before, after, &out, extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "stderr: {err}");
        let lines: Vec<&str> = err.trim().lines().collect();
        let (last, stages) = lines.split_last().unwrap();
        assert!(last.starts_with("talus: error: "), "{err}");
        for l in stages {
            assert!(finished_stage(l), "{err}");
        }
        for n in needles {
            assert!(last.contains(n), "'{n}' not in: {err}");
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
fn epochs_far_apart_in_z() {
    // Their footprints overlap, but 100 km of height lie between them: no cylinder reaches both.
    let c = Case::new();
    let high: Vec<Point3> = raised(6, 2000, 100_000.0);
    let f = c.p("high.las");
    common::write_cloud(&f, &high);
    c.fails(
        &c.p("good1.las"),
        &f,
        &[],
        &[
            "good1.las and ",
            "high.las: the epochs do not overlap: before z 99.9",
            "; after z 100099.9",
            "apart, and M3C2's cylinder reaches",
        ],
    );
}

#[test]
fn an_epoch_mirrored_by_a_negative_scale_does_not_overlap() {
    // z = record × scale + offset with the z scale negated (and the header's z bounds with it):
    // a valid file whose cloud lies at z ≈ -100, 200 m below the other epoch.
    let c = Case::new();
    let mut b = std::fs::read(c.p("good2.las")).unwrap();
    let at = |b: &[u8], i: usize| f64::from_le_bytes(b[i..i + 8].try_into().unwrap());
    let (scale, max_z, min_z) = (at(&b, SCALE_X + 16), at(&b, MAX_Z), at(&b, MAX_Z + 8));
    assert_eq!(at(&b, SCALE_X + 40), 0.0, "the fixture's z offset");
    put_f64(&mut b, SCALE_X + 16, -scale);
    put_f64(&mut b, MAX_Z, -min_z);
    put_f64(&mut b, MAX_Z + 8, -max_z);
    let f = c.p("mirrored.las");
    std::fs::write(&f, b).unwrap();
    c.fails(
        &c.p("good1.las"),
        &f,
        &[],
        &[
            "mirrored.las: the epochs do not overlap",
            "; after z -100.0",
        ],
    );
}

#[test]
fn core_points_outside_the_data() {
    let c = Case::new();
    let (b, a) = (c.p("good1.las"), c.p("good2.las"));
    let cores = c.p("cores.csv");
    let x = OFFSET[0] + 5.0;
    let y = OFFSET[1] + 5.0;
    // Beside the data and above it: no core point near either epoch.
    for (dx, z) in [(0.0, 5000.0), (1000.0, 100.0)] {
        std::fs::write(
            &cores,
            format!(
                "X,Y,Z\n{},{y},{z}\n{},{},{z}\n",
                x + dx,
                x + dx + 1.0,
                y + 1.0
            ),
        )
        .unwrap();
        c.fails(
            &b,
            &a,
            &["--core-points", cores.to_str().unwrap()],
            &[
                "the core points ",
                "cores.csv (x 50",
                "lie outside both epochs' bounds",
            ],
        );
    }
    // Within the after epoch's reach only (it lies 1 m above the before one): no normals.
    let up: Vec<Point3> = raised(9, 2000, 1.0);
    let high = c.p("up.las");
    common::write_cloud(&high, &up);
    std::fs::write(&cores, format!("X,Y,Z\n{x},{y},101.5\n")).unwrap();
    c.fails(
        &b,
        &high,
        &[
            "--core-points",
            cores.to_str().unwrap(),
            "--normal-radius",
            "0.5",
        ],
        &[
            "cores.csv (z 101.500..101.500) lie outside the before epoch's bounds (z 99.9",
            "beyond the normal radius 0.500",
        ],
    );
}

#[test]
fn a_run_without_any_distance_is_refused_with_the_reason() {
    let c = Case::new();
    let (b, a) = (c.p("good1.las"), c.p("good2.las"));
    // 2000 points over 10 × 10: 0.2 apart, none within a millimetre of a core point.
    c.fails_after_m3c2(
        &b,
        &a,
        &["--normal-radius", "0.001"],
        &[
            "no distance at any of the ",
            "no core point has the 3 neighbours a normal needs within the normal radius 0.001 (--normal-radius)",
        ],
    );
    c.fails_after_m3c2(
        &b,
        &a,
        &["--min-points", "100000"],
        &["no core point has enough points of the before epoch in M3C2's cylinder"],
    );
    // The after epoch a metre above, beyond a 10 cm cylinder: normals, but nothing to meet.
    let up: Vec<Point3> = raised(9, 2000, 0.5);
    let high = c.p("up.las");
    common::write_cloud(&high, &up);
    c.fails_after_m3c2(
        &b,
        &high,
        &["--cyl-halflen", "0.3", "--cyl-radius", "0.5"],
        &[
            "the other epoch lies along the normal beyond the cylinder's half-length 0.3 (--cyl-halflen)",
            "the epochs do not overlap within it",
        ],
    );
}

#[test]
fn a_campaign_survey_far_from_the_others_is_refused_naming_the_pair() {
    let c = Case::new();
    let mut args = vec!["campaign".to_string()];
    for (k, dz) in [0.0, 0.0, 100_000.0].into_iter().enumerate() {
        let f = c.p(&format!("survey_2020010{}.las", k + 1));
        let pts: Vec<Point3> = raised(20 + k as u64, 2000, dz);
        common::write_cloud(&f, &pts);
        args.push(f.to_str().unwrap().into());
    }
    let out = c.out();
    args.extend(["--out".into(), out.to_str().unwrap().into()]);
    let o = common::talus().args(&args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("pair 20200102_20200103 (") && err.contains("the epochs do not overlap"),
        "{err}"
    );
    assert!(!out.exists(), "{} was left behind", out.display());
}

#[test]
fn a_config_with_a_byte_order_mark_is_read() {
    let c = Case::new();
    let cfg = c.p("bom.toml");
    std::fs::write(&cfg, "\u{feff}normal_radius = -1\n").unwrap();
    // The key after the mark is read (and its value judged), not taken for a bad name.
    c.fails_on_good(
        &["--config", cfg.to_str().unwrap()],
        &["bom.toml: normal_radius: must be a positive number, got -1"],
    );
}

#[test]
fn one_mesh_without_the_other_is_refused() {
    let c = Case::new();
    let mesh = c.p("before.ply");
    std::fs::write(&mesh, "ply\nformat ascii 1.0\nend_header\n").unwrap();
    for flag in ["--before-mesh", "--after-mesh"] {
        c.fails_on_good(
            &[flag, mesh.to_str().unwrap()],
            &["before.ply: --before-mesh and --after-mesh go together"],
        );
    }
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
fn a_laz_record_length_that_is_not_its_items_is_refused_at_once() {
    // The las crate sized its buffers by the header's record length (65535 × the points: 11 GB
    // resident for a 100 KB file, 40 s) and the decompressor filled them by the LASzip items.
    let c = Case::new();
    let full = c.p("full.laz");
    common::write_cloud(&full, &plane(3, 20_000, 0.0));
    let mut b = std::fs::read(&full).unwrap();
    b[RECORD_LENGTH..RECORD_LENGTH + 2].copy_from_slice(&u16::MAX.to_le_bytes());
    let f = c.p("long_records.laz");
    std::fs::write(&f, b).unwrap();
    let t = std::time::Instant::now();
    c.fails(
        &f,
        &c.p("good2.las"),
        &[],
        &["long_records.laz: corrupt LAZ header: its point record length is 65535 bytes"],
    );
    assert!(
        t.elapsed() < std::time::Duration::from_secs(5),
        "{:?}",
        t.elapsed()
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

// ---------------------------------------------------------------- issue "Trust, second round"

/// Item 3: a LAS 1.4 file whose legacy point count disagrees with its 64-bit count, and a PLY
/// whose header count disagrees with its rows, are refused naming the disagreement, as BEFORE
/// and as AFTER (read by either count, they gave a result from 5 or 10 points).
#[test]
fn a_file_that_disagrees_with_itself_is_refused() {
    let c = Case::new();
    let mut las = std::fs::read(c.p("good1.las")).unwrap();
    assert_eq!(&las[24..26], &[1, 4], "LAS 1.4");
    let big = u64::from_le_bytes(las[247..255].try_into().unwrap());
    assert_eq!(big, 2000);
    las[107..111].copy_from_slice(&5u32.to_le_bytes());
    let f = c.p("counts.las");
    std::fs::write(&f, &las).unwrap();
    let needles = [
        "counts.las",
        "legacy point count is 5 but its 64-bit point count is 2000",
    ];
    c.fails(&c.p("good2.las"), &f, &[], &needles);
    c.fails(&f, &c.p("good2.las"), &[], &needles);

    let pts = plane(5, 829, 0.0);
    let rows: String = pts
        .iter()
        .map(|p| format!("{:.4} {:.4} {:.4}\n", p[0], p[1], p[2]))
        .collect();
    let ply = c.p("rows.ply");
    std::fs::write(
        &ply,
        format!(
            "ply\nformat ascii 1.0\nelement vertex 10\nproperty double x\nproperty double y\n\
             property double z\nend_header\n{rows}"
        ),
    )
    .unwrap();
    let needles = [
        "rows.ply",
        "declares 10 vertices but 819 more row(s) follow",
    ];
    c.fails(&c.p("good2.las"), &ply, &[], &needles);
    c.fails(&ply, &c.p("good2.las"), &[], &needles);
}

/// Item 4: one, two or three points, or 829 identical ones, are refused as AFTER as they are as
/// BEFORE, with the reason.
#[test]
fn degenerate_surveys_are_refused_either_way() {
    let c = Case::new();
    let p = plane(6, 3, 0.0);
    for n in 1..=3 {
        let f = c.p(&format!("few{n}.las"));
        common::write_cloud(&f, &p[..n]);
        let needles = [format!("few{n}.las"), format!("holds {n} point(s)")];
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        c.fails(&c.p("good1.las"), &f, &[], &needles);
        c.fails(&f, &c.p("good1.las"), &[], &needles);
    }
    // A text file: its bounds come from its points (write_cloud's LAS header keeps the
    // writer's own bounds).
    let f = c.p("same.csv");
    common::write_text(&f, "x,y,z\n", &vec![p[0]; 829]);
    c.fails(
        &c.p("good1.las"),
        &f,
        &[],
        &["same.csv", "all points coincide"],
    );
    c.fails(
        &f,
        &c.p("good1.las"),
        &[],
        &["same.csv", "all points coincide"],
    );
}

/// Item 7: a value a config file gives is blamed on the file and its key, even one JSON cannot
/// hold (nan), never on a flag the user did not pass.
#[test]
fn a_non_finite_config_value_is_blamed_on_the_file_and_key() {
    let c = Case::new();
    let cfg = c.p("talus.toml");
    std::fs::write(&cfg, "normal_radius = nan\n").unwrap();
    c.fails_on_good(
        &["--config", cfg.to_str().unwrap()],
        &[
            "talus.toml",
            "normal_radius: must be a positive number, got NaN",
        ],
    );
    let o = common::run_compare(
        &c.p("good1.las"),
        &c.p("good2.las"),
        &c.out(),
        &["--config", cfg.to_str().unwrap()],
    );
    assert!(!String::from_utf8_lossy(&o.stderr).contains("--normal-radius"));
}

/// Item 7: `talus status` of a folder that does not exist says so; `talus worker --slots 0` is
/// refused.
#[test]
fn status_of_nothing_and_a_worker_without_slots_are_refused_clearly() {
    let c = Case::new();
    let none = c.p("nothing-here");
    let o = common::run(&["status", none.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("nothing-here") && err.contains("no such directory"),
        "{err}"
    );
    assert!(!err.contains("cannot write"), "{err}");
    std::fs::create_dir(&none).unwrap();
    let o = common::run(&["status", none.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("no talus run here"), "{err}");
    assert!(!none.join(".talus").exists(), "status wrote nothing");
    let o = common::run(&["worker", none.to_str().unwrap(), "--slots", "0"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("--slots: must be at least 1"), "{err}");
}

/// Issue 44, item 6: nonsense accepted in silence is refused, naming the flag: `--min-points 0`
/// (acted as 1), `--core-spacing 1e-6` (every point a core point, and the derived DBSCAN
/// radius joins none: no event could form), `--tiles-per-task` with a local run (0 and all,
/// ignored), `synth --classified` on a scene without plants (did nothing).
#[test]
fn nonsense_parameters_are_refused() {
    let c = Case::new();
    c.fails_on_good(
        &["--min-points", "0"],
        &["--min-points: must be at least 1"],
    );
    c.fails_on_good(
        &["--core-spacing", "1e-6"],
        &[
            "--core-spacing",
            "every point would be a core point",
            "no event could form",
        ],
    );
    c.fails_on_good(
        &["--tiles-per-task", "0"],
        &["--tiles-per-task: must be at least 1"],
    );
    c.fails_on_good(
        &["--tiles-per-task", "2"],
        &["--tiles-per-task goes with --executor slurm"],
    );
    // A fine core spacing with --eps given is the user's choice.
    let o = common::run_compare(
        &c.p("good1.las"),
        &c.p("good2.las"),
        &c.out(),
        &["--core-spacing", "0.05", "--eps", "0.6"],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let scene = c.p("scene");
    for (args, needle) in [
        (
            vec!["synth", "cliff", "--classified"],
            "synth cliff: --classified is for",
        ),
        (
            vec!["synth", "campaign", "--classified"],
            "--classified for the vegetation scene",
        ),
    ] {
        let mut args = args;
        args.extend(["--out", scene.to_str().unwrap()]);
        let o = common::run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains(needle), "{err}");
        assert!(!scene.exists(), "{args:?} wrote {}", scene.display());
    }
}
