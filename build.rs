//! Embeds the web viewer (`viewer/index.html`, `viewer/src/`, the vendored three.js files under
//! `viewer/vendor/three/`) into the binary, so that `talus view` needs no source tree and no
//! `node_modules` (src/view.rs serves them; `TALUS_VIEWER_DIR` serves a directory instead).
//!
//! Writes `$OUT_DIR/viewer_assets.rs`: one `(path relative to viewer/, include_bytes!)` entry per
//! file, sorted. Dotfiles are left out (the server never serves them).

use std::path::{Path, PathBuf};

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        let hidden = p
            .file_name()
            .and_then(|n| n.to_str())
            .is_none_or(|n| n.starts_with('.'));
        if hidden {
            continue;
        }
        if p.is_dir() {
            files(&p, out);
        } else {
            out.push(p);
        }
    }
}

/// The commit this build is of (`git rev-parse`), so that `talus --version` tells two builds
/// apart; "unknown" outside a git checkout (a source tarball). Rebuilt when HEAD moves.
fn commit() -> String {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    if let Some(dir) = git(&["rev-parse", "--absolute-git-dir"]) {
        let dir = Path::new(&dir);
        println!("cargo:rerun-if-changed={}", dir.join("HEAD").display());
        if let Some(head) = git(&["symbolic-ref", "-q", "HEAD"]) {
            // The branch's ref (loose, or packed once git packs it); in a worktree, the common dir.
            let common = git(&["rev-parse", "--git-common-dir"])
                .map(|c| Path::new(env!("CARGO_MANIFEST_DIR")).join(c))
                .unwrap_or_else(|| dir.to_path_buf());
            println!("cargo:rerun-if-changed={}", common.join(&head).display());
            println!(
                "cargo:rerun-if-changed={}",
                common.join("packed-refs").display()
            );
        }
    }
    git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".to_string())
}

fn main() {
    println!("cargo:rustc-env=TALUS_COMMIT={}", commit());
    let viewer = Path::new(env!("CARGO_MANIFEST_DIR")).join("viewer");
    let mut list = vec![viewer.join("index.html")];
    for sub in ["src", "vendor"] {
        let dir = viewer.join(sub);
        println!("cargo:rerun-if-changed={}", dir.display());
        files(&dir, &mut list);
    }
    println!(
        "cargo:rerun-if-changed={}",
        viewer.join("index.html").display()
    );
    let mut code = String::from("pub static ASSETS: &[(&str, &[u8])] = &[\n");
    for p in &list {
        let rel = p.strip_prefix(&viewer).expect("under viewer/");
        let rel: Vec<&str> = rel
            .iter()
            .map(|c| c.to_str().expect("UTF-8 name"))
            .collect();
        code.push_str(&format!(
            "    ({:?}, include_bytes!({:?})),\n",
            rel.join("/"),
            p.display().to_string()
        ));
    }
    code.push_str("];\n");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR")).join("viewer_assets.rs");
    std::fs::write(&out, code).unwrap_or_else(|e| panic!("{}: {e}", out.display()));
}
