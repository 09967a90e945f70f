//! Serve the web viewer for one result directory on 127.0.0.1 and a free port.
//!
//! `cargo run --example view_server -- DIR` prints `talus viewer: http://127.0.0.1:PORT/` as its
//! first stdout line (the browser tests read it) and serves until killed: the viewer built into
//! the binary, or `$TALUS_VIEWER_DIR`, as `talus view DIR --port 0` does.

use std::io::Write;
use std::path::PathBuf;

fn main() {
    let Some(dir) = std::env::args_os().nth(1).map(PathBuf::from) else {
        eprintln!("usage: view_server DIR");
        std::process::exit(2);
    };
    let viewer = talus::commands::view::Viewer::from_env();
    let result = talus::commands::view::serve(
        &dir,
        talus::commands::view::DEFAULT_BIND,
        0,
        &viewer,
        |addr| {
            let mut out = std::io::stdout().lock();
            let _ = writeln!(out, "talus viewer: http://{addr}/");
            let _ = out.flush();
        },
    );
    if let Err(e) = result {
        eprintln!("view_server: {e}");
        std::process::exit(e.exit_code());
    }
}
