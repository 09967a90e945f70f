//! The LAS/LAZ result writer (`talus::io::las_out::ResultWriter`), checked with two readers we
//! did not write: las-rs (header, CRS records, raw records and extra bytes) and laspy, which
//! decodes the extra dimensions from our Extra Bytes VLR on its own (names, types, values).

use std::borrow::Cow;
use std::path::Path;

use talus::io::las_out::{ExtraDim, ExtraType, ResultWriter};
use talus::io::{self, Crs, RawVlr};
use talus::Error;

mod common;
use common::laspy::{laspy_python, laspy_read, num};

const DIMS: [ExtraDim; 5] = [
    ExtraDim {
        name: Cow::Borrowed("m3c2_significant"),
        ty: ExtraType::U8,
        description: "|d| > LoD95",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_count1"),
        ty: ExtraType::U32,
        description: "points in cylinder, epoch 1",
    },
    ExtraDim {
        name: Cow::Borrowed("event_id"),
        ty: ExtraType::I32,
        description: "signed event id",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_distance"),
        ty: ExtraType::F32,
        description: "M3C2 distance",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_uncertainty_with_a_long_nam"),
        ty: ExtraType::F64,
        description: "",
    },
];

const N: usize = 1000;

/// Point i: UTM-sized coordinates with sub-mm parts, and one value per dim spanning each type's
/// range (u32 beyond i32, negative i32), NaN in both float dims now and then.
fn point(i: usize) -> ([f64; 3], [f64; 5]) {
    let f = i as f64;
    let xyz = [
        299_834.0 + f * 0.3771 + 0.00012,
        5_773_164.0 + f * 0.5113 - 0.00031,
        -3.26 + f * 0.0217,
    ];
    let extra = [
        (i % 256) as f64,
        f * 4_000_000.0 + 7.0,
        (f - 500.0) * 4_000_000.0 + 3.0,
        if i % 97 == 5 {
            f64::NAN
        } else {
            f * 0.25 - 100.0
        },
        if i % 89 == 3 {
            f64::NAN
        } else {
            f * 1e-3 + 123_456.789_012
        },
    ];
    (xyz, extra)
}

fn write_file(path: &Path, crs: &Crs) -> u64 {
    let mut w =
        ResultWriter::create(path, crs, &DIMS, [299_900.0, 5_773_400.0, 0.0]).expect("create");
    for i in 0..N {
        let (xyz, extra) = point(i);
        w.write(xyz, &extra).expect("write");
    }
    w.finish().expect("finish")
}

fn wkt_crs() -> Crs {
    crs_of_wkt("PROJCS[\"NAD83 / Oregon GIC Lambert (ft)\",GEOGCS[\"NAD83\"]]")
}

/// A CRS given as WKT, with its LAS record.
fn crs_of_wkt(wkt: &str) -> Crs {
    let mut data = wkt.as_bytes().to_vec();
    data.push(0);
    Crs {
        wkt: Some(wkt.into()),
        epsg: None,
        vlrs: vec![RawVlr {
            user_id: "LASF_Projection".into(),
            record_id: 2112,
            description: "OGC WKT".into(),
            data,
        }],
    }
}

/// A GeoKeyDirectory with ProjectedCSTypeGeoKey = 32755, plus an ASCII params record.
fn geotiff_crs() -> Crs {
    let keys: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32755];
    let data = keys.iter().flat_map(|k| k.to_le_bytes()).collect();
    Crs {
        wkt: None,
        epsg: Some(32755),
        vlrs: vec![
            RawVlr {
                user_id: "LASF_Projection".into(),
                record_id: 34735,
                description: "GeoKeyDirectoryTag".into(),
                data,
            },
            RawVlr {
                user_id: "LASF_Projection".into(),
                record_id: 34737,
                description: "GeoAsciiParamsTag".into(),
                data: b"WGS 84 / UTM zone 55S|\0".to_vec(),
            },
        ],
    }
}

/// Every point of `r`, through las-rs' `Point` API.
fn all_points(r: &mut las::Reader) -> Vec<las::Point> {
    r.read_all()
        .expect("read")
        .points()
        .map(|p| p.expect("point"))
        .collect()
}

/// Check a written file with las-rs: header, CRS and Extra Bytes VLRs, coordinates and the raw
/// extra bytes of every record.
fn check_with_las_rs(path: &Path, crs: &Crs, point_format: u8) {
    let mut r = las::Reader::from_path(path).expect("las-rs open");
    let h = r.header().clone();
    assert_eq!(h.version(), las::Version::new(1, 4));
    assert_eq!(h.number_of_points(), N as u64);
    assert_eq!(h.point_format().to_u8().expect("format"), point_format);
    assert_eq!(usize::from(h.point_format().extra_bytes), 1 + 4 + 4 + 4 + 8);
    for t in [h.transforms().x, h.transforms().y, h.transforms().z] {
        assert_eq!(t.scale, 0.001);
    }
    let eb: Vec<_> = h
        .vlrs()
        .iter()
        .filter(|v| v.user_id == "LASF_Spec" && v.record_id == 4)
        .collect();
    assert_eq!(eb.len(), 1);
    assert_eq!(eb[0].data.len(), 192 * DIMS.len());
    // The CRS records are copied byte for byte.
    let copied: Vec<_> = h.all_vlrs().filter(|v| v.is_crs()).collect();
    assert_eq!(copied.len(), crs.vlrs.len());
    for (a, b) in copied.iter().zip(&crs.vlrs) {
        assert_eq!((a.record_id, &a.data), (b.record_id, &b.data));
    }
    assert_eq!(h.has_wkt_crs(), crs.wkt.is_some());

    let pts = all_points(&mut r);
    assert_eq!(pts.len(), N);
    for (i, p) in pts.iter().enumerate() {
        let (xyz, extra) = point(i);
        assert!(
            (p.x - xyz[0]).abs() <= 0.0005 + 1e-9,
            "x {i}: {} vs {}",
            p.x,
            xyz[0]
        );
        assert!((p.y - xyz[1]).abs() <= 0.0005 + 1e-9, "y {i}");
        assert!((p.z - xyz[2]).abs() <= 0.0005 + 1e-9, "z {i}");
        assert_eq!(p.return_number, 1);
        let b = &p.extra_bytes;
        assert_eq!(b.len(), 21);
        assert_eq!(f64::from(b[0]), extra[0]);
        assert_eq!(
            f64::from(u32::from_le_bytes(b[1..5].try_into().unwrap())),
            extra[1]
        );
        assert_eq!(
            f64::from(i32::from_le_bytes(b[5..9].try_into().unwrap())),
            extra[2]
        );
        let f = f32::from_le_bytes(b[9..13].try_into().unwrap());
        assert!(
            f64::from(f) == extra[3] || (f.is_nan() && extra[3].is_nan()),
            "f32 {i}"
        );
        let d = f64::from_le_bytes(b[13..21].try_into().unwrap());
        assert!(
            d == extra[4] || (d.is_nan() && extra[4].is_nan()),
            "f64 {i}"
        );
    }
}

/// Check a written file with laspy, which decodes the extra dimensions from our descriptor.
fn check_with_laspy(py: &Path, path: &Path, point_format: u8, wkt: bool) {
    let j = laspy_read(py, path, N);
    assert_eq!(j["point_count"].as_u64(), Some(N as u64));
    assert_eq!(j["point_format"].as_u64(), Some(u64::from(point_format)));
    assert_eq!(j["version"], "1.4");
    assert_eq!(j["wkt_bit"].as_bool(), Some(wkt));
    let dims = j["extra_dims"].as_array().expect("dims");
    let names: Vec<&str> = dims
        .iter()
        .map(|d| d["name"].as_str().expect("name"))
        .collect();
    assert_eq!(names, DIMS.map(|d| d.name));
    let types: Vec<&str> = dims
        .iter()
        .map(|d| d["type"].as_str().expect("type"))
        .collect();
    assert_eq!(types, ["uint8", "uint32", "int32", "float32", "float64"]);
    let descriptions: Vec<&str> = dims
        .iter()
        .map(|d| d["description"].as_str().expect("d"))
        .collect();
    assert_eq!(descriptions, DIMS.map(|d| d.description));
    for (k, d) in DIMS.iter().enumerate() {
        let values = j["extra"][d.name.as_ref()].as_array().expect("values");
        assert_eq!(values.len(), N);
        for (i, v) in values.iter().enumerate() {
            let want = point(i).1[k];
            let want = if d.ty == ExtraType::F32 {
                f64::from(want as f32)
            } else {
                want
            };
            match num(v) {
                Some(got) => assert_eq!(got, want, "{} at {i}", d.name),
                None => assert!(v.is_null() && want.is_nan(), "{} at {i}: {v}", d.name),
            }
        }
    }
    for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
        let got = j[axis].as_array().expect("coords");
        for (i, v) in got.iter().enumerate() {
            let want = point(i).0[k];
            assert!(
                (num(v).expect("coord") - want).abs() <= 0.0005 + 1e-9,
                "{axis} {i}"
            );
        }
    }
}

#[test]
fn writes_las_and_laz_with_wkt_and_all_extra_types() {
    let dir = tempfile::tempdir().expect("tempdir");
    let crs = wkt_crs();
    let py = laspy_python();
    for name in ["m3c2.las", "m3c2.laz"] {
        let path = dir.path().join(name);
        assert_eq!(write_file(&path, &crs), N as u64);
        check_with_las_rs(&path, &crs, 6);
        if let Some(py) = &py {
            check_with_laspy(py, &path, 6, true);
        }
        // Our reader finds the CRS again.
        let r = io::open(&path).expect("open");
        assert_eq!(r.info().crs.wkt, crs.wkt);
        assert_eq!(r.info().point_count, N as u64);
    }
}

#[test]
fn geotiff_crs_is_copied_verbatim_with_point_format_0() {
    let dir = tempfile::tempdir().expect("tempdir");
    let crs = geotiff_crs();
    let py = laspy_python();
    for name in ["geo.las", "geo.laz"] {
        let path = dir.path().join(name);
        write_file(&path, &crs);
        check_with_las_rs(&path, &crs, 0);
        if let Some(py) = &py {
            check_with_laspy(py, &path, 0, false);
            assert_eq!(laspy_read(py, &path, 1)["epsg"].as_u64(), Some(32755));
        }
        let r = io::open(&path).expect("open");
        assert_eq!(r.info().crs.epsg, Some(32755));
        let kind = if name.ends_with(".laz") { "LAZ" } else { "LAS" };
        assert_eq!(r.info().format_detail, format!("{kind} 1.4 point format 0"));
    }
}

#[test]
fn nothing_under_the_final_name_until_finish() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("m3c2.laz");
    let tmp = dir.path().join("m3c2.laz.tmp");
    let mut w = ResultWriter::create(&path, &Crs::default(), &DIMS, [0.0; 3]).expect("create");
    for i in 0..10 {
        w.write([i as f64, 0.0, 0.0], &[1.0, 2.0, 3.0, 4.0, 5.0])
            .expect("write");
    }
    assert!(!path.exists() && tmp.exists());
    assert_eq!(w.finish().expect("finish"), 10);
    assert!(path.exists() && !tmp.exists());

    // Dropped without finish (an error elsewhere): the temporary file goes, the old result stays.
    let before = std::fs::read(&path).expect("read");
    let mut w = ResultWriter::create(&path, &Crs::default(), &DIMS, [0.0; 3]).expect("create");
    w.write([1.0, 2.0, 3.0], &[1.0, 2.0, 3.0, 4.0, 5.0])
        .expect("write");
    drop(w);
    assert!(!tmp.exists());
    assert_eq!(std::fs::read(&path).expect("read"), before);
}

#[test]
fn unwritable_output_is_an_output_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("no/such/dir/m3c2.laz");
    match ResultWriter::create(&path, &Crs::default(), &DIMS, [0.0; 3]) {
        Err(Error::Output { path: p, .. }) => assert_eq!(p, path),
        Err(e) => panic!("expected Error::Output, got {e:?}"),
        Ok(_) => panic!("created a file in a missing directory"),
    }
    assert!(!path.exists());
}

#[test]
fn wrong_extra_values_are_rejected() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("bad.las");
    let mut w = ResultWriter::create(&path, &Crs::default(), &DIMS, [0.0; 3]).expect("create");
    assert!(w.write([0.0; 3], &[1.0]).is_err(), "too few values");
    assert!(
        w.write([0.0; 3], &[256.0, 0.0, 0.0, 0.0, 0.0]).is_err(),
        "u8 overflow"
    );
    assert!(
        w.write([0.0; 3], &[f64::NAN, 0.0, 0.0, 0.0, 0.0]).is_err(),
        "NaN in an integer dim"
    );
    assert!(
        w.write([1e7, 0.0, 0.0], &[0.0; 5]).is_err(),
        "beyond i32 millimetres"
    );
    drop(w);
    assert!(!path.exists());
}

/// A LAZ written with its point count known beforehand: chunks of `laz_chunk_size` (four, all of
/// one size but for the few points left over, so that every core compresses), read back whole by
/// las-rs and laspy; a WKT too long for a VLR goes to an EVLR after the points and is found
/// there; a different count than expected still gives a valid file.
#[test]
fn laz_chunks_sized_from_the_expected_count() {
    use talus::io::las_out::{laz_chunk_size, CoordinateGrid};
    let dir = tempfile::tempdir().expect("tempdir");
    let py = laspy_python();
    let long_wkt = format!("PROJCS[\"{}\",GEOGCS[\"NAD83\"]]", "x".repeat(70_000));
    let crs = crs_of_wkt(&long_wkt);
    let n: usize = 130_001;
    for (name, expected) in [("sized.laz", n as u64), ("fewer.laz", n as u64 + 40_000)] {
        let path = dir.path().join(name);
        let grid = CoordinateGrid::millimetre([299_900.0, 5_773_400.0, 0.0]);
        let mut w = ResultWriter::create_on_grid(&path, &crs, &DIMS[..1], grid, Some(expected))
            .expect("create");
        for i in 0..n {
            let (xyz, _) = point(i);
            w.write(xyz, &[(i % 256) as f64]).expect("write");
        }
        assert_eq!(w.finish().expect("finish"), n as u64);

        let mut r = las::Reader::from_path(&path).expect("las-rs open");
        let h = r.header().clone();
        assert_eq!(h.number_of_points(), n as u64);
        let chunk = laz_chunk_size(Some(expected));
        assert_eq!(h.laz_vlr().expect("LASzip VLR").chunk_size(), chunk);
        let laszip = h
            .vlrs()
            .iter()
            .filter(|v| v.user_id == "laszip encoded")
            .count();
        assert_eq!(laszip, 1, "one LASzip VLR");
        assert_eq!(h.evlrs().len(), 1, "the long WKT is an EVLR");
        assert_eq!(h.evlrs()[0].record_id, 2112);
        let pts = all_points(&mut r);
        assert_eq!(pts.len(), n);
        for (i, p) in pts.iter().enumerate().step_by(997) {
            let (xyz, _) = point(i);
            assert!((p.x - xyz[0]).abs() <= 0.0005 + 1e-9, "x {i}");
            assert!((p.z - xyz[2]).abs() <= 0.0005 + 1e-9, "z {i}");
            assert_eq!(f64::from(p.extra_bytes[0]), (i % 256) as f64, "extra {i}");
        }
        let last = pts.last().expect("points");
        assert!((last.y - point(n - 1).0[1]).abs() <= 0.0005 + 1e-9);
        let info = io::open(&path).expect("open");
        assert_eq!(info.info().crs.wkt.as_deref(), Some(long_wkt.as_str()));
        if let Some(py) = &py {
            let j = laspy_read(py, &path, n);
            assert_eq!(j["point_count"].as_u64(), Some(n as u64));
            let got = j["extra"]["m3c2_significant"].as_array().expect("values");
            assert_eq!(got.len(), n);
            for (i, v) in got.iter().enumerate().step_by(1009) {
                assert_eq!(num(v), Some((i % 256) as f64), "laspy extra {i}");
            }
        }
    }
}

/// The chunk size: one chunk for small files, otherwise a multiple of four chunks of about
/// 50 000 points with fewer points over than there are chunks, the same whatever the machine.
#[test]
fn laz_chunk_sizes() {
    use talus::io::las_out::laz_chunk_size;
    assert_eq!(laz_chunk_size(None), 50_000);
    assert_eq!(laz_chunk_size(Some(0)), 1);
    assert_eq!(laz_chunk_size(Some(1000)), 1000);
    assert_eq!(laz_chunk_size(Some(99_856)), 24_964);
    for n in [40_000u64, 99_856, 130_001, 1_000_003, 31_393_325] {
        let c = u64::from(laz_chunk_size(Some(n)));
        let chunks = n / c;
        assert_eq!(chunks % 4, 0, "{n}: {chunks} chunks of {c}");
        assert!(n - chunks * c < chunks, "{n}: {} left over", n - chunks * c);
        assert!((10_000..=50_000).contains(&c), "{n}: chunk {c}");
    }
}
