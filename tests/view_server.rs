//! The viewer's HTTP server, driven with raw requests over a TcpStream: it serves exactly the
//! files it should, byte for byte and with the right Content-Type, and refuses every path
//! traversal spelling, other methods and foreign Host headers.

use std::io::{Read, Write};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpStream};
use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

/// A fake viewer tree, a result directory and a secret next to it (outside every served root).
struct Fixture {
    _tmp: tempfile::TempDir,
    addr: SocketAddr,
    terrain: Vec<u8>,
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

fn start() -> Fixture {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let viewer = root.join("viewer");
    write(
        &viewer.join("index.html"),
        b"<!doctype html><title>talus</title>",
    );
    write(&viewer.join("src/main.js"), b"export const x = 1;\n");
    write(&viewer.join("src/style.css"), b"body{}\n");
    write(
        &viewer.join("vendor/three/build/three.module.js"),
        b"export const REVISION = '0';\n",
    );
    write(
        &viewer.join("vendor/three/examples/jsm/controls/OrbitControls.js"),
        b"export class OrbitControls {}\n",
    );
    // In vendor/three but outside the two served directories.
    write(
        &viewer.join("vendor/three/package.json"),
        b"{\"name\":\"three\"}",
    );
    write(
        &viewer.join("node_modules/other/index.js"),
        b"secret-module",
    );
    write(&viewer.join("Cargo.toml"), b"secret-cargo");

    let dir = root.join("result");
    write(&dir.join("view.json"), br#"{"version":1,"points":2}"#);
    write(
        &dir.join("events.geojson"),
        br#"{"type":"FeatureCollection","features":[]}"#,
    );
    // 2 points: binary content with every byte value class, to catch any text mangling.
    let terrain: Vec<u8> = (0..32u8)
        .map(|i| i.wrapping_mul(37).wrapping_add(200))
        .collect();
    write(&dir.join("terrain.bin"), &terrain);
    // Far more than the socket buffers between server and client hold.
    write(&dir.join("big.laz"), &vec![7u8; 16 << 20]);
    write(
        &dir.join("meshes/event_0001_before.ply"),
        b"ply\nformat binary_little_endian 1.0\n",
    );
    write(&root.join("secret"), b"top-secret");
    write(&root.join("x"), b"top-secret-x");
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink(root.join("secret"), dir.join("escape")).unwrap();
        std::os::unix::fs::symlink(dir.join("view.json"), dir.join("inside.json")).unwrap();
    }

    let (tx, rx) = mpsc::channel();
    let viewer_root = talus::commands::view::Viewer::Dir(viewer.clone());
    std::thread::spawn(move || {
        let result = talus::commands::view::serve(
            &dir,
            IpAddr::V4(Ipv4Addr::LOCALHOST),
            0,
            &viewer_root,
            |addr| tx.send(addr).unwrap(),
        );
        panic!("serve returned: {result:?}");
    });
    let addr = rx
        .recv_timeout(Duration::from_secs(20))
        .expect("server ready");
    Fixture {
        _tmp: tmp,
        addr,
        terrain,
    }
}

struct Response {
    status: u16,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Response {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

/// Send `raw` as is and parse the whole response (the server closes after each one).
fn raw_request(addr: SocketAddr, raw: &str) -> Response {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    s.write_all(raw.as_bytes()).unwrap();
    let mut bytes = Vec::new();
    s.read_to_end(&mut bytes).unwrap();
    let end = bytes
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("response head");
    let head = String::from_utf8(bytes[..end].to_vec()).unwrap();
    let mut lines = head.split("\r\n");
    let status_line = lines.next().unwrap();
    assert!(status_line.starts_with("HTTP/1.1 "), "{status_line}");
    let status = status_line[9..12].parse().unwrap();
    let headers = lines
        .map(|l| {
            let (n, v) = l.split_once(':').unwrap();
            (n.trim().to_owned(), v.trim().to_owned())
        })
        .collect();
    Response {
        status,
        headers,
        body: bytes[end + 4..].to_vec(),
    }
}

fn get(addr: SocketAddr, target: &str) -> Response {
    raw_request(
        addr,
        &format!("GET {target} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"),
    )
}

#[test]
fn serves_viewer_three_and_result_files_with_types() {
    let f = start();
    let cases: [(&str, &str, &[u8]); 7] = [
        ("/", "text/html", b"<!doctype html><title>talus</title>"),
        ("/src/main.js", "text/javascript", b"export const x = 1;\n"),
        ("/src/style.css", "text/css", b"body{}\n"),
        (
            "/vendor/three/build/three.module.js",
            "text/javascript",
            b"export const REVISION = '0';\n",
        ),
        (
            "/vendor/three/examples/jsm/controls/OrbitControls.js",
            "text/javascript",
            b"export class OrbitControls {}\n",
        ),
        (
            "/data/view.json",
            "application/json",
            br#"{"version":1,"points":2}"#,
        ),
        (
            "/data/meshes/event_0001_before.ply",
            "application/octet-stream",
            b"ply\nformat binary_little_endian 1.0\n",
        ),
    ];
    for (target, ctype, body) in cases {
        let r = get(f.addr, target);
        assert_eq!(r.status, 200, "{target}");
        let got = r.header("content-type").unwrap();
        assert!(got.starts_with(ctype), "{target}: {got}");
        assert_eq!(r.body, body, "{target}");
        assert_eq!(
            r.header("content-length"),
            Some(body.len().to_string().as_str())
        );
    }
    let t = get(f.addr, "/data/terrain.bin?cache=1");
    assert_eq!(t.status, 200);
    assert_eq!(t.header("content-type"), Some("application/octet-stream"));
    assert_eq!(t.body, f.terrain);
    let g = get(f.addr, "/data/events.geojson");
    assert_eq!(g.status, 200);
    assert!(g.header("content-type").unwrap().contains("json"));
    // A symlink that stays inside the result directory is fine.
    #[cfg(unix)]
    assert_eq!(
        get(f.addr, "/data/inside.json").body,
        br#"{"version":1,"points":2}"#
    );
}

#[test]
fn head_sends_headers_only() {
    let f = start();
    let r = raw_request(
        f.addr,
        &format!(
            "HEAD /data/terrain.bin HTTP/1.1\r\nHost: {}\r\n\r\n",
            f.addr
        ),
    );
    assert_eq!(r.status, 200);
    assert_eq!(r.header("content-length"), Some("32"));
    assert!(r.body.is_empty());
}

#[test]
fn traversal_attempts_are_refused() {
    let f = start();
    for target in [
        "/data/../Cargo.toml",
        "/data/%2e%2e/secret",
        "/data/%2E%2E/secret",
        "/data/.%2e/secret",
        "/data/..%2fsecret",
        "/..%2f..%2fetc/passwd",
        "/vendor/../../x",
        "/vendor/three/build/../../../node_modules/other/index.js",
        "/vendor/three/build/%2e%2e/%2e%2e/%2e%2e/node_modules/other/index.js",
        "/src/../Cargo.toml",
        "/data//etc/passwd",
        "/data/%2fetc%2fpasswd",
        "//etc/passwd",
        "/etc/passwd",
        "/data/..\\secret",
        "http://127.0.0.1/data/../secret",
        "/data/escape",
    ] {
        let r = get(f.addr, target);
        assert!(
            matches!(r.status, 400 | 403 | 404),
            "{target}: status {}",
            r.status
        );
        let body = String::from_utf8_lossy(&r.body);
        assert!(!body.contains("secret"), "{target}: {body}");
        assert!(!body.contains("root:"), "{target}: {body}");
    }
}

#[test]
fn only_the_two_three_directories_are_served() {
    let f = start();
    for target in [
        "/vendor/three/package.json",
        "/node_modules/other/index.js",
        "/vendor/three/examples/jsm/controls", // a directory: no listing
        "/data/meshes",
        "/data/",
        "/src/",
        "/Cargo.toml",
    ] {
        assert_eq!(get(f.addr, target).status, 404, "{target}");
    }
}

#[test]
fn other_methods_get_405() {
    let f = start();
    for method in ["POST", "PUT", "DELETE", "OPTIONS"] {
        let r = raw_request(
            f.addr,
            &format!(
                "{method} /data/view.json HTTP/1.1\r\nHost: {}\r\nContent-Length: 5\r\n\r\nhello",
                f.addr
            ),
        );
        assert_eq!(r.status, 405, "{method}");
        assert_eq!(r.header("allow"), Some("GET, HEAD"));
    }
}

#[test]
fn foreign_host_headers_are_refused_on_loopback() {
    let f = start();
    let r = raw_request(
        f.addr,
        "GET /data/view.json HTTP/1.1\r\nHost: attacker.example\r\n\r\n",
    );
    assert_eq!(r.status, 403);
    let r = raw_request(
        f.addr,
        "GET /data/view.json HTTP/1.1\r\nHost: localhost:1234\r\n\r\n",
    );
    assert_eq!(r.status, 200);
}

#[test]
fn serve_reports_missing_viewer_files_and_non_result_dirs() {
    let tmp = tempfile::tempdir().unwrap();
    let viewer = tmp.path().join("viewer");
    write(&viewer.join("index.html"), b"x");
    std::fs::create_dir_all(viewer.join("src")).unwrap();
    let viewer = talus::commands::view::Viewer::Dir(viewer);
    let dir = tmp.path().join("result");
    write(&dir.join("view.json"), b"{}");
    let lo = IpAddr::V4(Ipv4Addr::LOCALHOST);

    let err = talus::commands::view::serve(&dir, lo, 0, &viewer, |_| panic!("must not start"))
        .unwrap_err();
    assert!(
        err.to_string()
            .contains("vendor/three/build/three.module.js is missing"),
        "{err}"
    );
    assert_eq!(err.exit_code(), 2);

    let not_result = tmp.path().join("empty");
    std::fs::create_dir_all(&not_result).unwrap();
    let err =
        talus::commands::view::serve(&not_result, lo, 0, &viewer, |_| panic!("must not start"))
            .unwrap_err();
    assert!(err.to_string().contains("view.json"), "{err}");
    assert!(matches!(err, talus::Error::Input { .. }));
}

#[test]
fn dotfiles_and_the_work_area_are_never_served() {
    let f = start();
    let data = f._tmp.path().join("result");
    write(&data.join(".talus/tiles/before/t_0001_0001.tile"), b"tile");
    write(&data.join(".talus/manifest.json"), b"{}");
    write(&data.join(".hidden"), b"hidden");
    write(&f._tmp.path().join("viewer/src/.env"), b"secret");
    #[cfg(unix)]
    std::os::unix::fs::symlink(data.join(".talus"), data.join("work")).unwrap();
    for target in [
        "/data/.talus/manifest.json",
        "/data/.talus/tiles/before/t_0001_0001.tile",
        "/data/%2etalus/manifest.json",
        "/data/.hidden",
        "/src/.env",
        "/data/work/manifest.json",
    ] {
        assert_eq!(get(f.addr, target).status, 404, "{target}");
    }
    assert_eq!(get(f.addr, "/data/view.json").status, 200);
}

/// Open a connection that sends a request head one byte at a time, one byte per `every`, in a
/// thread of its own, until the server closes it; returns when it was closed.
fn trickle(
    addr: SocketAddr,
    every: Duration,
) -> std::thread::JoinHandle<Option<std::time::Instant>> {
    let mut s = TcpStream::connect(addr).unwrap();
    std::thread::spawn(move || {
        let head = b"GET /data/view.json HTTP/1.1\r\nHost: localhost\r\nX-Padding: ";
        for byte in head.iter().chain(std::iter::repeat(&b'x')).take(200) {
            if s.write_all(&[*byte]).is_err() {
                return Some(std::time::Instant::now());
            }
            std::thread::sleep(every);
        }
        None
    })
}

/// A client that sends its request at once gets view.json within 2 s.
fn served_at_once(addr: SocketAddr) {
    let asked = std::time::Instant::now();
    let r = get(addr, "/data/view.json");
    assert_eq!(r.status, 200);
    assert!(
        asked.elapsed() < Duration::from_secs(2),
        "served after {:?}",
        asked.elapsed()
    );
}

#[test]
fn trickling_clients_cannot_lock_others_out() {
    let f = start();
    let t0 = std::time::Instant::now();
    // More slow clients than the server serves at once, each still sending its head.
    let slow: Vec<_> = (0..40)
        .map(|_| trickle(f.addr, Duration::from_millis(500)))
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    served_at_once(f.addr);
    // The head has a deadline in total, not per read: every trickler is closed within it (or
    // sooner, when its place was taken), however steadily it sends.
    for h in slow {
        let closed = h
            .join()
            .unwrap()
            .expect("the server closed the slow client");
        let after = closed - t0;
        assert!(
            after < talus::commands::view::HEAD_DEADLINE + Duration::from_secs(3),
            "closed after {after:?}"
        );
    }
}

/// Open a connection that asks for the 16 MiB `big.laz` and then reads its response slowly (8
/// KiB every 300 ms: the server's writes keep progressing, never long enough stuck to time
/// out), in a thread of its own, until the server closes it or `stop` is set; returns whether
/// the server closed it.
fn slow_reader(
    addr: SocketAddr,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<bool> {
    let mut s = TcpStream::connect(addr).unwrap();
    s.write_all(format!("GET /data/big.laz HTTP/1.1\r\nHost: {addr}\r\n\r\n").as_bytes())
        .unwrap();
    std::thread::spawn(move || {
        let mut buf = [0u8; 8192];
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        while !stop.load(std::sync::atomic::Ordering::SeqCst) {
            match s.read(&mut buf) {
                Ok(0) | Err(_) => return true,
                Ok(_) => std::thread::sleep(Duration::from_millis(300)),
            }
        }
        false
    })
}

#[test]
fn slow_response_readers_cannot_lock_others_out() {
    let f = start();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    // More slow readers than the server serves at once, each with its response under way.
    let slow: Vec<_> = (0..40).map(|_| slow_reader(f.addr, stop.clone())).collect();
    std::thread::sleep(Duration::from_millis(1500));
    for _ in 0..3 {
        served_at_once(f.addr);
    }
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    let closed = slow
        .into_iter()
        .map(|h| h.join().unwrap())
        .filter(|&c| c)
        .count();
    assert!(closed >= 3, "{closed} slow readers were dropped");
}

/// A result directory the viewer accepts (view.json and the files the page loads).
fn tiny_result(dir: &Path) {
    write(&dir.join("view.json"), br#"{"version":1,"points":0}"#);
    write(
        &dir.join("events.geojson"),
        br#"{"type":"FeatureCollection","features":[]}"#,
    );
}

/// Run `talus view DIR --port 0 EXTRA...` from `exe`; returns the child, its address and its
/// stderr reader.
fn spawn_view(
    exe: &Path,
    cwd: &Path,
    dir: &Path,
    extra: &[&str],
) -> (std::process::Child, SocketAddr) {
    use std::io::BufRead;
    let mut child = std::process::Command::new(exe)
        .current_dir(cwd)
        .env_remove("TALUS_VIEWER_DIR")
        .arg("view")
        .arg(dir)
        .args(["--port", "0"])
        .args(extra)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .split_whitespace()
        .find(|w| w.starts_with("http://"))
        .unwrap_or_else(|| panic!("no URL in {line:?}"));
    let hostport = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_owned();
    let port: u16 = hostport.rsplit(':').next().unwrap().parse().unwrap();
    (child, SocketAddr::from((Ipv4Addr::LOCALHOST, port)))
}

#[test]
fn the_binary_alone_serves_the_built_in_viewer() {
    // A copy of the binary in a directory with no source tree beside it, as after
    // `cargo install` or a copy to another machine.
    let tmp = tempfile::tempdir().unwrap();
    let exe = tmp.path().join("bin/talus");
    std::fs::create_dir_all(exe.parent().unwrap()).unwrap();
    std::fs::copy(env!("CARGO_BIN_EXE_talus"), &exe).unwrap();
    let result = tmp.path().join("result");
    tiny_result(&result);
    let (mut child, addr) = spawn_view(&exe, tmp.path(), &result, &[]);
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("viewer");
    for (target, file, ctype) in [
        ("/", "index.html", "text/html"),
        ("/src/main.js", "src/main.js", "text/javascript"),
        ("/src/style.css", "src/style.css", "text/css"),
        (
            "/vendor/three/build/three.module.js",
            "vendor/three/build/three.module.js",
            "text/javascript",
        ),
        (
            "/vendor/three/build/three.core.js",
            "vendor/three/build/three.core.js",
            "text/javascript",
        ),
        (
            "/vendor/three/examples/jsm/controls/OrbitControls.js",
            "vendor/three/examples/jsm/controls/OrbitControls.js",
            "text/javascript",
        ),
    ] {
        let r = get(addr, target);
        assert_eq!(r.status, 200, "{target}");
        assert!(
            r.header("content-type").unwrap().starts_with(ctype),
            "{target}"
        );
        assert!(
            r.body == std::fs::read(repo.join(file)).unwrap(),
            "{target} differs from viewer/{file}"
        );
    }
    assert_eq!(get(addr, "/data/view.json").status, 200);
    for target in ["/vendor/three/package.json", "/build.rs", "/vendor/three/"] {
        assert_eq!(get(addr, target).status, 404, "{target}");
    }
    child.kill().unwrap();
    child.wait().unwrap();
}

/// `talus view` (the built binary) on a tiny result in a new temporary directory, serving.
fn tiny_view(extra: &[&str]) -> (tempfile::TempDir, std::process::Child, SocketAddr) {
    let tmp = tempfile::tempdir().unwrap();
    let result = tmp.path().join("result");
    tiny_result(&result);
    let exe = Path::new(env!("CARGO_BIN_EXE_talus"));
    let (child, addr) = spawn_view(exe, tmp.path(), &result, extra);
    assert_eq!(get(addr, "/data/view.json").status, 200);
    (tmp, child, addr)
}

#[test]
fn binding_beyond_loopback_warns() {
    for (bind, warns) in [("0.0.0.0", true), ("127.0.0.1", false)] {
        let (_tmp, mut child, _) = tiny_view(&["--bind", bind]);
        child.kill().unwrap();
        child.wait().unwrap();
        let mut err = String::new();
        child
            .stderr
            .take()
            .unwrap()
            .read_to_string(&mut err)
            .unwrap();
        assert_eq!(
            err.contains("warning") && err.contains("anyone"),
            warns,
            "--bind {bind}: {err}"
        );
        if warns {
            assert_eq!(err.trim().lines().count(), 1, "{err}");
        }
    }
}

#[test]
fn sigint_and_sigterm_end_talus_view_at_once() {
    // Serving has nothing to resume: one Ctrl-C (or the SIGTERM of a service manager) ends it,
    // not the second one as for the commands that keep finished units.
    use std::os::unix::process::ExitStatusExt;
    for signal in [libc::SIGINT, libc::SIGTERM] {
        let (_tmp, mut child, _) = tiny_view(&[]);
        assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, signal) }, 0);
        let t = std::time::Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if t.elapsed() > Duration::from_secs(5) {
                child.kill().unwrap();
                child.wait().unwrap();
                panic!("talus view still serving 5 s after signal {signal}");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        assert_eq!(status.signal(), Some(signal));
    }
}

#[test]
fn a_campaign_directory_is_served() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("campaign");
    write(&dir.join("campaign.json"), br#"{"pairs":[]}"#);
    tiny_result(&dir.join("pairs/20200101_20200201"));
    let exe = Path::new(env!("CARGO_BIN_EXE_talus"));
    let (mut child, addr) = spawn_view(exe, tmp.path(), &dir, &[]);
    assert_eq!(get(addr, "/data/campaign.json").status, 200);
    assert_eq!(
        get(addr, "/data/pairs/20200101_20200201/view.json").status,
        200
    );
    child.kill().unwrap();
    child.wait().unwrap();
}
