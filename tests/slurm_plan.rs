//! `--executor slurm` without a cluster (the run on a real Slurm is scripts/slurm/campaign.sh):
//! `--plan-only` writes the plan, one sbatch script per stage and `submit.sh` and submits
//! nothing; `talus status` reads them; the flags are checked; without sbatch on PATH the run
//! stops with a message naming it.

mod common;

use std::path::Path;

fn synth_pair(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let o = common::run(&[
        "synth",
        "hill",
        "--points",
        "20000",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut laz: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "laz" || e == "las"))
        .collect();
    laz.sort();
    assert_eq!(laz.len(), 2, "{laz:?}");
    (laz[0].clone(), laz[1].clone())
}

#[test]
fn plan_only_writes_the_scripts_and_submits_nothing() {
    let tmp = common::tempdir();
    let (a, b) = synth_pair(&tmp.path().join("scene"));
    let out = tmp.path().join("out");
    let o = common::run_compare(
        &a,
        &b,
        &out,
        &[
            "--executor",
            "slurm",
            "--plan-only",
            "--tiles-per-task",
            "2",
            "--tile-size",
            "12",
            "--slurm-args",
            "-p long --comment='a b'",
        ],
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("--plan-only"), "{stderr}");
    let sub = out.join(".talus/slurm/1");
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stages: Vec<&str> = stdout
        .lines()
        .map(|l| l.split_whitespace().next().unwrap())
        .collect();
    assert_eq!(
        stages,
        // The stages of one unit a task computed at the end of the arrays holding what they
        // read (issue 47): the aligned survey at the alignment's, the orientation at the
        // field's, the stable ground and the events at M3C2's, m3c2.laz and the outputs at the
        // volumes'. Not the alignment: at the tiling's end it would hold back the field, which
        // waits for the tiling and not for it.
        ["tiling", "align", "field", "m3c2", "volumes", "publish"],
        "{stdout}"
    );
    assert!(
        !sub.join("jobs.json").exists(),
        "--plan-only recorded job ids"
    );
    assert!(sub.join("plan.json").is_file() && out.join(".talus/plan.json").is_file());

    // Two tiles per task in the tile stages.
    let json = |p: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap()
    };
    // The items of array `key` of `v` whose `field` is "m3c2".
    let m3c2_of = |v: &serde_json::Value, key: &str, field: &dyn Fn(&serde_json::Value) -> bool| {
        v[key]
            .as_array()
            .unwrap()
            .iter()
            .filter(|x| field(x))
            .cloned()
            .collect::<Vec<_>>()
    };
    let tiles = m3c2_of(&json(&out.join(".talus/plan.json")), "units", &|u| {
        u["spec"]["kind"] == "m3c2"
    })
    .len();
    assert!(tiles >= 2, "the test wants several tiles, got {tiles}");
    let m3c2 = m3c2_of(&json(&sub.join("submission.json")), "stages", &|s| {
        s["kind"] == "m3c2"
    })
    .pop()
    .unwrap();
    assert_eq!(m3c2["tasks"].as_array().unwrap().len(), tiles.div_ceil(2));
    // The orientation field's sample is a unit per tile of the before survey: two to a task too.
    let field = m3c2_of(&json(&sub.join("submission.json")), "stages", &|s| {
        s["kind"] == "field"
    })
    .pop()
    .unwrap();
    assert_eq!(field["tasks"].as_array().unwrap().len(), tiles.div_ceil(2));

    let script = std::fs::read_to_string(sub.join("04-m3c2.sh")).unwrap();
    for line in [
        "#!/bin/bash",
        &format!("#SBATCH --array=0-{}", tiles.div_ceil(2) - 1),
        "#SBATCH --kill-on-invalid-dep=yes",
        "#SBATCH --mem=2048M",
        "slurm-task",
        "--stage m3c2",
    ] {
        assert!(script.contains(line), "no {line:?} in\n{script}");
    }
    // Each array waits for the arrays holding what its units read (issue 47): the orientation
    // field for the tiling alone, beside the alignment; M3C2 for the tiles, the alignment (the
    // aligned survey, at its end) and the field (the orientation, at its end); the volumes for
    // the tiles, the alignment and M3C2 (the events, at its end); the publishing job for every
    // array.
    let submit = std::fs::read_to_string(sub.join("submit.sh")).unwrap();
    for (script, after) in [
        ("01-tiling.sh", ""),
        ("02-align.sh", "$j1"),
        ("03-field.sh", "$j1"),
        ("04-m3c2.sh", "$j1:$j2:$j3"),
        ("05-volumes.sh", "$j1:$j2:$j4"),
        ("06-publish.sh", "$j1:$j2:$j3:$j4:$j5"),
    ] {
        let dependency = match after {
            "" => String::new(),
            a => format!("\"--dependency=afterok:{a}\" "),
        };
        let line = format!("sbatch --parsable {dependency}-p long '--comment=a b' {script}");
        assert!(submit.contains(&line), "no {line:?} in\n{submit}");
    }

    // Each array's tails, which its tasks compute when they end where their inputs are all
    // done; the publishing job computes any they left before it publishes.
    let submission = json(&sub.join("submission.json"));
    let units = json(&out.join(".talus/plan.json"))["units"].clone();
    let kind_of = |name: &serde_json::Value| -> String {
        let u = units
            .as_array()
            .unwrap()
            .iter()
            .find(|u| u["name"] == *name);
        u.unwrap()["spec"]["kind"].as_str().unwrap().to_string()
    };
    let stage = |kind: &str| m3c2_of(&submission, "stages", &|s| s["kind"] == kind).pop();
    let kinds = |v: &serde_json::Value| -> Vec<String> {
        v.as_array()
            .map_or(vec![], |t| t.iter().map(kind_of).collect())
    };
    for (array, tails) in [
        ("tiling", &[][..]),
        ("align", &["aligned"]),
        ("field", &["orient"]),
        ("m3c2", &["stable", "events"]),
        ("volumes", &["points", "outputs"]),
    ] {
        assert_eq!(kinds(&stage(array).unwrap()["tails"]), tails, "{array}");
    }
    assert_eq!(
        kinds(&stage("publish").unwrap()["tasks"][0]),
        ["aligned", "orient", "stable", "events", "points", "outputs"]
    );

    let o = common::run(&["status", out.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains("not submitted (--plan-only)"), "{text}");
    assert!(text.contains("outputs: not published"), "{text}");
}

#[test]
fn slurm_flags_are_checked_and_a_missing_sbatch_is_named() {
    let tmp = common::tempdir();
    let (a, b) = synth_pair(&tmp.path().join("scene"));
    for (extra, says) in [
        (vec!["--wait"], "go with --executor slurm"),
        (
            vec!["--executor", "slurm", "--wait", "--plan-only"],
            "nothing to wait for",
        ),
        (
            vec!["--executor", "slurm", "--slurm-args", "--comment='open"],
            "unclosed quote",
        ),
        (
            vec!["--executor", "slurm", "--tiles-per-task", "0"],
            "at least 1",
        ),
    ] {
        let o = common::run_compare(&a, &b, &tmp.path().join("x"), &extra);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {stderr}");
        assert!(stderr.contains(says), "{extra:?}: {stderr}");
    }
    // No Slurm client commands on PATH.
    let empty = tmp.path().join("empty-path");
    std::fs::create_dir_all(&empty).unwrap();
    let out = tmp.path().join("out");
    let o = common::talus()
        .env("PATH", &empty)
        .args(["compare", a.to_str().unwrap(), b.to_str().unwrap(), "--out"])
        .arg(&out)
        .args(["--executor", "slurm"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("no sbatch on PATH"), "{stderr}");
}
