//! A result folder that cannot reach outside itself (issue 44, item 1): result folders are
//! shared on clusters and sent between people, so every path talus reads from DIR — the publish
//! journal, the units' records, the plan, the claims, the Slurm records, `.talus/` itself with
//! links planted in it — is held to DIR. Each case: a finished compare in DIR, one thing in it
//! made hostile, the commands that read it run; nothing outside DIR changes, no file of the
//! user's is touched, and the refusal (exit 2) names the file and the problem.

mod common;

use std::collections::BTreeMap;
use std::os::unix::fs::symlink;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::{Rng, OFFSET};
use talus::io::Point3;

fn plane(seed: u64, n: usize, dz: f64) -> Vec<Point3> {
    let mut r = Rng::new(seed);
    (0..n)
        .map(|_| {
            [
                OFFSET[0] + r.uniform() * 10.0,
                OFFSET[1] + r.uniform() * 10.0,
                OFFSET[2] + dz + 0.002 * r.normal(),
            ]
        })
        .collect()
}

/// A finished compare in `D` beside a folder `outside` (a survey and a file of the user's).
struct Case {
    _tmp: tempfile::TempDir,
    root: PathBuf,
}

impl Case {
    fn new() -> Case {
        let tmp = common::tempdir();
        let root = tmp.path().to_path_buf();
        let outside = root.join("outside");
        std::fs::create_dir(&outside).unwrap();
        common::write_cloud(&outside.join("before.las"), &plane(1, 2000, 0.0));
        common::write_cloud(&outside.join("after.las"), &plane(2, 2000, 0.0));
        std::fs::write(outside.join("notes.txt"), "the user's notes").unwrap();
        let c = Case { _tmp: tmp, root };
        let o = c.compare(&[]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        c
    }
    fn d(&self) -> PathBuf {
        self.root.join("D")
    }
    fn outside(&self) -> PathBuf {
        self.root.join("outside")
    }
    fn compare(&self, extra: &[&str]) -> std::process::Output {
        common::run_compare(
            &self.outside().join("before.las"),
            &self.outside().join("after.las"),
            &self.d(),
            // The units' files stay after a run, for the cases to plant links among them.
            &[extra, &["--keep-units"]].concat(),
        )
    }
    fn status(&self) -> std::process::Output {
        common::run(&["status", self.d().to_str().unwrap()])
    }
    /// Everything below the tempdir but `D/.talus`: names, kinds and contents.
    fn snapshot(&self) -> BTreeMap<String, String> {
        fn walk(dir: &Path, rel: &str, out: &mut BTreeMap<String, String>) {
            for e in std::fs::read_dir(dir).unwrap().flatten() {
                let name = format!("{rel}/{}", e.file_name().to_string_lossy());
                if name == "/D/.talus" {
                    continue;
                }
                let m = std::fs::symlink_metadata(e.path()).unwrap();
                if m.file_type().is_symlink() {
                    out.insert(
                        name,
                        format!("-> {:?}", std::fs::read_link(e.path()).unwrap()),
                    );
                } else if m.is_dir() {
                    out.insert(name.clone(), "dir".into());
                    walk(&e.path(), &name, out);
                } else {
                    let h = crc32fast::hash(&std::fs::read(e.path()).unwrap());
                    out.insert(name, format!("{} bytes crc {h:08x}", m.len()));
                }
            }
        }
        let mut out = BTreeMap::new();
        walk(&self.root, "", &mut out);
        out
    }
    /// Everything that was outside DIR in `before` is still there, as it was.
    fn outside_as(&self, before: &BTreeMap<String, String>) {
        let after = self.snapshot();
        for (name, v) in before {
            if name.starts_with("/outside") {
                assert_eq!(after.get(name), Some(v), "{name}");
            }
        }
    }
    fn unit_dir(&self, kind: &str) -> PathBuf {
        std::fs::read_dir(self.d().join(".talus/units").join(kind))
            .unwrap()
            .flatten()
            .next()
            .unwrap()
            .path()
    }
}

/// Exit 2, one line, naming `needles`, no panic.
fn refused(o: &std::process::Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "'{n}' not in: {err}");
    }
}

/// The issue's reproduction: a crafted `.talus/publishing` that hard-links a file from outside
/// into DIR, creates one outside through `../` and removes one outside by absolute path. `talus
/// status` and `talus view` refuse it, naming the journal; nothing changes anywhere.
#[test]
fn a_crafted_publish_journal_is_refused_by_status_and_view() {
    let c = Case::new();
    let d = c.d();
    let journal = serde_json::json!({
        "files": [
            [c.outside().join("notes.txt"), "stolen.txt"],
            [d.join(".talus/plan.json"), "../outside/escape.txt"],
        ],
        "marker": "summary.json",
        "remove": [c.outside().join("before.las")],
        "dirs": [],
    });
    let path = d.join(".talus/publishing");
    std::fs::write(&path, serde_json::to_vec(&journal).unwrap()).unwrap();
    let before = c.snapshot();
    refused(&c.status(), &[path.to_str().unwrap(), "did not write"]);
    assert_eq!(c.snapshot(), before);
    // `talus view` refuses before serving anything.
    let mut child = common::talus()
        .args(["view", d.to_str().unwrap(), "--port", "0"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    let code = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s.code();
        }
        if t.elapsed() > Duration::from_secs(20) {
            let _ = child.kill();
            panic!("talus view served a DIR with a crafted journal");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(code, Some(2));
    assert_eq!(c.snapshot(), before);
    // And a run on DIR too.
    refused(&c.compare(&["--resume"]), &["did not write"]);
    assert_eq!(c.snapshot(), before);
}

/// A journal that names a file of the user's inside DIR for removal (not a talus output) is
/// refused as well: DIR's own files are the user's too.
#[test]
fn a_journal_removing_a_users_file_in_dir_is_refused() {
    let c = Case::new();
    let d = c.d();
    std::fs::write(d.join("my-notes.txt"), "mine").unwrap();
    let unit = c.unit_dir("outputs");
    let journal = serde_json::json!({
        "files": [[unit.join("summary.json"), "summary.json"]],
        "marker": "summary.json",
        "remove": ["my-notes.txt"],
        "dirs": [],
    });
    std::fs::write(
        d.join(".talus/publishing"),
        serde_json::to_vec(&journal).unwrap(),
    )
    .unwrap();
    refused(&c.status(), &["my-notes.txt", "not a talus output"]);
    assert_eq!(
        std::fs::read_to_string(d.join("my-notes.txt")).unwrap(),
        "mine"
    );
}

/// An output folder of DIR replaced by a link to elsewhere: a journal publishing into it is
/// refused before anything moves.
#[test]
fn a_journal_through_a_folder_linked_elsewhere_is_refused() {
    let c = Case::new();
    let d = c.d();
    std::fs::remove_dir_all(d.join("meshes")).ok();
    symlink(c.outside(), d.join("meshes")).unwrap();
    let unit = c.unit_dir("outputs");
    let journal = serde_json::json!({
        "files": [
            [unit.join("summary.json"), "meshes/event_0001_before.ply"],
            [unit.join("summary.json"), "summary.json"],
        ],
        "marker": "summary.json",
        "remove": ["meshes/event_0002_after.ply"],
        "dirs": [],
    });
    std::fs::write(
        d.join(".talus/publishing"),
        serde_json::to_vec(&journal).unwrap(),
    )
    .unwrap();
    let before = c.snapshot();
    refused(&c.status(), &["symbolic link"]);
    assert_eq!(c.snapshot(), before);
}

/// The outputs unit's record lists what to publish: a record naming a source outside its unit
/// or an output outside DIR is damaged — status does not read it, a run computes the unit
/// again and publishes only inside DIR.
#[test]
fn a_record_publishing_outside_dir_is_damage() {
    let c = Case::new();
    let unit = c.unit_dir("outputs");
    let rec_path = unit.join("record.json");
    let mut rec: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&rec_path).unwrap()).unwrap();
    let list = rec["meta"]["publish"].as_array_mut().unwrap();
    list[0]["name"] = "../outside/escape.txt".into();
    list[1]["file"] = "../../../../outside/notes.txt".into();
    std::fs::write(&rec_path, serde_json::to_vec(&rec).unwrap()).unwrap();
    let outside = c.outside();
    let o = c.status();
    assert!(
        o.status.code().is_some(),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!String::from_utf8_lossy(&o.stdout).contains("published (this plan's)"));
    let o = c.compare(&["--resume"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!outside.join("escape.txt").exists());
    assert_eq!(
        std::fs::read_to_string(outside.join("notes.txt")).unwrap(),
        "the user's notes"
    );
    common::assert_published(&c.d());
}

/// A plan read back from DIR whose units or run id are paths, or whose dependencies point
/// nowhere: refused as damaged, naming plan.json, not a panic and not a read elsewhere.
#[test]
fn a_crafted_plan_is_refused_naming_it() {
    let c = Case::new();
    let path = c.d().join(".talus/plan.json");
    let good: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let edits = [
        ("/run", serde_json::json!("../../../outside")),
        ("/run", serde_json::json!("ééééééééééééééééé")),
        ("/units/0/name", serde_json::json!("../../../../outside")),
        ("/units/0/spec/kind", serde_json::json!("/etc")),
        ("/units/0/deps", serde_json::json!([100000])),
        ("/units/0/spec/survey", serde_json::json!(7)),
        ("/pairs/0/after", serde_json::json!(9)),
    ];
    let before = c.snapshot();
    for (at, value) in edits {
        let mut p = good.clone();
        *p.pointer_mut(at).unwrap() = value;
        std::fs::write(&path, serde_json::to_vec(&p).unwrap()).unwrap();
        refused(&c.status(), &["plan.json", "damaged plan"]);
        assert_eq!(c.snapshot(), before);
    }
    // The plan as a link to a plan elsewhere, or a FIFO: not followed, not waited on.
    let elsewhere = c.outside().join("plan.json");
    std::fs::write(&elsewhere, serde_json::to_vec(&good).unwrap()).unwrap();
    std::fs::remove_file(&path).unwrap();
    symlink(&elsewhere, &path).unwrap();
    refused(&c.status(), &["symbolic link"]);
    std::fs::remove_file(&path).unwrap();
    let made = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(made.as_ptr(), 0o600) }, 0);
    refused(&c.status(), &["plan.json", "FIFO"]);
}

/// Links planted in `.talus/`: `tmp/` (which a run's clean-up empties) as a link to a folder of
/// the user's, `units/<kind>` as one, a unit's file or record as a link to a file elsewhere.
/// Runs and status refuse the first; a linked unit is never done (the run computes it again)
/// and nothing outside is read into DIR or removed.
#[test]
fn links_planted_in_the_work_area_reach_nothing_outside() {
    let c = Case::new();
    let d = c.d();
    let outside = c.outside();
    // Old enough for gc to remove, were it walked.
    std::fs::create_dir(outside.join("old")).unwrap();
    std::fs::write(outside.join("old/data.bin"), "precious").unwrap();
    let old = std::time::SystemTime::now() - Duration::from_secs(3 * 3600);
    std::fs::File::open(outside.join("old/data.bin"))
        .unwrap()
        .set_modified(old)
        .unwrap();
    let tmp = d.join(".talus/tmp");
    std::fs::remove_dir_all(&tmp).unwrap();
    symlink(&outside, &tmp).unwrap();
    let before = c.snapshot();
    for o in [
        c.compare(&["--resume"]),
        c.compare(&["--force"]),
        c.status(),
    ] {
        refused(&o, &[".talus/tmp", "symbolic link"]);
    }
    assert_eq!(c.snapshot(), before);
    std::fs::remove_file(&tmp).unwrap();
    std::fs::create_dir(&tmp).unwrap();

    // A tile replaced by a link to the user's file of the same size: not done, recomputed.
    let tiling = c.unit_dir("tiling");
    let tile = std::fs::read_dir(&tiling)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "tile"))
        .unwrap();
    let bytes = std::fs::read(&tile).unwrap();
    std::fs::write(outside.join("same-size.bin"), vec![7u8; bytes.len()]).unwrap();
    std::fs::remove_file(&tile).unwrap();
    symlink(outside.join("same-size.bin"), &tile).unwrap();
    // The outputs unit's record as a link to a copy elsewhere.
    let out_unit = c.unit_dir("outputs");
    let rec = out_unit.join("record.json");
    std::fs::copy(&rec, outside.join("record.json")).unwrap();
    std::fs::remove_file(&rec).unwrap();
    symlink(outside.join("record.json"), &rec).unwrap();
    let before = c.snapshot();
    let o = c.compare(&["--resume"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    c.outside_as(&before);
    assert_eq!(
        std::fs::read(outside.join("same-size.bin")).unwrap(),
        vec![7u8; bytes.len()]
    );
    common::assert_published(&c.d());
}

/// Claims and Slurm records: a `claims/<run>` linked elsewhere is never written through; a
/// Slurm submission whose stage names a path is not read through it.
#[test]
fn claims_and_slurm_records_stay_inside_dir() {
    let c = Case::new();
    let d = c.d();
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join(".talus/plan.json")).unwrap()).unwrap();
    let run = plan["run"].as_str().unwrap();
    let claims = d.join(".talus/claims").join(run);
    let _ = std::fs::remove_dir_all(&claims);
    symlink(c.outside(), &claims).unwrap();
    let before = c.snapshot();
    // Status reads claims of units not done: make one not done.
    let m3c2 = c.unit_dir("m3c2");
    std::fs::remove_dir_all(&m3c2).unwrap();
    std::fs::create_dir_all(c.outside().join("m3c2")).unwrap();
    std::fs::write(
        c.outside().join("m3c2").join(m3c2.file_name().unwrap()),
        serde_json::json!({"pid": 1, "host": "x", "started": 0, "token": "t", "label": "evil"})
            .to_string(),
    )
    .unwrap();
    let o = c.status();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("0 running"),
        "a claim read through a link: {}",
        String::from_utf8_lossy(&o.stdout)
    );
    refused(&c.compare(&["--resume"]), &["symbolic link", "claims"]);
    c.outside_as(&before);
    std::fs::remove_file(d.join(".talus/claims").join(run)).unwrap();

    // A Slurm submission whose stage is a path: its task report is not read through it.
    let sub = d.join(".talus/slurm/1");
    std::fs::create_dir_all(sub.join("tasks")).unwrap();
    std::fs::create_dir_all(sub.join("logs")).unwrap();
    std::fs::write(
        c.outside().join("x-0.json"),
        serde_json::json!({"state": "failed", "task_id": "1_0", "job_id": "1", "host": "h",
            "pid": 1, "started": 0, "ended": 0, "computed": 0, "error": "READ FROM OUTSIDE"})
        .to_string(),
    )
    .unwrap();
    let submission = serde_json::json!({
        "number": 1, "run": run, "command": "talus", "created": 0, "talus": "/bin/true",
        "dir": d, "sbatch_args": [], "mem_mib": 1, "cpus": null,
        "stages": [{"kind": "../../../../outside/x", "script": "s.sh", "tasks": [[]]}],
    });
    std::fs::write(sub.join("submission.json"), submission.to_string()).unwrap();
    std::fs::write(sub.join("jobs.json"), r#"{"ids":["1"]}"#).unwrap();
    let o = c.status();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(!text.contains("READ FROM OUTSIDE"), "{text}");
}
