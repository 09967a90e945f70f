//! Web viewer server: a small, read-only HTTP/1.1 file server for `talus view DIR`.
//!
//! It serves the static viewer (`index.html`, `src/`, and the vendored three.js files under
//! `vendor/three/`: `build/`, `examples/jsm/` and its `LICENSE`) plus the files of one comparison
//! or campaign result directory under `/data/`. The viewer's files are built into the binary (build.rs), so a
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
//! read, so trickling a byte at a time does not extend it), and when all `MAX_CONNECTIONS`
//! are taken, a new connection takes the place of the one that has been sending its head the
//! longest, or else of the slowest reader of a response: one under way for `ANSWER_GRACE`
//! that has averaged less than `MIN_RATE`. A crowd of trickling connections, or of
//! connections that read their responses a little at a time (each write progresses, so no
//! write times out), therefore cannot lock out a client that sends its request at once.

use std::io::{self, Read, Write};
use std::net::{IpAddr, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};

/// Where `talus view` listens unless told otherwise: this machine only.
pub const DEFAULT_BIND: IpAddr = IpAddr::V4(std::net::Ipv4Addr::LOCALHOST);

/// At most this many connections are served at once; more get `503` right away unless one
/// still sending its head can be dropped. A browser opens about six per host, so this leaves
/// room for a few tabs without letting a client exhaust threads.
pub(crate) const MAX_CONNECTIONS: usize = 32;

/// Largest request head (request line + headers) we read; GET requests have no body.
const MAX_HEAD_BYTES: usize = 16 * 1024;

/// The whole request head must arrive within this time of the connection being accepted.
pub const HEAD_DEADLINE: Duration = Duration::from_secs(5);

/// A client that stops reading the response for this long is dropped.
const IO_TIMEOUT: Duration = Duration::from_secs(15);

/// When every place is taken, a response under way for this long ...
pub(crate) const ANSWER_GRACE: Duration = Duration::from_secs(1);

/// ... whose client lately read less than this many bytes a second gives its place up. A
/// browser on this machine reads hundreds of MiB/s. "Lately": over the last `RATE_WINDOW`
/// (not since the start: the socket buffers take megabytes at once, whatever the client reads).
pub(crate) const MIN_RATE: f64 = 1024.0 * 1024.0;

/// The window a response's rate is measured over.
const RATE_WINDOW: Duration = Duration::from_millis(250);

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
/// once the socket is listening. Errors: `dir` is not a result directory (no `view.json`, no
/// `campaign.json`), a
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

    let conns = Arc::new(Mutex::new(Conns::default()));
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
        {
            let mut c = lock(&conns);
            if c.list.len() >= MAX_CONNECTIONS && !c.drop_one(Instant::now()) {
                drop(c);
                let mut stream = stream;
                let _ = respond_error(&mut stream, 503, "too many connections", false);
                continue;
            }
        }
        let Ok((id, progress)) = lock(&conns).add(&stream) else {
            continue;
        };
        // Takes the connection off the list when its thread ends (even by panic).
        let guard = ConnGuard(Arc::clone(&conns), id);
        let roots = Arc::clone(&roots);
        let spawned = std::thread::Builder::new()
            .name("talus-view".into())
            .spawn(move || {
                let guard = guard;
                let mut stream = stream;
                let head = read_head(&mut stream, Instant::now() + HEAD_DEADLINE);
                lock(&guard.0).answering(id, Instant::now());
                // A client that goes away mid-response is its own business.
                let mut counted = Counted {
                    stream: &mut stream,
                    progress: &progress,
                };
                let _ = handle(&mut counted, head, &roots, loopback_only);
                let _ = stream.flush();
                drain_and_close(&mut stream);
            });
        // If no thread could be made, the closure (and its guard) is dropped: the place is free.
        if spawned.is_err() {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    Ok(())
}

/// A connection being served.
struct Conn {
    id: u64,
    /// A handle on it, to shut it down when a new connection needs its place.
    stream: TcpStream,
    /// Since when it is being answered (None: still sending its head).
    answering: Option<Instant>,
    progress: Arc<Progress>,
}

/// How a response is going: bytes written, and the rate over the last window (updated by the
/// writes themselves, read by [`Conns::drop_one`]; a torn read of them is harmless).
struct Progress {
    base: Instant,
    sent: AtomicU64,
    /// When the current window started (µs since `base`) and the bytes sent by then.
    window_us: AtomicU64,
    window_bytes: AtomicU64,
    /// Bytes a second over the last complete window (u64::MAX: none yet).
    last_rate: AtomicU64,
    /// When the last write finished (µs since `base`).
    last_us: AtomicU64,
}

impl Progress {
    fn new() -> Progress {
        Progress {
            base: Instant::now(),
            sent: AtomicU64::new(0),
            window_us: AtomicU64::new(0),
            window_bytes: AtomicU64::new(0),
            last_rate: AtomicU64::new(u64::MAX),
            last_us: AtomicU64::new(0),
        }
    }

    fn micros(&self, t: Instant) -> u64 {
        t.saturating_duration_since(self.base).as_micros() as u64
    }

    /// Count `n` bytes written at `now`; roll the window when it is over.
    fn wrote(&self, n: usize, now: Instant) {
        let sent = self.sent.fetch_add(n as u64, Ordering::Relaxed) + n as u64;
        let (t, start) = (self.micros(now), self.window_us.load(Ordering::Relaxed));
        self.last_us.store(t, Ordering::Relaxed);
        let elapsed = t.saturating_sub(start);
        if elapsed >= RATE_WINDOW.as_micros() as u64 {
            let bytes = sent.saturating_sub(self.window_bytes.load(Ordering::Relaxed));
            let rate = bytes as f64 / (elapsed as f64 * 1e-6);
            self.last_rate.store(rate as u64, Ordering::Relaxed);
            self.window_us.store(t, Ordering::Relaxed);
            self.window_bytes.store(sent, Ordering::Relaxed);
        }
    }

    /// Bytes a second lately, at `now`: 0 when no write finished for a window (the client is
    /// not reading; what the socket buffers took at first does not count), else over the last
    /// complete window.
    fn rate(&self, now: Instant) -> f64 {
        let idle = self
            .micros(now)
            .saturating_sub(self.last_us.load(Ordering::Relaxed));
        if idle >= RATE_WINDOW.as_micros() as u64 {
            0.0
        } else {
            self.last_rate.load(Ordering::Relaxed) as f64
        }
    }
}

/// The connections being served, oldest first.
#[derive(Default)]
struct Conns {
    next_id: u64,
    list: Vec<Conn>,
}

impl Conns {
    fn add(&mut self, stream: &TcpStream) -> io::Result<(u64, Arc<Progress>)> {
        let id = self.next_id;
        self.next_id += 1;
        let progress = Arc::new(Progress::new());
        self.list.push(Conn {
            id,
            stream: stream.try_clone()?,
            answering: None,
            progress: Arc::clone(&progress),
        });
        Ok((id, progress))
    }

    fn answering(&mut self, id: u64, now: Instant) {
        if let Some(c) = self.list.iter_mut().find(|c| c.id == id) {
            c.answering = Some(now);
            // The rate of the response, not of the head.
            let t = c.progress.micros(now);
            c.progress.window_us.store(t, Ordering::Relaxed);
            c.progress.last_us.store(t, Ordering::Relaxed);
        }
    }

    fn remove(&mut self, id: u64) {
        self.list.retain(|c| c.id != id);
    }

    /// Shut one connection down to make room (its thread's read or write returns at once and
    /// the thread ends, freeing the place): the oldest still sending its head, else the slowest
    /// reader of a response under way for [`ANSWER_GRACE`] read at less than [`MIN_RATE`]
    /// lately; false when there is none.
    fn drop_one(&mut self, now: Instant) -> bool {
        let rate = |c: &Conn| -> Option<f64> {
            let t = now.saturating_duration_since(c.answering?);
            (t >= ANSWER_GRACE).then(|| c.progress.rate(now))
        };
        let pick = match self.list.iter().position(|c| c.answering.is_none()) {
            Some(i) => Some(i),
            None => self
                .list
                .iter()
                .enumerate()
                .filter_map(|(i, c)| rate(c).filter(|&r| r < MIN_RATE).map(|r| (i, r)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i),
        };
        match pick {
            Some(i) => {
                let c = self.list.remove(i);
                let _ = c.stream.shutdown(std::net::Shutdown::Both);
                true
            }
            None => false,
        }
    }
}

/// The lock, also after a panic elsewhere (the list stays usable).
fn lock(conns: &Mutex<Conns>) -> std::sync::MutexGuard<'_, Conns> {
    conns.lock().unwrap_or_else(|e| e.into_inner())
}

/// Takes connection `.1` off the list when dropped.
struct ConnGuard(Arc<Mutex<Conns>>, u64);

impl Drop for ConnGuard {
    fn drop(&mut self) {
        lock(&self.0).remove(self.1);
    }
}

/// A response stream that counts the bytes written to it.
struct Counted<'a> {
    stream: &'a mut TcpStream,
    progress: &'a Progress,
}

impl Write for Counted<'_> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.stream.write(buf)?;
        self.progress.wrote(n, Instant::now());
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.stream.flush()
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
        // A publish a crash cut short is finished first (as the next run would): the viewer
        // shows a whole set, never half of one.
        // (A campaign's pair folder, pairs/<pair>, is published by its campaign's DIR.)
        if let Some(run) = data.ancestors().take(3).find(|d| d.join(".talus").is_dir()) {
            // Opened for reading: a result on a read-only mount is viewed all the same.
            let store = crate::store::Store::inspect(run)?;
            let ours = crate::exec::publish::any_output;
            if let crate::store::Recovery::Unfinished(why) =
                store.finish_interrupted_publish("talus view", &ours)?
            {
                eprintln!("talus: {}", super::status::unfinished_note(run, &why));
            }
        }
        // A comparison (view.json), or a campaign (campaign.json; each pairs/<label>/ is a
        // comparison the viewer shows one at a time).
        if !data.join("view.json").is_file() && !data.join("campaign.json").is_file() {
            return Err(Error::input(
                dir,
                "not a talus result directory (no view.json or campaign.json); run `talus \
                 compare` or `talus campaign` first",
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
    stream: &mut impl Write,
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
            // Copied through a buffer, not sendfile: the bytes sent are counted (slow readers).
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

fn respond_error(
    stream: &mut impl Write,
    code: u16,
    text: &str,
    head_only: bool,
) -> io::Result<()> {
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

/// `talus view DIR`.
pub(crate) fn command(dir: &Path, bind: IpAddr, port: u16) -> Result<()> {
    // Serving has nothing to resume: Ctrl-C or SIGTERM end it at once.
    crate::interrupt::uninstall();
    serve(dir, bind, port, &Viewer::from_env(), |addr| {
        println!("talus viewer: http://{addr}/");
        use std::io::Write;
        let _ = std::io::stdout().flush();
    })
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
