//! Every unit knows the code that made it (issue 46, item 2): a stage's `VERSION` is part of its
//! units' keys, so it must change whenever what the stage writes changes. This test runs a fixed
//! campaign (3 misregistered surveys of 20,000 points, `--vegetation remove`: tiling, align,
//! aligned, cleared, orient, thinned, m3c2, stable, events, series, volumes, points, outputs,
//! campaign) and a compare with `--core-points` (cores) and `--tiling-part` (segments), hashes
//! each stage's units, and compares with `tests/data/stage_outputs.json`: a hash that changed under an unchanged version fails,
//! naming the stage to bump, unless an earlier stage's version changed (a stage's output follows
//! from its dependencies'). (`merged` needs more than 32 tiles a pair: not covered here.)
//!
//! After bumping a version (or adding a stage), rewrite the file with
//! `TALUS_BLESS=1 cargo test --test stage_versions` and commit it.
//!
//! What is hashed: every file of every unit of the stage (sorted by unit label and file name),
//! and the record's meta; the run's own clock (keys `seconds`, `peak_rss_bytes`; the `seconds`
//! column of campaign.csv), the report's HTML (a rendering of campaign.json), the folder the run
//! was in, unit keys named in files (they hold the inputs' paths) and the package version (which
//! the outputs' keys hold already) left out.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;
use talus_tiling::Fnv64;

const GOLDEN: &str = "tests/data/stage_outputs.json";

/// `v` without the run's clock.
fn without_clock(v: &mut Value) {
    match v {
        Value::Object(m) => {
            m.retain(|k, _| k != "seconds" && k != "peak_rss_bytes");
            m.values_mut().for_each(without_clock);
        }
        Value::Array(a) => a.iter_mut().for_each(without_clock),
        _ => {}
    }
}

/// `bytes` with every occurrence of `from` replaced by `to`.
fn replace(bytes: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if !from.is_empty() && bytes[i..].starts_with(from) {
            out.extend_from_slice(to);
            i += from.len();
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    out
}

/// `text` with every unit key (`-` and 16 hex digits ending a unit's name) replaced: keys hold
/// the input files' paths, so they differ from folder to folder.
fn without_keys(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < b.len() {
        let key = b[i] == b'-'
            && i + 17 <= b.len()
            && b[i + 1..i + 17].iter().all(|c| c.is_ascii_hexdigit())
            && b.get(i + 17).is_none_or(|c| !c.is_ascii_alphanumeric());
        if key {
            out.push_str("-<KEY>");
            i += 17;
        } else {
            let c = text[i..].chars().next().unwrap();
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

/// What of file `name` (bytes `raw`) is the stage's output: the folder `tmp` and the package
/// version replaced, the clock removed.
fn content(name: &str, raw: &[u8], tmp: &Path) -> Option<Vec<u8>> {
    if name.ends_with(".html") {
        return None;
    }
    let mut b = raw.to_vec();
    for dir in [tmp.to_path_buf(), tmp.canonicalize().unwrap()] {
        b = replace(&b, dir.to_str().unwrap().as_bytes(), b"<TMP>");
    }
    b = replace(&b, env!("CARGO_PKG_VERSION").as_bytes(), b"<VERSION>");
    if name.ends_with(".json") || name.ends_with(".csv") || name.ends_with(".geojson") {
        b = without_keys(&String::from_utf8(b).unwrap()).into_bytes();
    }
    if name.ends_with(".json") {
        let mut v: Value = serde_json::from_slice(&b).unwrap();
        without_clock(&mut v);
        return Some(serde_json::to_vec(&v).unwrap());
    }
    if name.ends_with(".csv") {
        let text = String::from_utf8(b).unwrap();
        let header: Vec<&str> = text.lines().next().unwrap_or("").split(',').collect();
        let clock = header.iter().position(|h| *h == "seconds");
        let kept: Vec<String> = text
            .lines()
            .map(|l| {
                l.split(',')
                    .enumerate()
                    .filter(|(i, _)| Some(*i) != clock)
                    .map(|(_, c)| c)
                    .collect::<Vec<_>>()
                    .join(",")
            })
            .collect();
        return Some(kept.join("\n").into_bytes());
    }
    Some(b)
}

/// Every file below `dir`, relative to it, sorted.
fn files(dir: &Path, rel: &str, out: &mut Vec<String>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        let r = if rel.is_empty() {
            name
        } else {
            format!("{rel}/{name}")
        };
        if p.is_dir() {
            files(&p, &r, out);
        } else {
            out.push(r);
        }
    }
}

/// Each stage's hash over the units of the result folder `res` (run in `tmp`), by kind.
fn stage_hashes(res: &Path, tmp: &Path, into: &mut BTreeMap<String, Fnv64>) {
    let units = res.join(".talus/units");
    for kind in std::fs::read_dir(&units).unwrap() {
        let kind = kind.unwrap().path();
        let k = kind.file_name().unwrap().to_str().unwrap().to_string();
        // Units by label: a unit's directory is `<label>-<key>`, and the key holds the version.
        let mut dirs: Vec<(String, std::path::PathBuf)> = std::fs::read_dir(&kind)
            .unwrap()
            .map(|e| e.unwrap().path())
            .map(|p| {
                let n = p.file_name().unwrap().to_str().unwrap();
                (n[..n.rfind('-').unwrap()].to_string(), p)
            })
            .collect();
        dirs.sort();
        let h = into.entry(k).or_default();
        for (label, dir) in dirs {
            h.write_str(&label);
            let mut names = Vec::new();
            files(&dir, "", &mut names);
            for name in names {
                let raw = std::fs::read(dir.join(&name)).unwrap();
                if name == "record.json" {
                    let record: Value = serde_json::from_slice(&raw).unwrap();
                    let mut meta = record["meta"].clone();
                    without_clock(&mut meta);
                    let text = serde_json::to_string(&meta).unwrap();
                    let c = content("meta.json", text.as_bytes(), tmp).unwrap();
                    h.write_str("meta").write(&c);
                } else if let Some(c) = content(&name, &raw, tmp) {
                    h.write_str(&name).write(&c);
                }
            }
        }
    }
}

#[test]
fn a_stage_whose_output_changed_has_a_new_version() {
    let tmp = common::tempdir();
    let t = tmp.path();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let data = t.join("data");
    common::run_ok(&[
        "synth",
        "campaign",
        "--epochs",
        "3",
        "--points",
        "20000",
        "--misregister",
        "--out",
        &s(&data),
    ]);
    let surveys: Vec<String> = (0..3)
        .map(|k| s(&data.join(format!("survey_2021{:02}01.laz", 3 + 3 * k))))
        .collect();
    let camp = t.join("campaign");
    let mut args: Vec<&str> = vec!["campaign"];
    args.extend(surveys.iter().map(String::as_str));
    let out = s(&camp);
    // Every unit's files stay after the run, to be hashed.
    args.extend(["--out", &out, "--vegetation", "remove", "--keep-units"]);
    common::run_ok(&args);
    let pair = t.join("pair");
    common::run_ok(&[
        "compare",
        &surveys[0],
        &surveys[1],
        "--out",
        &s(&pair),
        "--core-points",
        &surveys[0],
        "--keep-units",
        // The before survey tiled in parts, and m3c2.laz written in segments.
        "--tiling-part",
        "8000",
    ]);

    let mut hashes = BTreeMap::new();
    stage_hashes(&camp, t, &mut hashes);
    stage_hashes(&pair, t, &mut hashes);
    let registry = talus::units::stage::registry();
    let now: BTreeMap<String, Value> = hashes
        .iter()
        .map(|(k, h)| {
            let v = registry.get(k).unwrap().version();
            (
                k.clone(),
                serde_json::json!({"version": v, "hash": h.hex()}),
            )
        })
        .collect();
    let golden_path = Path::new(env!("CARGO_MANIFEST_DIR")).join(GOLDEN);
    if std::env::var_os("TALUS_BLESS").is_some() {
        let text = serde_json::to_string_pretty(&now).unwrap();
        std::fs::write(&golden_path, text + "\n").unwrap();
        eprintln!("wrote {}", golden_path.display());
        return;
    }
    let golden: BTreeMap<String, Value> =
        serde_json::from_str(&std::fs::read_to_string(&golden_path).unwrap()).unwrap();
    // In pipeline order: a stage whose output changed is explained by its own new version, or
    // by an earlier stage's (its output follows from its dependencies').
    let mut wrong = Vec::new();
    let mut bumped = false;
    for stage in registry.stages() {
        let kind = stage.kind();
        let Some(n) = now.get(kind) else { continue };
        let Some(g) = golden.get(kind) else {
            wrong.push(format!("{kind}: not in {GOLDEN}"));
            continue;
        };
        let same_version = g["version"] == n["version"];
        if !same_version {
            bumped = true;
            wrong.push(format!(
                "{kind}: VERSION {} where {GOLDEN} has {}: rewrite it",
                n["version"], g["version"]
            ));
        } else if g["hash"] != n["hash"] && !bumped {
            wrong.push(format!(
                "{kind}: what it writes changed but its VERSION ({}) did not: bump it, then \
                 rewrite {GOLDEN}",
                n["version"]
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "{}\n(TALUS_BLESS=1 cargo test --test stage_versions rewrites {GOLDEN})",
        wrong.join("\n")
    );
    assert_eq!(
        now.len(),
        registry.stages().len() - 1,
        "every stage but merged is covered: {:?}",
        now.keys().collect::<Vec<_>>()
    );
}

/// `talus --version` tells two builds apart: the release and the commit it was built from.
#[test]
fn the_version_names_the_release_and_the_commit() {
    let o = common::run(&["--version"]);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    let want = format!("talus {} (commit ", env!("CARGO_PKG_VERSION"));
    assert!(text.starts_with(&want), "{text}");
    let commit = text[want.len()..].trim_end().trim_end_matches(')');
    // Outside a git checkout (a source tarball) the commit is unknown, and says so.
    assert!(
        commit == "unknown"
            || (commit.len() == 12 && commit.chars().all(|c| c.is_ascii_hexdigit())),
        "{text}"
    );
}
