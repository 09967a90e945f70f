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
        &viewer.join("node_modules/three/build/three.module.js"),
        b"export const REVISION = '0';\n",
    );
    write(
        &viewer.join("node_modules/three/examples/jsm/controls/OrbitControls.js"),
        b"export class OrbitControls {}\n",
    );
    // In node_modules/three but outside the two served directories.
    write(
        &viewer.join("node_modules/three/package.json"),
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
    let viewer_root = viewer.clone();
    std::thread::spawn(move || {
        let result = talus::view::serve(
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
            "/node_modules/three/build/three.module.js",
            "text/javascript",
            b"export const REVISION = '0';\n",
        ),
        (
            "/node_modules/three/examples/jsm/controls/OrbitControls.js",
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
        "/node_modules/../../x",
        "/node_modules/three/build/../../other/index.js",
        "/node_modules/three/build/%2e%2e/%2e%2e/other/index.js",
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
        "/node_modules/three/package.json",
        "/node_modules/other/index.js",
        "/node_modules/three/examples/jsm/controls", // a directory: no listing
        "/data/meshes",
        "/data/",
        "/src/",
        "/Cargo.toml",
    ] {
        let r = get(f.addr, target);
        assert_eq!(r.status, 404, "{target}");
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
    let dir = tmp.path().join("result");
    write(&dir.join("view.json"), b"{}");
    let lo = IpAddr::V4(Ipv4Addr::LOCALHOST);

    let err = talus::view::serve(&dir, lo, 0, &viewer, |_| panic!("must not start")).unwrap_err();
    assert!(err.to_string().contains("npm ci"), "{err}");
    assert_eq!(err.exit_code(), 2);

    let not_result = tmp.path().join("empty");
    std::fs::create_dir_all(&not_result).unwrap();
    let err =
        talus::view::serve(&not_result, lo, 0, &viewer, |_| panic!("must not start")).unwrap_err();
    assert!(err.to_string().contains("view.json"), "{err}");
    assert!(matches!(err, talus::Error::Input { .. }));
}
