//! Point-cloud readers (`talus::io::open`) against data and tools we did not write:
//! the real LAS/LAZ data read by laspy (an independent reader) and by las-rs' `Point` API,
//! CloudCompare's text output checked against the LAS it was computed from, and fixtures whose
//! ground truth is the points we generate (text in every header style, PLY in all three
//! encodings with extra properties and faces, LAZ written by las-rs). Every error case must be
//! an `Error::Input` naming the file.

use std::io::Write;
use std::path::{Path, PathBuf};

use talus::io::{self, CloudFormat, Point3};
use talus::Error;

mod common;
use common::laspy::{laspy_python, laspy_read};

// ---------------------------------------------------------------------------------------------
// helpers

/// The real data folder (tests/data).
fn data_dir() -> PathBuf {
    common::data(".")
}

fn f64s(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| match x {
            // Floats come as exact repr strings (see tests/py/read_extra_bytes.py).
            serde_json::Value::String(s) => s.parse().expect("float string"),
            other => other.as_f64().expect("number"),
        })
        .collect()
}

/// Read a whole cloud with small `fill` calls (exercises chunk boundaries).
fn read_small_chunks(path: &Path) -> (io::CloudInfo, Vec<Point3>) {
    let mut r = io::open(path).unwrap_or_else(|e| panic!("open {}: {e}", path.display()));
    let info = r.info().clone();
    let mut all = Vec::new();
    let mut buf = Vec::new();
    loop {
        let n = r.fill(&mut buf, 1000).expect("fill");
        assert_eq!(n, buf.len());
        if n == 0 {
            break;
        }
        assert!(n <= 1000);
        all.extend_from_slice(&buf);
    }
    (info, all)
}

fn bounds_of(points: &[Point3]) -> io::Bounds {
    let mut b = io::Bounds::empty();
    for p in points {
        b.grow(p);
    }
    b
}

/// Points read by las-rs' own `Point` API (a different code path from our column sweep).
fn las_rs_points(path: &Path) -> Vec<Point3> {
    let mut r = las::Reader::from_path(path).expect("las-rs open");
    r.read_all()
        .expect("las-rs read")
        .points()
        .map(|p| {
            let p = p.expect("point");
            [p.x, p.y, p.z]
        })
        .collect()
}

/// The expected `Error::Input` for `path`, with its message.
fn input_error(result: talus::Result<impl Sized>, path: &Path) -> String {
    match result {
        Err(e @ Error::Input { .. }) => {
            let Error::Input { path: p, .. } = &e else {
                unreachable!()
            };
            assert_eq!(p, path, "error names the wrong file: {e}");
            let msg = e.to_string();
            assert!(msg.starts_with(&path.display().to_string()), "{msg}");
            assert!(!msg.contains('\n'), "one line: {msg}");
            assert_eq!(e.exit_code(), 2);
            msg
        }
        Err(e) => panic!("expected Error::Input for {}, got {e:?}", path.display()),
        Ok(_) => panic!("expected an error for {}", path.display()),
    }
}

/// Open and read everything; the first error (at open or while filling).
fn read_error(path: &Path) -> String {
    let r = io::read_all(path).map(|_| ());
    input_error(r, path)
}

/// Deterministic test points with mm-exact UTM-sized coordinates (exact in f32 for z).
fn sample_points(n: usize) -> Vec<Point3> {
    (0..n)
        .map(|i| {
            let i = i as f64;
            [
                300_000.0 + (i * 37.0) % 500.0 + 0.125,
                5_773_000.0 + (i * 91.0) % 700.0 - 0.375,
                -3.5 + (i * 13.0) % 25.0 + 0.25,
            ]
        })
        .collect()
}

/// Millimetre transforms with UTM-sized offsets, for the LAZ written by las-rs.
fn millimetre_transforms() -> las::Vector<las::Transform> {
    let t = |offset: f64| las::Transform {
        scale: 0.001,
        offset,
    };
    las::Vector {
        x: t(300_000.0),
        y: t(5_773_000.0),
        z: t(0.0),
    }
}

fn write_file(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes).expect("write fixture");
}

// ---------------------------------------------------------------------------------------------
// real data

#[test]
fn autzen_las_matches_laspy_and_las_rs() {
    let data = data_dir();
    for (name, count) in [
        ("autzen-bmx-2010.las", 829u64),
        ("autzen-bmx-2023.las", 687),
    ] {
        let path = data.join("autzen-bmx").join(name);
        let (info, pts) = read_small_chunks(&path);
        assert_eq!(info.format, CloudFormat::Las);
        assert_eq!(info.format_detail, "LAS 1.4 point format 7");
        assert_eq!(info.point_count, count);
        assert_eq!(pts.len() as u64, count);
        // Bounds from the header equal the bounds of the points read.
        let b = bounds_of(&pts);
        for k in 0..3 {
            assert!(
                (b.min[k] - info.bounds.min[k]).abs() < 1e-9,
                "{name} min {k}"
            );
            assert!(
                (b.max[k] - info.bounds.max[k]).abs() < 1e-9,
                "{name} max {k}"
            );
        }
        // CRS: WKT VLR copied verbatim, text decoded.
        let wkt = info.crs.wkt.as_deref().expect("WKT");
        assert!(wkt.contains("Oregon"), "{wkt}");
        assert_eq!(info.crs.vlrs.len(), 1);
        assert_eq!(info.crs.vlrs[0].record_id, 2112);
        assert_eq!(info.crs.vlrs[0].user_id, "LASF_Projection");
        assert_eq!(info.crs.epsg, None);
        // The same points as las-rs' Point API, in the same order.
        assert_eq!(pts, las_rs_points(&path));

        if let Some(py) = laspy_python() {
            let j = laspy_read(&py, &path, 20);
            assert_eq!(j["point_count"].as_u64(), Some(count));
            assert_eq!(f64s(&j["mins"]), info.bounds.min.to_vec());
            assert_eq!(f64s(&j["maxs"]), info.bounds.max.to_vec());
            let (x, y, z) = (f64s(&j["x"]), f64s(&j["y"]), f64s(&j["z"]));
            for i in 0..20 {
                assert!((pts[i][0] - x[i]).abs() < 1e-9);
                assert!((pts[i][1] - y[i]).abs() < 1e-9);
                assert!((pts[i][2] - z[i]).abs() < 1e-9);
            }
        }
    }
}

#[test]
fn st_leonards_laz_matches_laspy_with_epsg() {
    let data = data_dir();
    let dir = data.join("st-leonards");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("st-leonards")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "laz"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 6);
    let py = laspy_python();
    for path in files {
        let (info, pts) = read_small_chunks(&path);
        assert_eq!(info.format, CloudFormat::Laz);
        assert_eq!(info.format_detail, "LAZ 1.4 point format 0");
        assert_eq!(info.crs.epsg, Some(32755), "{}", path.display());
        assert!(info.crs.vlrs.iter().any(|v| v.record_id == 34735));
        assert_eq!(info.crs.describe(), "EPSG:32755");
        assert_eq!(pts.len() as u64, info.point_count);
        let b = bounds_of(&pts);
        for k in 0..3 {
            assert!((b.min[k] - info.bounds.min[k]).abs() < 1e-9);
            assert!((b.max[k] - info.bounds.max[k]).abs() < 1e-9);
        }
        if let Some(py) = &py {
            let j = laspy_read(py, &path, 50);
            assert_eq!(j["point_count"].as_u64(), Some(info.point_count));
            assert_eq!(j["epsg"].as_u64(), Some(32755));
            let (x, y, z) = (f64s(&j["x"]), f64s(&j["y"]), f64s(&j["z"]));
            for i in 0..50 {
                assert!((pts[i][0] - x[i]).abs() < 1e-9);
                assert!((pts[i][1] - y[i]).abs() < 1e-9);
                assert!((pts[i][2] - z[i]).abs() < 1e-9);
            }
        }
    }
}

#[test]
fn cloudcompare_text_reads_103_core_points_of_the_2010_cloud() {
    let data = data_dir();
    let path = data.join("autzen-bmx/autzen-bmx-cc.txt");
    let (info, pts) = read_small_chunks(&path);
    assert_eq!(info.format, CloudFormat::Text);
    assert_eq!(info.point_count, 103);
    assert_eq!(pts.len(), 103);
    assert_eq!(bounds_of(&pts), info.bounds);
    // CloudCompare's core points are points of the 2010 cloud: each must be found there.
    let las = las_rs_points(&data.join("autzen-bmx/autzen-bmx-2010.las"));
    for p in &pts {
        let best = las
            .iter()
            .map(|q| (0..3).map(|k| (p[k] - q[k]).abs()).fold(0.0, f64::max))
            .fold(f64::INFINITY, f64::min);
        assert!(
            best < 1e-6,
            "core point {p:?} not in the 2010 cloud ({best})"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// text fixtures

fn check_text(dir: &Path, name: &str, content: &str, expect: &[Point3]) {
    let path = dir.join(name);
    write_file(&path, content.as_bytes());
    let (info, pts) = read_small_chunks(&path);
    assert_eq!(info.format, CloudFormat::Text, "{name}");
    assert_eq!(info.point_count as usize, expect.len(), "{name}");
    assert_eq!(pts, expect, "{name}");
    assert_eq!(info.bounds, bounds_of(expect), "{name}");
}

#[test]
fn text_header_styles() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pts = sample_points(2500);
    let rows = |f: &dyn Fn(&Point3) -> String| pts.iter().map(f).collect::<Vec<_>>().join("\n");
    // No header, comma, extra columns.
    let body = rows(&|p| format!("{},{},{},7,nan", p[0], p[1], p[2]));
    check_text(dir.path(), "plain.csv", &body, &pts);
    // Quoted header in another order, CRLF line ends.
    let body = rows(&|p| format!("1,{},\"{}\",{},0", p[2], p[0], p[1]));
    let content = format!(
        "\"id\",\"Z\",\"X\",\"Y\",\"class\"\r\n{}\r\n",
        body.replace('\n', "\r\n")
    );
    check_text(dir.path(), "quoted.csv", &content, &pts);
    // CloudCompare style `//X Y Z`, whitespace, lower/mixed case.
    let body = rows(&|p| format!("{} {}\t{}   255 0 0", p[0], p[1], p[2]));
    check_text(
        dir.path(),
        "cc.txt",
        &format!("//x Y z R G B\n{body}\n"),
        &pts,
    );
    // `# X Y Z` header, blank lines and a trailing comment.
    let body = rows(&|p| format!("{} {} {}", p[0], p[1], p[2]));
    check_text(
        dir.path(),
        "hash.xyz",
        &format!("# X Y Z\n\n{body}\n\n# end\n"),
        &pts,
    );
    // Plain header without quotes, semicolons.
    let body = rows(&|p| format!("{};{};{}", p[0], p[1], p[2]));
    check_text(dir.path(), "semi.csv", &format!("X;Y;Z\n{body}\n"), &pts);
    // PTS: a count line, then x y z intensity r g b.
    let body = rows(&|p| format!("{} {} {} -120 10 20 30", p[0], p[1], p[2]));
    check_text(
        dir.path(),
        "cloud.pts",
        &format!("{}\n{body}\n", pts.len()),
        &pts,
    );
}

// ---------------------------------------------------------------------------------------------
// PLY fixtures

#[derive(Clone, Copy)]
enum Enc {
    Ascii,
    Le,
    Be,
}

/// A PLY with a `camera` element before the vertices, vertex props
/// `uchar red, double x, float nx, double y, list uchar int idx, float z, uchar alpha`
/// (list only when `with_list`), and a `face` element after.
fn ply_bytes(pts: &[Point3], enc: Enc, with_list: bool) -> Vec<u8> {
    let fmt = match enc {
        Enc::Ascii => "ascii",
        Enc::Le => "binary_little_endian",
        Enc::Be => "binary_big_endian",
    };
    let mut h = format!(
        "ply\nformat {fmt} 1.0\ncomment made by talus tests\nelement camera 1\n\
         property float view_px\nproperty list uchar int ids\n\
         element vertex {}\nproperty uchar red\nproperty double x\nproperty float nx\n\
         property double y\n",
        pts.len()
    );
    if with_list {
        h.push_str("property list uchar int idx\n");
    }
    h.push_str(
        "property float z\nproperty uchar alpha\nelement face 2\n\
         property list uchar int vertex_indices\nend_header\n",
    );
    let mut out = h.into_bytes();
    macro_rules! put {
        ($v:expr) => {
            match enc {
                Enc::Le => out.extend_from_slice(&$v.to_le_bytes()),
                Enc::Be => out.extend_from_slice(&$v.to_be_bytes()),
                Enc::Ascii => unreachable!(),
            }
        };
    }
    match enc {
        Enc::Ascii => {
            out.extend_from_slice(b"1.5 2 7 8\n");
            for (i, p) in pts.iter().enumerate() {
                let list = if with_list {
                    format!(" 3 {i} 5 6")
                } else {
                    String::new()
                };
                out.extend_from_slice(
                    format!("200 {} 0.5 {}{} {} 255\n", p[0], p[1], list, p[2]).as_bytes(),
                );
            }
            out.extend_from_slice(b"3 0 1 2\n3 1 2 3\n");
        }
        _ => {
            put!(1.5f32);
            out.push(2);
            put!(7i32);
            put!(8i32);
            for (i, p) in pts.iter().enumerate() {
                out.push(200);
                put!(p[0]);
                put!(0.5f32);
                put!(p[1]);
                if with_list {
                    out.push(3);
                    put!(i as i32);
                    put!(5i32);
                    put!(6i32);
                }
                put!(p[2] as f32);
                out.push(255);
            }
            for f in [[0i32, 1, 2], [1, 2, 3]] {
                out.push(3);
                for v in f {
                    put!(v);
                }
            }
        }
    }
    out
}

#[test]
fn ply_all_encodings_with_extra_props_and_faces() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pts = sample_points(3001);
    for (enc, name, detail) in [
        (Enc::Ascii, "ascii", "PLY ascii"),
        (Enc::Le, "le", "PLY binary_little_endian"),
        (Enc::Be, "be", "PLY binary_big_endian"),
    ] {
        for with_list in [false, true] {
            let path = dir.path().join(format!("{name}-{with_list}.ply"));
            write_file(&path, &ply_bytes(&pts, enc, with_list));
            let (info, got) = read_small_chunks(&path);
            assert_eq!(info.format, CloudFormat::Ply);
            assert_eq!(info.format_detail, detail);
            assert_eq!(info.point_count, 3001);
            assert_eq!(got, pts, "{name} list={with_list}");
            assert_eq!(info.bounds, bounds_of(&pts));
        }
    }
}

#[test]
fn ply_integer_coordinates() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("int.ply");
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty int x\n\
                  property short y\nproperty uint z\nend_header\n"
        .to_vec();
    let expect = [
        [-5.0, 7.0, 4_000_000_000.0],
        [1.0, -32768.0, 0.0],
        [2_000_000.0, 3.0, 9.0],
    ];
    for p in expect {
        b.extend_from_slice(&(p[0] as i32).to_le_bytes());
        b.extend_from_slice(&(p[1] as i16).to_le_bytes());
        b.extend_from_slice(&(p[2] as u32).to_le_bytes());
    }
    write_file(&path, &b);
    let (_, got) = read_small_chunks(&path);
    assert_eq!(got, expect);
}

// ---------------------------------------------------------------------------------------------
// LAZ written by las-rs (point format 3), and the LAS -> our LAZ writer -> reader round trip

#[test]
fn laz_written_by_las_rs_reads_back() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("pf3.laz");
    let pts = sample_points(120_000);
    let mut b = las::Builder::from((1, 2));
    b.point_format = las::point::Format::new(3).expect("pf3");
    b.transforms = millimetre_transforms();
    let header = b.into_header().expect("header");
    let mut w = las::Writer::from_path(&path, header).expect("writer");
    for p in &pts {
        let mut pt = las::Point {
            x: p[0],
            y: p[1],
            z: p[2],
            ..Default::default()
        };
        pt.gps_time = Some(1.0);
        pt.color = Some(las::Color::new(1, 2, 3));
        w.write_point(pt).expect("write");
    }
    w.close().expect("close");
    drop(w);
    let (info, got) = read_small_chunks(&path);
    assert_eq!(info.format, CloudFormat::Laz);
    assert_eq!(info.format_detail, "LAZ 1.2 point format 3");
    assert_eq!(got.len(), pts.len());
    for (a, b) in got.iter().zip(&pts) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-6);
        }
    }
}

/// A LAZ of a layered point format (LAS 1.4, formats 6 to 10), whose other fields vary from
/// point to point (intensity, GPS time, classification, flags, scan angle, colours): talus
/// decodes only the coordinates' layers, and gets exactly the coordinates las-rs gets by
/// decoding everything.
#[test]
fn layered_laz_coordinates_equal_a_full_decode() {
    let dir = tempfile::tempdir().expect("tempdir");
    for format in [6u8, 7, 8] {
        let path = dir.path().join(format!("pf{format}.laz"));
        let pts = sample_points(130_000);
        let mut b = las::Builder::from((1, 4));
        b.point_format = las::point::Format::new(format).expect("format");
        b.point_format.is_compressed = true;
        b.transforms = millimetre_transforms();
        let header = b.into_header().expect("header");
        let mut w = las::Writer::from_path(&path, header).expect("writer");
        for (i, p) in pts.iter().enumerate() {
            let k = i as u16;
            let pt = las::Point {
                x: p[0],
                y: p[1],
                z: p[2],
                intensity: k.wrapping_mul(7919),
                return_number: 1 + (k % 3) as u8,
                number_of_returns: 3,
                classification: las::point::Classification::new((k % 20) as u8)
                    .unwrap_or(las::point::Classification::Ground),
                scan_angle: f32::from(k % 90) - 45.0,
                user_data: (k % 251) as u8,
                point_source_id: k % 17,
                gps_time: Some(1.0e8 + i as f64 * 1.3e-5),
                color: (format != 6).then(|| las::Color::new(k, k.wrapping_mul(3), !k)),
                nir: (format == 8).then_some(k.wrapping_mul(5)),
                ..Default::default()
            };
            w.write_point(pt).expect("write");
        }
        w.close().expect("close");
        drop(w);
        let (info, got) = read_small_chunks(&path);
        assert_eq!(info.format_detail, format!("LAZ 1.4 point format {format}"));
        let want = las_rs_points(&path);
        assert_eq!(got.len(), want.len());
        for (i, (a, b)) in got.iter().zip(&want).enumerate() {
            for k in 0..3 {
                assert_eq!(a[k].to_bits(), b[k].to_bits(), "format {format}, point {i}");
            }
        }
    }
}

#[test]
fn laz_round_trip_through_result_writer() {
    let data = data_dir();
    let src = data.join("autzen-bmx/autzen-bmx-2010.las");
    let (info, pts) = io::read_all(&src).expect("read");
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("round.laz");
    let mut w = io::las_out::ResultWriter::create(&out, &info.crs, &[], pts[0]).expect("create");
    for p in &pts {
        w.write(*p, &[]).expect("write");
    }
    assert_eq!(w.finish().expect("finish"), pts.len() as u64);
    let (info2, back) = read_small_chunks(&out);
    assert_eq!(info2.format_detail, "LAZ 1.4 point format 6");
    assert_eq!(info2.crs.wkt, info.crs.wkt);
    assert_eq!(back.len(), pts.len());
    for (a, b) in back.iter().zip(&pts) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() <= 0.0005 + 1e-9, "{a:?} vs {b:?}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// errors

#[test]
fn missing_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("nope.laz");
    let msg = read_error(&path);
    assert!(msg.contains("not found"), "{msg}");
}

#[test]
fn not_a_point_cloud() {
    let dir = tempfile::tempdir().expect("tempdir");
    let png = dir.path().join("photo.png");
    let mut b = b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR".to_vec();
    b.extend_from_slice(&[0u8; 200]);
    write_file(&png, &b);
    assert!(read_error(&png).contains("not a point cloud"));

    let prose = dir.path().join("notes.txt");
    write_file(&prose, b"Survey notes\nwind from the west, 12 knots\n");
    assert!(read_error(&prose).contains("not a point cloud"));

    let dirpath = dir.path().join("folder.las");
    std::fs::create_dir(&dirpath).expect("mkdir");
    assert!(read_error(&dirpath).contains("directory"));

    let noxyz = dir.path().join("noxyz.ply");
    write_file(
        &noxyz,
        b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int v\nend_header\n3 0 1 2\n",
    );
    assert!(read_error(&noxyz).contains("no vertex element"));
}

#[test]
fn truncated_las_is_found_up_front() {
    let data = data_dir();
    let src = data.join("autzen-bmx/autzen-bmx-2010.las");
    let bytes = std::fs::read(&src).expect("read");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("cut.las");
    write_file(&path, &bytes[..bytes.len() - 3000]);
    let msg = input_error(io::open(&path).map(|_| ()), &path);
    assert!(msg.contains("truncated") && msg.contains("829"), "{msg}");
}

#[test]
fn truncated_laz_is_a_read_error() {
    let data = data_dir();
    let src = data.join("st-leonards/leo_20180606_dsm_resampled_1m.laz");
    let bytes = std::fs::read(&src).expect("read");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("cut.laz");
    write_file(&path, &bytes[..bytes.len() * 6 / 10]);
    let msg = read_error(&path);
    assert!(msg.contains("truncated or corrupt LAZ"), "{msg}");

    // A LAZ whose chunk table survives but whose point data lost 20 kB in the middle: the
    // header opens, and decompression runs out of bytes part-way through the points.
    let dir2 = tempfile::tempdir().expect("tempdir");
    let big = dir2.path().join("big.laz");
    write_synthetic_laz(&big, 400_000);
    let mut b = std::fs::read(&big).expect("read");
    let raw = las::raw::Header::read_from(&b[..]).expect("raw header");
    let at = raw.offset_to_point_data as usize;
    // LAZ point data starts with the i64 offset of the chunk table: move it with the cut.
    let table = i64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"));
    let cut_len = 20_000;
    b[at..at + 8].copy_from_slice(&(table - cut_len as i64).to_le_bytes());
    let mid = b.len() / 2;
    b.drain(mid..mid + cut_len);
    let cut = dir2.path().join("hole.laz");
    write_file(&cut, &b);
    let mut r = io::open(&cut).expect("the header and chunk table are intact");
    let mut buf = Vec::new();
    let mut read = 0usize;
    let err = loop {
        match r.fill(&mut buf, 50_000) {
            Ok(0) => panic!("read all {read} points of a damaged file"),
            Ok(n) => read += n,
            Err(e) => break e,
        }
    };
    let msg = input_error(Err::<(), _>(err), &cut);
    assert!(
        msg.contains("truncated or corrupt LAZ data") && msg.contains("of 400000 points"),
        "{msg}"
    );
}

fn write_synthetic_laz(path: &Path, n: usize) {
    let mut w = io::las_out::ResultWriter::create(
        path,
        &Default::default(),
        &[],
        [300_000.0, 5_773_000.0, 0.0],
    )
    .expect("create");
    for p in sample_points(n) {
        w.write(p, &[]).expect("write");
    }
    w.finish().expect("finish");
}

#[test]
fn zero_points() {
    let dir = tempfile::tempdir().expect("tempdir");
    let las_path = dir.path().join("empty.las");
    let header = las::Builder::from((1, 4)).into_header().expect("header");
    let mut w = las::Writer::from_path(&las_path, header).expect("writer");
    w.close().expect("close");
    drop(w);
    assert!(read_error(&las_path).contains("no points"));

    let txt = dir.path().join("empty.csv");
    write_file(&txt, b"X,Y,Z\n");
    assert!(read_error(&txt).contains("no points"));

    let ply = dir.path().join("empty.ply");
    write_file(&ply, b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n");
    assert!(read_error(&ply).contains("no points"));
}

#[test]
fn nan_and_infinite_coordinates_name_the_point() {
    let dir = tempfile::tempdir().expect("tempdir");
    let txt = dir.path().join("nan.txt");
    write_file(&txt, b"//X Y Z\n1 2 3\n4 5 6\n7 nan 9\n");
    let msg = read_error(&txt);
    assert!(
        msg.contains("line 4") && msg.contains("point 2") && msg.contains("NaN"),
        "{msg}"
    );

    let inf = dir.path().join("inf.csv");
    write_file(&inf, b"1,2,3\n4,5,inf\n");
    let msg = read_error(&inf);
    assert!(msg.contains("line 2") && msg.contains("point 1"), "{msg}");

    let mut pts = sample_points(10);
    pts[7][1] = f64::NAN;
    let ply = dir.path().join("nan.ply");
    write_file(&ply, &ply_bytes(&pts, Enc::Le, false));
    let msg = read_error(&ply);
    assert!(msg.contains("point 7") && msg.contains("NaN"), "{msg}");
}

#[test]
fn bad_text_rows_name_the_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("short.txt");
    let mut s = String::from("X Y Z\n");
    for i in 0..15 {
        s.push_str(&format!("{i} {i} {i}\n"));
    }
    s.push_str("1.0 2.0\n");
    write_file(&path, s.as_bytes());
    let msg = read_error(&path);
    assert!(msg.ends_with("line 17: expected 3 numbers"), "{msg}");

    let word = dir.path().join("word.txt");
    write_file(&word, b"1 2 3\n4 five 6\n");
    let msg = read_error(&word);
    assert!(
        msg.contains("line 2") && msg.contains("'five' is not a number"),
        "{msg}"
    );
}

#[test]
fn unreadable_headers() {
    let dir = tempfile::tempdir().expect("tempdir");
    let las_path = dir.path().join("stub.las");
    write_file(&las_path, b"LASF\x01\x02 too short");
    assert!(read_error(&las_path).contains("unreadable LAS header"));

    let ply = dir.path().join("stub.ply");
    write_file(
        &ply,
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n",
    );
    assert!(read_error(&ply).contains("unreadable PLY header"));

    let ply2 = dir.path().join("short.ply");
    let mut b = ply_bytes(&sample_points(100), Enc::Be, true);
    b.truncate(b.len() - 700);
    write_file(&ply2, &b);
    let msg = read_error(&ply2);
    assert!(
        msg.contains("truncated PLY") && msg.contains("promises 100"),
        "{msg}"
    );
}

#[test]
fn dropping_a_reader_early_is_fine() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("big.laz");
    write_synthetic_laz(&path, 600_000);
    let mut r = io::open(&path).expect("open");
    let mut buf = Vec::new();
    assert_eq!(r.fill(&mut buf, 10).expect("fill"), 10);
    assert_eq!(buf, sample_points(10));
    drop(r); // the decoding thread must notice and stop (the test would hang otherwise)
    let _ = std::io::stderr().flush();
}
