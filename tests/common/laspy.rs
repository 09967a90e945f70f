//! laspy, the independent LAS reader of the tests (a venv made by scripts/test.sh).

use std::path::{Path, PathBuf};
use std::process::Command;

/// A python with laspy: `$TALUS_PYTHON`, else `tests/py/.venv/bin/python`.
pub fn laspy_python() -> Option<PathBuf> {
    let mut candidates = Vec::new();
    if let Ok(p) = std::env::var("TALUS_PYTHON") {
        candidates.push(PathBuf::from(p));
    }
    candidates.push(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/py/.venv/bin/python"));
    for py in candidates {
        let ok = Command::new(&py)
            .args(["-c", "import laspy"])
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false);
        if ok {
            return Some(py);
        }
    }
    eprintln!(
        "SKIPPED: laspy not available (run: python3 -m venv tests/py/.venv && \
         tests/py/.venv/bin/pip install 'laspy[lazrs]')"
    );
    None
}

pub fn laspy_read(py: &Path, file: &Path, n: usize) -> serde_json::Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/py/read_extra_bytes.py");
    let out = Command::new(py)
        .arg(script)
        .arg(file)
        .arg(n.to_string())
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "laspy failed on {}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("laspy JSON")
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
