//! The layers of the library, checked: every top-level module of `src/` has a place in
//! [`LAYERS`], and a module names (`crate::X`) only modules placed before it, so the imports
//! have no cycle and none goes upward (ARCHITECTURE.md "Layers"). Whole files are read, their
//! test modules too; comments (doc comments among them) are not imports and are left out.
//!
//! Some layers are crates of their own beneath this one (`talus-base`: error, geom, rng;
//! `talus-store`; `talus-synth`), re-exported under those names by `src/lib.rs`: the compiler
//! keeps their own imports down (a crate sees only the crates it depends on), so here they are
//! ranked for the imports of them, and [`CRATES`] checks that a crate depends only on the crates
//! below it.

use std::collections::BTreeMap;
use std::path::Path;

/// From the bottom up: the shared base; the pure algorithms; the formats; the parameters; the
/// store; the plan and the stages' units; the executors; the commands.
const LAYERS: &[&str] = &[
    // base (error, geom and rng: the talus-base crate)
    "error",
    "geom",
    "rng",
    "interrupt",
    "memory",
    "progress",
    // algorithms
    "spatial",
    "m3c2",
    "events",
    "volume",
    "campaign",
    // the talus-synth crate
    "synth",
    // formats
    "io",
    // parameters: the spacing measured on the input, the resolved parameters
    "sampling",
    "params",
    // store: the talus-store crate
    "store",
    // plan, then the units that do it
    "plan",
    "units",
    // executors
    "exec",
    // commands, and the command line over them
    "commands",
    "cli",
];

/// The workspace's crates from the bottom up, each with its folder: a crate may depend only on
/// crates before it (cargo refuses a cycle; this refuses a dependency that goes up without one,
/// e.g. the store on synth).
const CRATES: &[(&str, &str)] = &[
    ("talus-base", "base"),
    ("talus-tiling", "tiling"),
    ("talus-store", "store"),
    ("talus-synth", "synth"),
    ("talus", "."),
];

/// The top-level module a file of `src/` belongs to.
fn top_module(rel: &Path) -> String {
    let first = rel
        .components()
        .next()
        .unwrap()
        .as_os_str()
        .to_string_lossy();
    first.trim_end_matches(".rs").to_string()
}

/// The code of a file as imports see it: no comments. Test modules count: a test names only
/// what its module may (a check across layers lives in the higher one).
fn code(text: &str) -> String {
    text.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The modules `crate::X` (or `crate::{X, Y::..}`) names in `code`.
fn named(code: &str) -> Vec<String> {
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = Vec::new();
    for (i, _) in code.match_indices("crate::") {
        let rest = &code[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            // Top-level names of the group: split at commas outside nested braces.
            let (mut depth, mut start) = (0, 0);
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => {
                        out.push(ident(&group[start..k]));
                        break;
                    }
                    '}' => depth -= 1,
                    ',' if depth == 0 => {
                        out.push(ident(&group[start..k]));
                        start = k + 1;
                    }
                    _ => {}
                }
            }
        } else {
            out.push(ident(rest));
        }
    }
    out.retain(|m| !m.is_empty());
    out
}

fn files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn every_import_goes_to_a_lower_layer() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut all = Vec::new();
    files(&src, &mut all);
    let rank = |m: &str| LAYERS.iter().position(|l| *l == m);
    let mut upward: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut unplaced = Vec::new();
    for f in &all {
        let rel = f.strip_prefix(&src).unwrap();
        let me = top_module(rel);
        if me == "main" || me == "lib" {
            continue; // the binary and the crate root sit above everything
        }
        let Some(mine) = rank(&me) else {
            unplaced.push(me);
            continue;
        };
        let text = std::fs::read_to_string(f).unwrap();
        for m in named(&code(&text)) {
            // `crate::Error`, `crate::Result`: the crate root's re-exports of `error`.
            let m = if m.starts_with(char::is_uppercase) {
                "error".to_string()
            } else {
                m
            };
            if m == me {
                continue;
            }
            match rank(&m) {
                Some(r) if r < mine => {}
                Some(_) => upward
                    .entry(format!("{} -> {m}", rel.display()))
                    .or_default()
                    .push(m.clone()),
                None => unplaced.push(m),
            }
        }
    }
    unplaced.sort();
    unplaced.dedup();
    assert!(
        unplaced.is_empty(),
        "modules with no place in LAYERS: {unplaced:?}"
    );
    assert!(
        upward.is_empty(),
        "imports of a module at the same or a higher layer: {:#?}",
        upward.keys().collect::<Vec<_>>()
    );
}

#[test]
fn the_check_sees_an_upward_import() {
    // The parser the test relies on: a name in code counts, in a test module too; one in a
    // comment does not.
    let text = "use crate::units::Ctx; // crate::commands\n/// [`crate::exec`]\n\
                use crate::{io::{self, Bounds}, plan};\n\
                #[cfg(test)]\nmod tests {\n    use crate::cli;\n}\n";
    assert_eq!(named(&code(text)), vec!["units", "io", "plan", "cli"]);
}

/// The talus crates a manifest depends on (`talus-…` keys of its `[dependencies]`), by name.
fn talus_dependencies(manifest: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_deps = false;
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            in_deps = line == "[dependencies]";
            continue;
        }
        if !in_deps {
            continue;
        }
        let name = line.split(['=', ' ']).next().unwrap_or("");
        if name.starts_with("talus") {
            out.push(name.to_string());
        }
    }
    out
}

#[test]
fn every_crate_depends_only_on_crates_below_it() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let rank = |name: &str| CRATES.iter().position(|(n, _)| *n == name);
    let members = std::fs::read_to_string(root.join("Cargo.toml")).unwrap();
    let mut upward = Vec::new();
    for (i, (name, dir)) in CRATES.iter().enumerate() {
        assert!(
            *dir == "." || members.contains(&format!("\"{dir}\"")),
            "{name} ({dir}/) is not a member of the workspace"
        );
        let manifest = std::fs::read_to_string(root.join(dir).join("Cargo.toml")).unwrap();
        assert!(
            manifest.contains(&format!("name = \"{name}\"")),
            "{dir}/Cargo.toml"
        );
        for dep in talus_dependencies(&manifest) {
            match rank(&dep) {
                Some(r) if r < i => {}
                _ => upward.push(format!("{name} -> {dep}")),
            }
        }
    }
    assert!(
        upward.is_empty(),
        "crate dependencies that go up: {upward:?}"
    );
}
