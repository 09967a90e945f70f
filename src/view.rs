//! Web viewer server: a small, read-only HTTP/1.1 file server for `talus view DIR`.
//!
//! It serves the static viewer (`viewer/index.html`, `viewer/src/`, and only the `build/` and
//! `examples/jsm/` directories of the `three` npm package) plus the files of one comparison
//! result directory under `/data/`. The browser does all the rendering; the server never writes
//! anything and never lists directories.
//!
//! Why hand-written on `std::net` rather than a web framework: the whole job is "GET a file",
//! the dependency tree stays small, and the security-relevant part (mapping a URL to a file
//! without escaping its root, RFC 3986 §2.1 percent-decoding, RFC 9110 methods and status codes)
//! is short enough to be read in one sitting. Each request path is percent-decoded *before* it
//! is split into segments, so `%2e%2e` and `%2f` cannot smuggle `..` or an absolute path past
//! the checks; then the joined file path is canonicalized and must still lie under its root,
//! which also stops symlinks that point outside.
//!
//! When bound to a loopback address, requests whose `Host` header is not a loopback name are
//! refused: that blocks DNS-rebinding pages from reading the result through the user's browser.

use std::io::{self, Read, Write};
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::error::{Error, Result};

/// Where `talus view` listens unless told otherwise: this machine only.
pub const DEFAULT_BIND: IpAddr = IpAddr::V4(std::net::Ipv4Addr::LOCALHOST);

/// At most this many connections are served at once; more get `503` right away. A browser opens
/// about six per host, so this leaves room for a few tabs without letting a client exhaust threads.
pub const MAX_CONNECTIONS: usize = 32;

/// Largest request head (request line + headers) we read; GET requests have no body.
const MAX_HEAD_BYTES: usize = 16 * 1024;

/// A client that sends nothing (or stops reading) for this long is dropped.
const IO_TIMEOUT: Duration = Duration::from_secs(15);

/// The `three` package files the page imports; nothing else under `node_modules/` is served.
const THREE_BUILD: &str = "node_modules/three/build";
const THREE_JSM: &str = "node_modules/three/examples/jsm";

/// The viewer's static files: `$TALUS_VIEWER_DIR` if set, else the `viewer/` directory of the
/// talus source tree this binary was built from. `None` when that directory has no `index.html`.
///
/// The directory may still lack `node_modules/three` (`npm ci` not run); [`serve`] reports that.
pub fn find_viewer_root() -> Option<PathBuf> {
    // An explicit setting wins and is not silently replaced by the built-in path.
    let dir = match std::env::var_os("TALUS_VIEWER_DIR") {
        Some(dir) if !dir.is_empty() => PathBuf::from(dir),
        _ => Path::new(env!("CARGO_MANIFEST_DIR")).join("viewer"),
    };
    dir.join("index.html").is_file().then_some(dir)
}

/// [`find_viewer_root`], or the error to show the user when it finds nothing.
pub fn viewer_root() -> Result<PathBuf> {
    find_viewer_root().ok_or_else(|| {
        Error::Usage(
            "viewer files not found: set TALUS_VIEWER_DIR to the talus `viewer/` directory \
             (and run `npm ci` in viewer/)"
                .into(),
        )
    })
}

/// Serve the viewer for the result directory `dir` on `bind:port` until the process ends.
///
/// `port` 0 picks a free port; `on_ready` receives the bound address (print the URL from it)
/// once the socket is listening. Errors: `dir` is not a result directory (no `view.json`), the
/// viewer files or `node_modules/three` are missing, or the address cannot be bound.
pub fn serve(
    dir: &Path,
    bind: IpAddr,
    port: u16,
    viewer_root: &Path,
    on_ready: impl FnOnce(SocketAddr),
) -> Result<()> {
    let roots = Arc::new(Roots::new(dir, viewer_root)?);
    let listener = TcpListener::bind((bind, port)).map_err(|e| {
        Error::Usage(format!(
            "cannot listen on {}: {e}",
            SocketAddr::new(bind, port)
        ))
    })?;
    let addr = listener
        .local_addr()
        .map_err(|e| Error::Internal(format!("listening socket has no address: {e}")))?;
    on_ready(addr);

    let active = Arc::new(AtomicUsize::new(0));
    let loopback_only = bind.is_loopback();
    for conn in listener.incoming() {
        let stream = match conn {
            Ok(s) => s,
            // Transient (a client reset, out of file descriptors): keep serving.
            Err(_) => {
                std::thread::sleep(Duration::from_millis(20));
                continue;
            }
        };
        let _ = stream.set_read_timeout(Some(IO_TIMEOUT));
        let _ = stream.set_write_timeout(Some(IO_TIMEOUT));
        if active.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
            active.fetch_sub(1, Ordering::SeqCst);
            let mut stream = stream;
            let _ = respond_error(&mut stream, 503, "too many connections", false);
            continue;
        }
        let guard = ActiveGuard(Arc::clone(&active));
        let roots = Arc::clone(&roots);
        let spawned = std::thread::Builder::new()
            .name("talus-view".into())
            .spawn(move || {
                let _guard = guard;
                let mut stream = stream;
                // A client that goes away mid-response is its own business.
                let _ = handle(&mut stream, &roots, loopback_only);
                let _ = stream.flush();
                drain_and_close(&mut stream);
            });
        // If no thread could be made, the closure (and its guard) is dropped: the count recovers.
        if spawned.is_err() {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    Ok(())
}

/// Decrements the active-connection count when a connection thread ends (even by panic).
struct ActiveGuard(Arc<AtomicUsize>);

impl Drop for ActiveGuard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// The canonical directories files may come from.
struct Roots {
    index: PathBuf,
    src: PathBuf,
    three_build: PathBuf,
    three_jsm: PathBuf,
    data: PathBuf,
}

impl Roots {
    fn new(dir: &Path, viewer_root: &Path) -> Result<Roots> {
        let data = dir
            .canonicalize()
            .map_err(|e| Error::input(dir, format!("cannot open result directory: {e}")))?;
        if !data.join("view.json").is_file() {
            return Err(Error::input(
                dir,
                "not a talus result directory (no view.json); run `talus compare` first",
            ));
        }
        let missing = |what: &str| {
            Error::input(
                viewer_root,
                format!("viewer files not found ({what} is missing): run `npm ci` in viewer/"),
            )
        };
        let canon = |rel: &str| {
            viewer_root
                .join(rel)
                .canonicalize()
                .map_err(|_| missing(rel))
        };
        let index = canon("index.html")?;
        let src = canon("src")?;
        let three_build = canon(THREE_BUILD)?;
        let three_jsm = canon(THREE_JSM)?;
        if !three_build.join("three.module.js").is_file() {
            return Err(missing("node_modules/three/build/three.module.js"));
        }
        Ok(Roots {
            index,
            src,
            three_build,
            three_jsm,
            data,
        })
    }

    /// The file a decoded, validated path maps to, or the status code to answer with.
    fn resolve(&self, segments: &[String]) -> std::result::Result<PathBuf, u16> {
        let s: Vec<&str> = segments.iter().map(String::as_str).collect();
        match s.as_slice() {
            [] | ["index.html"] => Ok(self.index.clone()),
            ["src", rest @ ..] => under(&self.src, rest),
            ["node_modules", "three", "build", rest @ ..] => under(&self.three_build, rest),
            ["node_modules", "three", "examples", "jsm", rest @ ..] => under(&self.three_jsm, rest),
            ["data", rest @ ..] => under(&self.data, rest),
            _ => Err(404),
        }
    }
}

/// `root/rest...` if that is a regular file whose canonical path is still inside `root`.
fn under(root: &Path, rest: &[&str]) -> std::result::Result<PathBuf, u16> {
    if rest.is_empty() {
        return Err(404); // a directory: no listings
    }
    let mut path = root.to_path_buf();
    path.extend(rest);
    let canonical = path.canonicalize().map_err(|_| 404u16)?;
    // Symlinks are followed by canonicalize; one pointing outside the root lands here.
    if !canonical.starts_with(root) {
        return Err(403);
    }
    if !canonical.is_file() {
        return Err(404);
    }
    Ok(canonical)
}

/// Percent-decode a request path (RFC 3986 §2.1) and split it into checked segments.
///
/// Refused (403): empty segments (`//` would make `Path::join` absolute), `.` and `..`, and
/// segments with a backslash, a NUL or a drive colon. Malformed escapes or non-UTF-8 give 400.
fn decode_path(raw: &str) -> std::result::Result<Vec<String>, u16> {
    let path = raw.split(['?', '#']).next().unwrap_or("");
    // Only origin-form targets ("/..."): absolute-form URLs and "*" are for proxies.
    let rest = path.strip_prefix('/').ok_or(400u16)?;
    let bytes = rest.as_bytes();
    let mut decoded = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes.get(i + 1..i + 3).ok_or(400u16)?;
            let hex = std::str::from_utf8(hex).map_err(|_| 400u16)?;
            decoded.push(u8::from_str_radix(hex, 16).map_err(|_| 400u16)?);
            i += 3;
        } else {
            decoded.push(bytes[i]);
            i += 1;
        }
    }
    let decoded = String::from_utf8(decoded).map_err(|_| 400u16)?;
    if decoded.is_empty() {
        return Ok(Vec::new());
    }
    // A trailing slash asks for a directory: checked like the rest, then answered 404 (no listings).
    let (body, is_dir) = match decoded.strip_suffix('/') {
        Some(body) => (body, true),
        None => (decoded.as_str(), false),
    };
    let mut segments = Vec::new();
    for seg in body.split('/') {
        if seg.is_empty() || seg == "." || seg == ".." || seg.contains(['\\', '\0', ':']) {
            return Err(403);
        }
        segments.push(seg.to_owned());
    }
    if is_dir {
        return Err(404);
    }
    Ok(segments)
}

/// The Content-Type for a file name.
fn content_type(path: &Path) -> &'static str {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    match ext.as_str() {
        "html" | "htm" => "text/html; charset=utf-8",
        "js" | "mjs" => "text/javascript; charset=utf-8",
        "css" => "text/css; charset=utf-8",
        "json" | "map" => "application/json",
        "geojson" => "application/geo+json",
        "csv" => "text/csv; charset=utf-8",
        "txt" | "md" => "text/plain; charset=utf-8",
        "svg" => "image/svg+xml",
        "png" => "image/png",
        "wasm" => "application/wasm",
        // ply, bin, laz and anything unknown: raw bytes.
        _ => "application/octet-stream",
    }
}

/// Read one request head and answer it; every response closes the connection.
fn handle(stream: &mut TcpStream, roots: &Roots, loopback_only: bool) -> io::Result<()> {
    let Some(head) = read_head(stream)? else {
        return respond_error(stream, 431, "request head too large", false);
    };
    let Ok(head) = std::str::from_utf8(&head) else {
        return respond_error(stream, 400, "bad request", false);
    };
    let mut lines = head.split("\r\n");
    let request_line = lines.next().unwrap_or("");
    let mut parts = request_line.split(' ');
    let (Some(method), Some(target), Some(version), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return respond_error(stream, 400, "bad request", false);
    };
    if !version.starts_with("HTTP/1.") {
        return respond_error(stream, 505, "HTTP version not supported", false);
    }
    let head_only = match method {
        "GET" => false,
        "HEAD" => true,
        _ => return respond_error(stream, 405, "method not allowed", false),
    };
    if loopback_only {
        let host = lines
            .filter_map(|l| l.split_once(':'))
            .find(|(name, _)| name.trim().eq_ignore_ascii_case("host"))
            .map(|(_, value)| value.trim());
        if let Some(host) = host {
            if !is_loopback_host(host) {
                return respond_error(stream, 403, "host not allowed", head_only);
            }
        }
    }
    let file = match decode_path(target).and_then(|segments| roots.resolve(&segments)) {
        Ok(file) => file,
        Err(code) => return respond_error(stream, code, reason(code), head_only),
    };
    let mut f = match std::fs::File::open(&file) {
        Ok(f) => f,
        Err(_) => return respond_error(stream, 404, "not found", head_only),
    };
    let len = f.metadata()?.len();
    write!(
        stream,
        "HTTP/1.1 200 OK\r\nContent-Type: {}\r\nContent-Length: {len}\r\n\
         Cache-Control: no-cache\r\nX-Content-Type-Options: nosniff\r\n\
         Server: talus\r\nConnection: close\r\n\r\n",
        content_type(&file)
    )?;
    if !head_only {
        // std turns File -> TcpStream copies into sendfile/splice on Linux.
        io::copy(&mut f, stream)?;
    }
    Ok(())
}

/// Half-close and read what the client still sends (a request body we did not want), so the
/// kernel does not answer unread bytes with a reset that could destroy the response in flight.
fn drain_and_close(stream: &mut TcpStream) {
    let _ = stream.shutdown(std::net::Shutdown::Write);
    let _ = stream.set_read_timeout(Some(Duration::from_millis(500)));
    let mut buf = [0u8; 4096];
    let mut left: usize = 64 * 1024;
    while left > 0 {
        match stream.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => left = left.saturating_sub(n),
        }
    }
}

/// Bytes up to and including the blank line that ends the head; `None` when it is too long.
fn read_head(stream: &mut TcpStream) -> io::Result<Option<Vec<u8>>> {
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 2048];
    loop {
        let n = stream.read(&mut buf)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        head.extend_from_slice(&buf[..n]);
        if let Some(end) = head.windows(4).position(|w| w == b"\r\n\r\n") {
            head.truncate(end);
            return Ok(Some(head));
        }
        if head.len() > MAX_HEAD_BYTES {
            return Ok(None);
        }
    }
}

/// Whether a `Host` header value names this machine (`localhost`, `127.x.y.z`, `[::1]`).
fn is_loopback_host(host: &str) -> bool {
    let name = if let Some(v6) = host.strip_prefix('[') {
        v6.split(']').next().unwrap_or("")
    } else {
        host.rsplit_once(':').map_or(host, |(name, _)| name)
    };
    name.eq_ignore_ascii_case("localhost")
        || name.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

fn reason(code: u16) -> &'static str {
    match code {
        400 => "bad request",
        403 => "forbidden",
        404 => "not found",
        405 => "method not allowed",
        _ => "error",
    }
}

fn respond_error(stream: &mut TcpStream, code: u16, text: &str, head_only: bool) -> io::Result<()> {
    let allow = if code == 405 {
        "Allow: GET, HEAD\r\n"
    } else {
        ""
    };
    let body = format!("{code} {text}\n");
    write!(
        stream,
        "HTTP/1.1 {code} {text}\r\nContent-Type: text/plain; charset=utf-8\r\n\
         Content-Length: {}\r\n{allow}Server: talus\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    if !head_only {
        stream.write_all(body.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decoding_refuses_traversal_in_every_spelling() {
        for raw in [
            "/data/../x",
            "/data/%2e%2e/x",
            "/data/%2E%2E/x",
            "/..%2f..%2fetc/passwd",
            "/data/.%2e/x",
            "/data//etc/passwd",
            "/data/%2fetc/passwd",
            "/data/..\\x",
            "/data/a%5c..%5cb",
            "/data/./x",
            "/data/C:/x",
        ] {
            assert_eq!(decode_path(raw), Err(403), "{raw}");
        }
        assert_eq!(decode_path("http://h/x"), Err(400));
        assert_eq!(decode_path("/data/%zz"), Err(400));
        assert_eq!(decode_path("/data/%2"), Err(400));
        assert_eq!(decode_path("/data/../"), Err(403));
        assert_eq!(decode_path("/data/"), Err(404));
        assert_eq!(decode_path("/data/%ff"), Err(400));
    }

    #[test]
    fn decoding_keeps_ordinary_names() {
        assert_eq!(decode_path("/"), Ok(vec![]));
        assert_eq!(
            decode_path("/data/meshes/event%200001.ply?x=1#f"),
            Ok(vec![
                "data".into(),
                "meshes".into(),
                "event 0001.ply".into()
            ])
        );
    }

    #[test]
    fn loopback_host_names() {
        for ok in [
            "127.0.0.1:8080",
            "localhost",
            "LOCALHOST:1",
            "[::1]:80",
            "127.1.2.3",
        ] {
            assert!(is_loopback_host(ok), "{ok}");
        }
        for bad in ["evil.example:8080", "10.0.0.1", "[2001:db8::1]:80", ""] {
            assert!(!is_loopback_host(bad), "{bad}");
        }
    }

    #[test]
    fn content_types_by_extension() {
        assert_eq!(
            content_type(Path::new("a.js")),
            "text/javascript; charset=utf-8"
        );
        assert_eq!(content_type(Path::new("view.json")), "application/json");
        assert_eq!(content_type(Path::new("t.bin")), "application/octet-stream");
        assert_eq!(content_type(Path::new("m.PLY")), "application/octet-stream");
        assert_eq!(
            content_type(Path::new("index.html")),
            "text/html; charset=utf-8"
        );
    }
}
