use super::*;

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn assert_bit_exact(a: &TileColumns, b: &TileColumns) {
    assert_eq!(bits(&a.x), bits(&b.x));
    assert_eq!(bits(&a.y), bits(&b.y));
    assert_eq!(bits(&a.z), bits(&b.z));
    assert_eq!(a.extra.len(), b.extra.len());
    for (ca, cb) in a.extra.iter().zip(&b.extra) {
        assert_eq!(ca.name, cb.name);
        match (&ca.data, &cb.data) {
            (ColumnData::F64(u), ColumnData::F64(v)) => assert_eq!(bits(u), bits(v)),
            (ColumnData::F32(u), ColumnData::F32(v)) => {
                let b = |w: &[f32]| w.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(b(u), b(v))
            }
            (u, v) => assert_eq!(u, v),
        }
    }
}

/// Awkward values: NaN payloads, infinities, signed zero, subnormals, extremes, plus noise.
fn awkward(n: usize, seed: u64) -> Vec<f64> {
    let special = [
        f64::NAN,
        f64::from_bits(0x7ff8_0000_dead_beef),
        f64::INFINITY,
        f64::NEG_INFINITY,
        -0.0,
        0.0,
        f64::MIN_POSITIVE / 3.0,
        f64::MAX,
        f64::MIN,
        512_345.678_9,
    ];
    let mut s = seed;
    (0..n)
        .map(|i| {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            if i % 13 == 0 {
                special[(s >> 60) as usize % special.len()]
            } else {
                f64::from_bits(s)
            }
        })
        .collect()
}

fn sample(n: usize) -> TileColumns {
    TileColumns {
        x: awkward(n, 1),
        y: awkward(n, 2),
        z: awkward(n, 3),
        extra: vec![
            Column {
                name: "owned".into(),
                data: ColumnData::U8((0..n).map(|i| (i % 3 == 0) as u8).collect()),
            },
            Column {
                name: "index".into(),
                data: ColumnData::U32(
                    (0..n as u32)
                        .map(|i| i.wrapping_mul(2_654_435_761))
                        .collect(),
                ),
            },
            Column {
                name: "intensity_f".into(),
                data: ColumnData::F64(awkward(n, 4)),
            },
            Column {
                // f32 (kind 4): awkward f64s' high bits (NaN payloads, infinities, subnormals).
                name: "distance_f32".into(),
                data: ColumnData::F32(
                    awkward(n, 5)
                        .iter()
                        .map(|x| f32::from_bits((x.to_bits() >> 32) as u32))
                        .collect(),
                ),
            },
        ],
    }
}

fn all_options() -> Vec<WriteOptions> {
    let q = Quantisation {
        scale: [0.001, 0.001, 0.01],
        offset: [500_000.0, 5_000_000.0, 0.0],
    };
    let mut v = vec![];
    for level in [1, 3] {
        for (shuffle_f64, shuffle_int) in [(false, false), (true, true), (false, true)] {
            for quantise in [None, Some(q)] {
                v.push(WriteOptions {
                    level,
                    shuffle_f64,
                    shuffle_f32: shuffle_int,
                    shuffle_int,
                    quantise,
                });
            }
        }
    }
    v
}

#[test]
fn round_trip_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.tile");
    for n in [0, 1, 7, 5000] {
        let cols = sample(n);
        for opts in all_options() {
            write_tile_with(&path, &cols, &opts).unwrap();
            let back = read_tile(&path).unwrap();
            assert_bit_exact(&cols, &back);
            let h = read_tile_header(&path).unwrap();
            assert_eq!(h.point_count, n as u64);
            assert_eq!(
                h.columns,
                [
                    "x",
                    "y",
                    "z",
                    "owned",
                    "index",
                    "intensity_f",
                    "distance_f32"
                ]
            );
        }
    }
    // The temporary sibling is gone after a successful write.
    assert!(!crate::atomic::tmp_path(&path).exists());
}

/// One u32 column read alone is the column a whole read gives; other kinds and missing names
/// are errors, and a damaged payload is caught as by a whole read.
#[test]
fn a_u32_column_read_alone() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.tile");
    for n in [0, 1, 5000] {
        let cols = sample(n);
        for opts in all_options() {
            write_tile_with(&path, &cols, &opts).unwrap();
            let got = read_u32_columns(&path, &["index"]).unwrap();
            assert_eq!(Some(&ColumnData::U32(got[0].clone())), cols.column("index"));
            assert!(read_u32_columns(&path, &["owned"]).is_err());
            assert!(read_u32_columns(&path, &["nothing"]).is_err());
        }
    }
    let mut bytes = std::fs::read(&path).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x55;
    std::fs::write(&path, &bytes).unwrap();
    assert!(matches!(
        read_u32_columns(&path, &["index"]),
        Err(crate::Error::Corrupt { .. })
    ));
}

/// LAS-style coordinates (integers times the file's scale plus its offset, computed the way the
/// `las` crate does) are stored quantised, bit-exact and smaller; values off that lattice fall
/// back to f64 and stay bit-exact.
#[test]
fn quantisation_is_exact_for_las_values_and_never_lossy() {
    let scale = [0.001, 0.001, 0.001];
    let offset = [500_000.0, 5_100_000.0, 0.0];
    let n: i32 = 20_000;
    let mut cols = TileColumns::default();
    for i in 0..n {
        let k = [
            i * 37 % 100_000,
            (i * 91 + 5) % 100_000,
            250_000 + (i * 13 % 777),
        ];
        cols.x.push(scale[0] * f64::from(k[0]) + offset[0]);
        cols.y.push(scale[1] * f64::from(k[1]) + offset[1]);
        cols.z.push(scale[2] * f64::from(k[2]) + offset[2]);
    }
    let dir = tempfile::tempdir().unwrap();
    let (pq, pf) = (dir.path().join("q.tile"), dir.path().join("f.tile"));
    let q = WriteOptions {
        quantise: Some(Quantisation { scale, offset }),
        ..WriteOptions::default()
    };
    write_tile_with(&pq, &cols, &q).unwrap();
    write_tile(&pf, &cols).unwrap();
    assert_bit_exact(&cols, &read_tile(&pq).unwrap());
    let (sq, sf) = (
        std::fs::metadata(&pq).unwrap().len(),
        std::fs::metadata(&pf).unwrap().len(),
    );
    assert!(sq < sf, "quantised {sq} B is not smaller than f64 {sf} B");
    // Off-lattice values with the same option: stored as f64, still exact.
    cols.x[17] += 1e-7;
    write_tile_with(&pq, &cols, &q).unwrap();
    assert_bit_exact(&cols, &read_tile(&pq).unwrap());
}

/// The header is laid out as documented (checked by hand, not through the reader).
#[test]
fn header_layout_matches_the_documentation() {
    let cols = sample(10);
    let bytes = encode(&cols, &WriteOptions::default()).unwrap();
    assert_eq!(&bytes[..8], b"TALUSTIL");
    assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 1);
    let header_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    assert_eq!(u64::from_le_bytes(bytes[16..24].try_into().unwrap()), 10);
    assert_eq!(u32::from_le_bytes(bytes[24..28].try_into().unwrap()), 7);
    let crc = u32::from_le_bytes(bytes[header_len - 4..header_len].try_into().unwrap());
    assert_eq!(crc, crc32fast::hash(&bytes[..header_len - 4]));
    let payload_crc = u32::from_le_bytes(bytes[header_len - 8..header_len - 4].try_into().unwrap());
    assert_eq!(payload_crc, crc32fast::hash(&bytes[header_len..]));
    // First column: name "x", kind f64, not shuffled, and its stored bytes are one zstd frame
    // holding the 10 values' little-endian bytes.
    assert_eq!(u16::from_le_bytes(bytes[76..78].try_into().unwrap()), 1);
    assert_eq!(&bytes[78..81], &[b'x', 0, 0]);
    let stored = u64::from_le_bytes(bytes[81..89].try_into().unwrap()) as usize;
    let frame = &bytes[header_len..header_len + stored];
    let raw = zstd::stream::decode_all(frame).unwrap();
    let want: Vec<u8> = cols.x.iter().flat_map(|v| v.to_le_bytes()).collect();
    assert_eq!(raw, want);
}

fn expect_corrupt(path: &std::path::Path, what: &str) {
    match read_tile(path) {
        Err(Error::Corrupt { path: p, .. }) => assert_eq!(p, path, "{what}"),
        other => panic!("{what}: expected Corrupt, got {other:?}"),
    }
}

#[test]
fn any_flipped_byte_or_truncation_is_corrupt() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.tile");
    let bad = dir.path().join("bad.tile");
    write_tile(&good, &sample(40)).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    for i in 0..bytes.len() {
        for mask in [0x01u8, 0x80, 0xff] {
            let mut b = bytes.clone();
            b[i] ^= mask;
            std::fs::write(&bad, &b).unwrap();
            expect_corrupt(&bad, &format!("byte {i} ^ {mask:#x}"));
        }
    }
    let header_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    for len in 0..bytes.len() {
        std::fs::write(&bad, &bytes[..len]).unwrap();
        expect_corrupt(&bad, &format!("truncated to {len}"));
        // The header alone is readable exactly when it is complete.
        match read_tile_header(&bad) {
            Err(Error::Corrupt { .. }) => assert!(len < header_len, "header cut at {len}"),
            Ok(h) => {
                assert!(len >= header_len);
                assert_eq!(h.point_count, 40);
            }
            Err(e) => panic!("unexpected {e}"),
        }
    }
    let mut longer = bytes.clone();
    longer.push(0);
    std::fs::write(&bad, &longer).unwrap();
    expect_corrupt(&bad, "trailing byte");
}

#[test]
fn inconsistent_columns_are_rejected_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.tile");
    let mut cols = sample(5);
    cols.z.pop();
    assert!(matches!(
        write_tile(&path, &cols),
        Err(Error::Invalid { .. })
    ));
    let mut cols = sample(5);
    cols.extra[0].name = "x".into();
    assert!(matches!(
        write_tile(&path, &cols),
        Err(Error::Invalid { .. })
    ));
    assert!(!path.exists());
    assert!(matches!(read_tile(&path), Err(Error::Io { .. })));
}

/// A crash during a rewrite (simulated by a half-written temporary left behind) leaves the
/// previous tile intact, and the next write succeeds over the leftover.
#[test]
fn crash_leftover_tmp_leaves_previous_tile_intact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.tile");
    let old = sample(100);
    write_tile(&path, &old).unwrap();
    let new = sample(300);
    let bytes = encode(&new, &WriteOptions::default()).unwrap();
    std::fs::write(crate::atomic::tmp_path(&path), &bytes[..bytes.len() / 3]).unwrap();
    assert_bit_exact(&old, &read_tile(&path).unwrap());
    write_tile(&path, &new).unwrap();
    assert_bit_exact(&new, &read_tile(&path).unwrap());
    assert!(!crate::atomic::tmp_path(&path).exists());
}

/// Every value a LAS record can hold, whatever the file's scale and offset (odd scales, negative
/// and large offsets, records over the whole i32 range), is found on the lattice and stored
/// quantised: the reciprocal-and-round search for the integer never misses it.
#[test]
fn quantisation_finds_every_las_record() {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for (scale, offset) in [
        (0.001, 500_000.0),
        (0.01, -1234.5),
        (0.0001, 5_100_000.0),
        (0.00025, 0.0),
        (1.0 / 3.0, 17.0),
        (0.1, -4_000_000.0),
    ] {
        let n = 5000;
        let mut cols = TileColumns::default();
        for i in 0..n {
            // Records over the whole i32 range and near zero, as `las` turns them into values.
            let r = if i % 2 == 0 {
                next() as i32
            } else {
                (next() % 2001) as i32 - 1000
            };
            let v = scale * f64::from(r) + offset;
            cols.x.push(v);
            cols.y.push(v);
            cols.z.push(v);
        }
        // The columns span the whole i32 range, whose span still fits u32.
        let q = WriteOptions {
            quantise: Some(Quantisation {
                scale: [scale; 3],
                offset: [offset; 3],
            }),
            ..WriteOptions::default()
        };
        let bytes = encode(&cols, &q).unwrap();
        let h = parse_header(&bytes).unwrap();
        for c in &h.columns[..3] {
            assert_eq!(
                c.kind, KIND_QUANT,
                "scale {scale} offset {offset}: {}",
                c.name
            );
        }
        assert_bit_exact(&cols, &decode(&bytes).unwrap());
    }
}
