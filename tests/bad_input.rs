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
