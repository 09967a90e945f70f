//! Web viewer server: a small, read-only HTTP/1.1 file server for `talus view DIR`.
//!
//! It serves the static viewer (`index.html`, `src/`, and the vendored three.js files under
//! `vendor/three/`: `build/`, `examples/jsm/` and its `LICENSE`) plus the files of one comparison
//! result directory under `/data/`. The viewer's files are built into the binary (build.rs), so a
//! copied or `cargo install`ed `talus` serves them with no source tree and no `node_modules`;
//! `TALUS_VIEWER_DIR` makes it serve a `viewer/` directory from disk instead (for working on the
//! page). The browser does all the rendering; the server never writes anything and never lists
//! directories.
//!
//! Why hand-written on `std::net` rather than a web framework: the whole job is "GET a file",
//! the dependency tree stays small, and the security-relevant part (mapping a URL to a file
//! without escaping its root, RFC 3986 §2.1 percent-decoding, RFC 9110 methods and status codes)
//! is short enough to be read in one sitting. Each request path is percent-decoded *before* it
//! is split into segments, so `%2e%2e` and `%2f` cannot smuggle `..` or an absolute path past
//! the checks; then the joined file path is canonicalized and must still lie under its root,
//! which also stops symlinks that point outside. Nothing whose name starts with a dot is served
//! (`.talus/` is the result's work area: tiles and internal files), also not through a symlink.
//!
//! When bound to a loopback address, requests whose `Host` header is not a loopback name are
//! refused: that blocks DNS-rebinding pages from reading the result through the user's browser.
//! Bound to any other address, the server says on stderr that the network can read the result.
//!
//! Slow clients: a connection has [`HEAD_DEADLINE`] in total to send its request head (not per
//! read, so trickling a byte at a time does not extend it), and when all [`MAX_CONNECTIONS`]
//! are taken, a new connection takes the place of the one that has been sending its head the
//! longest. A crowd of trickling connections therefore cannot lock out a client that sends its
//! request at once.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};

/// Where `talus view` listens unless told otherwise: this machine only.
pub const DEFAULT_BIND: IpAddr = IpAddr::V4(std::net::Ipv4Addr::LOCALHOST);

/// At most this many connections are served at once; more get `503` right away unless one
/// still sending its head can be dropped. A browser opens about six per host, so this leaves
/// room for a few tabs without letting a client exhaust threads.
pub const MAX_CONNECTIONS: usize = 32;

/// Largest request head (request line + headers) we read; GET requests have no body.
const MAX_HEAD_BYTES: usize = 16 * 1024;

/// The whole request head must arrive within this time of the connection being accepted.
pub const HEAD_DEADLINE: Duration = Duration::from_secs(5);

/// A client that stops reading the response for this long is dropped.
const IO_TIMEOUT: Duration = Duration::from_secs(15);

/// The viewer's files built into the binary: (path relative to `viewer/`, contents).
mod embedded {
    include!(concat!(env!("OUT_DIR"), "/viewer_assets.rs"));
}

/// Where the viewer's static files come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Viewer {
    /// The files built into the binary.
    Embedded,
    /// A `viewer/` directory on disk (index.html, src/, vendor/three/).
    Dir(PathBuf),
}

impl Viewer {
    /// `$TALUS_VIEWER_DIR` when set and not empty (a developer's `viewer/` directory, served
    /// from disk so edits show on reload), else the files built into the binary.
    pub fn from_env() -> Viewer {
        match std::env::var_os("TALUS_VIEWER_DIR") {
            Some(dir) if !dir.is_empty() => Viewer::Dir(PathBuf::from(dir)),
            _ => Viewer::Embedded,
        }
    }
}

/// The directories of a `viewer/` tree that are served, as (URL prefix, path under the tree).
const VIEWER_DIRS: [(&[&str], &str); 3] = [
    (&["src"], "src"),
    (&["vendor", "three", "build"], "vendor/three/build"),
    (
        &["vendor", "three", "examples", "jsm"],
        "vendor/three/examples/jsm",
    ),
];

/// Serve the viewer for the result directory `dir` on `bind:port` until the process ends.
///
/// `port` 0 picks a free port; `on_ready` receives the bound address (print the URL from it)
/// once the socket is listening. Errors: `dir` is not a result directory (no `view.json`), a
/// viewer directory lacks the viewer's files, or the address cannot be bound.
pub fn serve(
    dir: &Path,
    bind: IpAddr,
    port: u16,
    viewer: &Viewer,
    on_ready: impl FnOnce(SocketAddr),
) -> Result<()> {
    let roots = Arc::new(Roots::new(dir, viewer)?);
    let listener = TcpListener::bind((bind, port)).map_err(|e| {
        Error::Usage(format!(
            "cannot listen on {}: {e}",
            SocketAddr::new(bind, port)
        ))
    })?;
    let addr = listener
        .local_addr()
        .map_err(|e| Error::Internal(format!("listening socket has no address: {e}")))?;
    if !bind.is_loopback() {
        eprintln!(
            "talus view: warning: listening on {addr}, not only on this machine: anyone who can \
             reach it on the network can read this result"
        );
    }
    on_ready(addr);

    let active = Arc::new(AtomicUsize::new(0));
    let heads = Arc::new(Mutex::new(Heads::default()));
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
        let _ = stream.set_write_timeout(Some(IO_TIMEOUT));
        if active.load(Ordering::SeqCst) >= MAX_CONNECTIONS && !lock(&heads).drop_oldest() {
            let mut stream = stream;
            let _ = respond_error(&mut stream, 503, "too many connections", false);
            continue;
        }
        let Ok(id) = lock(&heads).add(&stream) else {
            continue;
        };
        active.fetch_add(1, Ordering::SeqCst);
        let guard = ActiveGuard(Arc::clone(&active));
        let roots = Arc::clone(&roots);
        let waiting = Arc::clone(&heads);
        let spawned = std::thread::Builder::new()
            .name("talus-view".into())
            .spawn(move || {
                let _guard = guard;
                let mut stream = stream;
                let head = read_head(&mut stream, Instant::now() + HEAD_DEADLINE);
                lock(&waiting).remove(id);
                // A client that goes away mid-response is its own business.
                let _ = handle(&mut stream, head, &roots, loopback_only);
                let _ = stream.flush();
                drain_and_close(&mut stream);
            });
        // If no thread could be made, the closure (and its guard) is dropped: the count recovers.
        if spawned.is_err() {
            lock(&heads).remove(id);
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    Ok(())
}

/// The connections still sending their request head, oldest first (a handle on each, to drop
/// it when a new connection needs its place).
#[derive(Default)]
struct Heads {
    next_id: u64,
    waiting: VecDeque<(u64, TcpStream)>,
}

impl Heads {
    fn add(&mut self, stream: &TcpStream) -> io::Result<u64> {
        let id = self.next_id;
        self.next_id += 1;
        self.waiting.push_back((id, stream.try_clone()?));
        Ok(id)
    }

    fn remove(&mut self, id: u64) {
        self.waiting.retain(|(i, _)| *i != id);
    }

    /// Shut the oldest waiting connection down (its thread's read returns at once and the
    /// thread ends); false when none is waiting.
    fn drop_oldest(&mut self) -> bool {
        match self.waiting.pop_front() {
            Some((_, s)) => {
                let _ = s.shutdown(std::net::Shutdown::Both);
                true
            }
            None => false,
        }
    }
}

/// The lock, also after a panic elsewhere (the list stays usable).
fn lock(heads: &Mutex<Heads>) -> std::sync::MutexGuard<'_, Heads> {
    heads.lock().unwrap_or_else(|e| e.into_inner())
}

/// Decrements the active-connection count when a connection thread ends (even by panic).
struct ActiveGuard(Arc<AtomicUsize>);

impl Drop for ActiveGuard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// A file to send: built into the binary, or on disk.
enum Body {
    /// A built-in file: its path under `viewer/` and its bytes.
    Static(&'static str, &'static [u8]),
    File(PathBuf),
}

/// Where files may come from: the viewer (built in, or canonical directories of a viewer tree)
/// and the canonical result directory.
struct Roots {
    viewer: ViewerRoots,
    data: PathBuf,
}

enum ViewerRoots {
    Embedded,
    /// index.html and the [`VIEWER_DIRS`], canonical.
    Dir {
        index: PathBuf,
        dirs: Vec<PathBuf>,
    },
}

impl Roots {
    fn new(dir: &Path, viewer: &Viewer) -> Result<Roots> {
        let data = dir
            .canonicalize()
            .map_err(|e| Error::input(dir, format!("cannot open result directory: {e}")))?;
        if !data.join("view.json").is_file() {
            return Err(Error::input(
                dir,
                "not a talus result directory (no view.json); run `talus compare` first",
            ));
        }
        let viewer = match viewer {
            Viewer::Embedded => ViewerRoots::Embedded,
            Viewer::Dir(root) => {
                let canon = |rel: &str| {
                    root.join(rel).canonicalize().map_err(|_| {
                        Error::input(
                            root,
                            format!(
                                "viewer files not found ({rel} is missing): TALUS_VIEWER_DIR \
                                 must name the talus `viewer/` directory"
                            ),
                        )
                    })
                };
                let index = canon("index.html")?;
                canon("vendor/three/build/three.module.js")?;
                let dirs = VIEWER_DIRS
                    .iter()
                    .map(|(_, rel)| canon(rel))
                    .collect::<Result<_>>()?;
                ViewerRoots::Dir { index, dirs }
            }
        };
        Ok(Roots { viewer, data })
    }

    /// What a decoded, validated path maps to, or the status code to answer with.
    fn resolve(&self, segments: &[String]) -> std::result::Result<Body, u16> {
        let s: Vec<&str> = segments.iter().map(String::as_str).collect();
        if s.iter().any(|seg| seg.starts_with('.')) {
            return Err(404); // dotfiles and dot-directories (.talus/) are never served
        }
        if let ["data", rest @ ..] = s.as_slice() {
            return under(&self.data, rest).map(Body::File);
        }
        let s = match s.as_slice() {
            [] => vec!["index.html"],
            _ => s,
        };
        match &self.viewer {
            ViewerRoots::Embedded => {
                let path = s.join("/");
                let served = path == "index.html"
                    || path == "vendor/three/LICENSE"
                    || VIEWER_DIRS
                        .iter()
                        .any(|(prefix, _)| s.len() > prefix.len() && s.starts_with(prefix));
                embedded::ASSETS
                    .iter()
                    .find(|(p, _)| served && *p == path)
                    .map(|(p, bytes)| Body::Static(p, bytes))
                    .ok_or(404)
            }
            ViewerRoots::Dir { index, dirs } => {
                if s == ["index.html"] {
                    return Ok(Body::File(index.clone()));
                }
                VIEWER_DIRS
                    .iter()
                    .zip(dirs)
                    .find(|((prefix, _), _)| s.starts_with(prefix))
                    .map_or(Err(404), |((prefix, _), root)| {
                        under(root, &s[prefix.len()..]).map(Body::File)
                    })
            }
        }
    }
}

/// `root/rest...` if that is a regular file whose canonical path is still inside `root` and
/// passes through no dot-directory there.
fn under(root: &Path, rest: &[&str]) -> std::result::Result<PathBuf, u16> {
    if rest.is_empty() {
        return Err(404); // a directory: no listings
    }
    let mut path = root.to_path_buf();
    path.extend(rest);
    let canonical = path.canonicalize().map_err(|_| 404u16)?;
    // Symlinks are followed by canonicalize; one pointing outside the root lands here.
    let Ok(inside) = canonical.strip_prefix(root) else {
        return Err(403);
    };
    // ... and one pointing into `.talus/` here.
    if inside
        .iter()
        .any(|c| c.to_str().is_none_or(|c| c.starts_with('.')))
    {
        return Err(404);
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

/// Answer one request whose head was read (or not: too long, too slow, gone); every response
/// closes the connection.
fn handle(
    stream: &mut TcpStream,
    head: io::Result<Option<Vec<u8>>>,
    roots: &Roots,
    loopback_only: bool,
) -> io::Result<()> {
    let head = match head {
        Ok(Some(head)) => head,
        Ok(None) => return respond_error(stream, 431, "request head too large", false),
        Err(e)
            if matches!(
                e.kind(),
                io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
            ) =>
        {
            return respond_error(stream, 408, "request timeout", false)
        }
        Err(e) => return Err(e),
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
    let body = match decode_path(target).and_then(|segments| roots.resolve(&segments)) {
        Ok(body) => body,
        Err(code) => return respond_error(stream, code, reason(code), head_only),
    };
    let (name, len, file) = match body {
        Body::Static(name, bytes) => (PathBuf::from(name), bytes.len() as u64, Err(bytes)),
        Body::File(path) => match std::fs::File::open(&path) {
            Ok(f) => {
                let len = f.metadata()?.len();
                (path, len, Ok(f))
            }
            Err(_) => return respond_error(stream, 404, "not found", head_only),
        },
    };
    write!(
        stream,
        "HTTP/1.1 200 OK\r\nContent-Type: {}\r\nContent-Length: {len}\r\n\
         Cache-Control: no-cache\r\nX-Content-Type-Options: nosniff\r\n\
         Server: talus\r\nConnection: close\r\n\r\n",
        content_type(&name)
    )?;
    if !head_only {
        match file {
            // std turns File -> TcpStream copies into sendfile/splice on Linux.
            Ok(mut f) => {
                io::copy(&mut f, stream)?;
            }
            Err(bytes) => stream.write_all(bytes)?,
        }
    }
    Ok(())
}

/// Half-close and read what the client still sends (a request body we did not want), so the
/// kernel does not answer unread bytes with a reset that could destroy the response in flight.
/// At most 64 KiB and half a second in total: a client trickling bytes cannot keep it open.
fn drain_and_close(stream: &mut TcpStream) {
    let _ = stream.shutdown(std::net::Shutdown::Write);
    let deadline = Instant::now() + Duration::from_millis(500);
    let mut buf = [0u8; 4096];
    let mut left: usize = 64 * 1024;
    while left > 0 {
        let wait = deadline.saturating_duration_since(Instant::now());
        if wait.is_zero() || stream.set_read_timeout(Some(wait)).is_err() {
            break;
        }
        match stream.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => left = left.saturating_sub(n),
        }
    }
}

/// Bytes up to and including the blank line that ends the head; `None` when it is too long;
/// a `TimedOut` error when it is not all there by `deadline`.
fn read_head(stream: &mut TcpStream, deadline: Instant) -> io::Result<Option<Vec<u8>>> {
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 2048];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::ErrorKind::TimedOut.into());
        }
        stream.set_read_timeout(Some(left))?;
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
        408 => "request timeout",
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
