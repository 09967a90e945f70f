//! laspy and pyarrow, the independent LAS and Parquet readers of the tests (a venv made by
//! scripts/test.sh).

use std::path::{Path, PathBuf};
use std::process::Command;

/// A python with laspy: `$TALUS_PYTHON`, else `tests/py/.venv/bin/python`.
pub fn laspy_python() -> Option<PathBuf> {
    python_with("laspy")
}

/// A python with laspy and pyarrow (`$TALUS_PYTHON`, else `tests/py/.venv/bin/python`).
pub fn pyarrow_python() -> Option<PathBuf> {
    python_with("laspy, pyarrow")
}

/// A python that imports `modules`.
fn python_with(modules: &str) -> Option<PathBuf> {
    let mut candidates = Vec::new();
    if let Ok(p) = std::env::var("TALUS_PYTHON") {
        candidates.push(PathBuf::from(p));
    }
    candidates.push(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/py/.venv/bin/python"));
    for py in candidates {
        let ok = Command::new(&py)
            .args(["-c", &format!("import {modules}")])
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false);
        if ok {
            return Some(py);
        }
    }
    eprintln!(
        "SKIPPED: {modules} not available (run: python3 -m venv tests/py/.venv && \
         tests/py/.venv/bin/pip install 'laspy[lazrs]' pyarrow)"
    );
    None
}

/// A campaign's timeseries.parquet (pyarrow) and timeseries.laz (laspy) in `dir` compared value
/// by value, with `pairs` each pair's m3c2.laz too, with `against` the timeseries.laz of another
/// campaign of the same first survey (tests/py/read_timeseries.py): its JSON.
pub fn read_timeseries(
    py: &Path,
    dir: &Path,
    pairs: bool,
    against: Option<&Path>,
) -> serde_json::Value {
    let mut args = vec![dir.as_os_str()];
    if pairs {
        args.push("--pairs".as_ref());
    }
    if let Some(other) = against {
        args.extend(["--against".as_ref(), other.as_os_str()]);
    }
    run_script(py, "read_timeseries.py", &args)
}

pub fn laspy_read(py: &Path, file: &Path, n: usize) -> serde_json::Value {
    let n = n.to_string();
    run_script(py, "read_extra_bytes.py", &[file.as_os_str(), n.as_ref()])
}

/// tests/py/`script` run by `py` with `args`: its JSON on stdout.
fn run_script(py: &Path, script: &str, args: &[&std::ffi::OsStr]) -> serde_json::Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/py")
        .join(script);
    let out = Command::new(py)
        .arg(path)
        .args(args)
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "{script} failed on {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the script's JSON")
}

/// A number from the laspy JSON: floats come as exact repr strings, integers as numbers,
/// NaN as null.
pub fn num(v: &serde_json::Value) -> Option<f64> {
    match v {
        serde_json::Value::String(s) => Some(s.parse().expect("float string")),
        serde_json::Value::Number(n) => n.as_f64(),
        _ => None,
    }
}
