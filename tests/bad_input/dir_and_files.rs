//! DIR and what lies in it: `--force` and `--resume` never replace the user's files, damaged and
//! half-published outputs, `talus status`; inputs that are not regular files or are degenerate.

use super::*;

/// Item 1: `--force` and `--resume` on a folder talus never ran in, holding files with the names
/// of talus outputs (the user's own), are refused and every file stays; an input where talus
/// would publish an output is refused even in a folder talus ran in.
#[test]
fn force_and_resume_never_replace_files_talus_did_not_write() {
    let c = Case::new();
    let out = c.out();
    std::fs::create_dir_all(out.join("meshes")).unwrap();
    let mine = [
        "events.csv",
        "summary.json",
        "view.json",
        "terrain.bin",
        "events.geojson",
        "event_regions.geojson",
        "meshes/event_0001_before.ply",
    ];
    for name in mine {
        std::fs::write(out.join(name), format!("the user's {name}")).unwrap();
    }
    for flag in ["--force", "--resume"] {
        let o = common::run_compare(&c.p("good1.las"), &c.p("good2.las"), &out, &[flag]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag}: {err}");
        assert!(err.contains("not talus's to replace"), "{err}");
        for name in mine {
            assert_eq!(
                std::fs::read_to_string(out.join(name)).unwrap(),
                format!("the user's {name}"),
                "{flag}: {name}"
            );
        }
        assert!(!out.join(".talus").exists(), "{flag}: nothing written");
    }
    // The input survey copied to DIR/m3c2.laz.
    let dir = c.p("run");
    let o = common::run_compare(&c.p("good1.las"), &c.p("good2.las"), &dir, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::copy(c.p("good1.las"), dir.join("m3c2.laz")).unwrap();
    let input = std::fs::read(dir.join("m3c2.laz")).unwrap();
    for flag in ["--force", "--resume"] {
        let o = common::run_compare(&dir.join("m3c2.laz"), &c.p("good2.las"), &dir, &[flag]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag}: {err}");
        assert!(
            err.contains("lies where talus writes its output m3c2.laz"),
            "{err}"
        );
        assert_eq!(
            std::fs::read(dir.join("m3c2.laz")).unwrap(),
            input,
            "{flag}"
        );
    }
}

/// Item 2: a published file damaged in DIR is named by `talus status`, and `--resume` publishes
/// it again from the store (which the damage did not reach: published files are copies).
#[test]
fn a_damaged_published_file_is_named_and_published_again() {
    let c = Case::new();
    let dir = c.out();
    let o = common::run_compare(&c.p("good1.las"), &c.p("good2.las"), &dir, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let good = std::fs::read(dir.join("m3c2.laz")).unwrap();
    let mut bad = good.clone();
    let k = bad.len() / 2;
    bad[k] ^= 0xff;
    std::fs::write(dir.join("m3c2.laz"), &bad).unwrap();
    let o = common::run(&["status", dir.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("differ from the run's result") && text.contains("m3c2.laz"),
        "{text}"
    );
    let o = common::run_compare(&c.p("good1.las"), &c.p("good2.las"), &dir, &["--resume"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read(dir.join("m3c2.laz")).unwrap(), good);
    common::assert_published(&dir);
}

/// Items 5 and 6: a publish cut short (here: the journal a SIGKILL inside publish leaves, with
/// the marker and a file already gone) is finished by the next command on DIR — `talus status`
/// too, not only `--resume` — so DIR (and a campaign's pairs/<pair>/, part of the same set) is
/// whole again.
#[test]
fn status_finishes_a_publish_cut_short() {
    let c = Case::new();
    let dir = c.out();
    let o = common::run_compare(&c.p("good1.las"), &c.p("good2.las"), &dir, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // As journals were written before their sources were made relative: still finished.
    let journal = common::publish_journal(&dir, true);
    let whole: Vec<(String, Vec<u8>)> = journal["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f[1].as_str().unwrap().to_string())
        .map(|n| (n.clone(), std::fs::read(dir.join(&n)).unwrap()))
        .collect();
    std::fs::write(
        dir.join(".talus/publishing"),
        serde_json::to_vec(&journal).unwrap(),
    )
    .unwrap();
    std::fs::remove_file(dir.join("summary.json")).unwrap();
    std::fs::remove_file(dir.join("events.csv")).unwrap();
    let o = common::run(&["status", dir.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        !dir.join(".talus/publishing").exists(),
        "the journal is done"
    );
    for (name, bytes) in &whole {
        assert_eq!(&std::fs::read(dir.join(name)).unwrap(), bytes, "{name}");
    }
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("published (this plan's)"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
}

/// Run talus with `args` through `sh -c` (for `<(…)`); killed and failed after 30 s.
fn run_shell_with_deadline(script: &str) -> std::process::Output {
    let mut child = std::process::Command::new("bash")
        .args(["-c", script])
        .env("TALUS", env!("CARGO_BIN_EXE_talus"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let t = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed() > std::time::Duration::from_secs(30) {
            let _ = child.kill();
            panic!("{script}: still running after 30 s (waiting on a FIFO?)");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// Issue 44, item 3: an input that is not a regular file — a FIFO with no writer (which hung
/// `info` and `compare`), a process substitution of a valid LAS (which gave "signature is not
/// 'LASF': [0, 0, 0, 0]"), a FIFO as the config or a mesh — is refused at once, naming it.
#[test]
fn inputs_that_are_not_regular_files_are_refused_at_once() {
    let c = Case::new();
    let fifo = c.p("fifo.las");
    let made = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(made.as_ptr(), 0o600) }, 0);
    let (good1, good2, out) = (c.p("good1.las"), c.p("good2.las"), c.out());
    let (f, g1, g2, o) = (
        fifo.display(),
        good1.display(),
        good2.display(),
        out.display(),
    );
    for (script, names) in [
        (format!("\"$TALUS\" info {f}"), f.to_string()),
        (
            format!("\"$TALUS\" compare {f} {g2} --out {o}"),
            f.to_string(),
        ),
        (
            format!("\"$TALUS\" compare {g1} {f} --out {o}"),
            f.to_string(),
        ),
        (
            format!("\"$TALUS\" compare {g1} {g2} --out {o} --config {f}"),
            f.to_string(),
        ),
        (
            format!("\"$TALUS\" compare {g1} {g2} --out {o} --before-mesh {f} --after-mesh {f}"),
            f.to_string(),
        ),
        (format!("\"$TALUS\" info <(cat {g1})"), "/dev/fd/".into()),
        (
            format!("\"$TALUS\" compare <(cat {g1}) {g2} --out {o}"),
            "/dev/fd/".into(),
        ),
    ] {
        let out_ = run_shell_with_deadline(&script);
        let err = String::from_utf8_lossy(&out_.stderr);
        assert_eq!(out_.status.code(), Some(2), "{script}: {err}");
        assert!(
            err.contains(&names) && err.contains("not a regular file"),
            "{script}: {err}"
        );
        assert!(!out.exists(), "{script}: {} left behind", out.display());
    }
    // A folder survey holding a FIFO among its clouds: named, not skipped in silence.
    let folder = c.p("tiles");
    std::fs::create_dir(&folder).unwrap();
    std::fs::copy(&good1, folder.join("a.las")).unwrap();
    std::fs::rename(&fifo, folder.join("b.las")).unwrap();
    let o = run_shell_with_deadline(&format!(
        "\"$TALUS\" compare {} {g2} --out {o}",
        folder.display()
    ));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("b.las") && err.contains("not a regular file"),
        "{err}"
    );
}

/// Issue 44, item 5: messages that were not true. `info` on a file of 2 or 3 points said
/// "fewer than two" and failed; now it describes the file and says why no spacing is measured.
/// Coordinates near 1e295 gave exit 1 "internal error: point spacing inf is not positive"
/// without the file, and messages printed 300-digit numbers. Two distinct positions over 829
/// rows were accepted as AFTER (refused as BEFORE, as "fewer than two"). `status` of a file
/// said "cannot write".
#[test]
fn degenerate_inputs_are_described_truly() {
    let c = Case::new();
    let p = plane(7, 3, 0.0);
    for n in [2, 3] {
        let f = c.p(&format!("few{n}.xyz"));
        common::write_text(&f, "x,y,z\n", &p[..n]);
        let o = common::run(&["info", f.to_str().unwrap()]);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            text.contains(&format!("points         {n}"))
                && text.contains(&format!(
                    "not measurable: {n} point(s); it needs at least 11 distinct positions"
                )),
            "{text}"
        );
    }
    // Coordinates near 1e295.
    let mut r = Rng::new(8);
    let huge: Vec<Point3> = (0..500)
        .map(|_| {
            [
                1e295 * (1.0 + r.uniform() * 1e-12),
                1e295 * (1.0 + r.uniform() * 1e-12),
                0.0,
            ]
        })
        .collect();
    let f = c.p("huge.xyz");
    let text: String = huge
        .iter()
        .map(|q| format!("{:e},{:e},{}\n", q[0], q[1], r.uniform()))
        .collect();
    std::fs::write(&f, text).unwrap();
    let o = common::run(&["info", f.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("coordinates as large as 1.000e295"), "{out}");
    assert!(out.lines().all(|l| l.len() < 400), "{out}");
    c.fails(
        &f,
        &f,
        &[],
        &["huge.xyz", "coordinates as large as 1.000e295"],
    );
    let o = common::run_compare(&c.p("good1.las"), &f, &c.out(), &[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("do not overlap") && err.contains("1.000e295"),
        "{err}"
    );
    assert!(err.len() < 400, "a number of hundreds of digits: {err}");
    // Two distinct positions over 829 rows, refused either way and with the truth.
    let twice: Vec<Point3> = (0..829).map(|i| p[i % 2]).collect();
    let f = c.p("two_places.xyz");
    common::write_text(&f, "x,y,z\n", &twice);
    for (before, after) in [(&f, &c.p("good1.las")), (&c.p("good1.las"), &f)] {
        let o = common::run_compare(before, after, &c.out(), &[]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        let last = err.trim().lines().last().unwrap();
        assert!(
            last.contains("two_places.xyz")
                && last.contains("829 points at only 2 distinct position(s)"),
            "{err}"
        );
        assert!(!c.out().exists());
    }
    // `status` of a file.
    let o = common::run(&["status", c.p("good1.las").to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("good1.las: is a file, not a directory"),
        "{err}"
    );
    assert!(!err.contains("cannot write"), "{err}");
}

/// Issue 44, item 5: a plain run into a folder that is not empty is told what works — it
/// advised "--resume or --force" where both refuse (files of the user's named like talus
/// outputs), and gave the loser of two runs started at once that advice instead of "in use by
/// another talus run".
#[test]
fn a_plain_run_into_a_used_folder_is_told_what_works() {
    let c = Case::new();
    let (g1, g2) = (c.p("good1.las"), c.p("good2.las"));
    let dir = c.p("d");
    let run = |extra: &[&str]| common::run_compare(&g1, &g2, &dir, extra);
    let refused = |o: &std::process::Output, needles: &[&str], not: &[&str]| {
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        for n in needles {
            assert!(err.contains(n), "'{n}' not in: {err}");
        }
        for n in not {
            assert!(!err.contains(n), "'{n}' in: {err}");
        }
    };
    // The user's own file named like an output: neither flag would do.
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("events.csv"), "mine").unwrap();
    refused(
        &run(&[]),
        &["events.csv", "not talus's to replace"],
        &["--resume"],
    );
    for flag in ["--resume", "--force"] {
        refused(&run(&[flag]), &["not talus's to replace"], &[]);
    }
    // Other files of the user's: --force writes beside them.
    std::fs::remove_file(dir.join("events.csv")).unwrap();
    std::fs::write(dir.join("notes.txt"), "mine").unwrap();
    refused(&run(&[]), &["holds no talus run", "--force"], &["--resume"]);
    let o = run(&["--force"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
        "mine"
    );
    // A finished run: either flag.
    refused(
        &run(&[]),
        &["holds a talus run", "--resume", "--force"],
        &[],
    );
    // A run holding DIR (as the loser of two runs started at once finds it).
    let lock = serde_json::json!({
        "pid": std::process::id(),
        "host": std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap().trim(),
        "started": 0,
        "token": "t",
        "run": "run",
        "command": "talus compare (the other run)",
    });
    std::fs::write(dir.join(".talus/lock"), lock.to_string()).unwrap();
    for extra in [&[][..], &["--resume"], &["--force"]] {
        refused(
            &run(extra),
            &["in use by another talus run", "the other run"],
            &["use --resume"],
        );
    }
    std::fs::remove_file(dir.join(".talus/lock")).unwrap();
    // A fresh DIR holding only the work area of a run that stopped before it planned.
    let fresh = c.p("fresh");
    std::fs::create_dir_all(fresh.join(".talus/units")).unwrap();
    let o = common::run_compare(&g1, &g2, &fresh, &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
