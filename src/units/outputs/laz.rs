//! m3c2.laz: the core points with PDAL-named extra bytes, in canonical key order whatever the
//! tiling.

use std::borrow::Cow;

use serde::{Deserialize, Serialize};

use crate::error::Result;
use crate::io::las_out::{CoordinateGrid, ExtraDim, ExtraType, ResultWriter};
use crate::io::Crs;
use crate::m3c2::tile::KeyedResult;
use crate::m3c2::Reach;
use crate::store::UnitWriter;

/// The extra dimensions of m3c2.laz, in record order (SPEC.md §2). Distances, uncertainties and
/// spreads as 32-bit floats, as CloudCompare's scalar fields hold them: 24 bits of mantissa are
/// 0.06 µm at 1 m and 8 µm at 100 m, below any survey's coordinate scale, and NaN stays NaN.
/// f64 took 39 bytes a core point in the LAZ (the 10M-point pair's 2.65M core points: 104 MB),
/// f32 takes 24; scaled integers would take 11, but have no NaN (a no-data value laspy and
/// PDAL hand out as a number).
pub(crate) const M3C2_DIMS: &[ExtraDim] = &[
    ExtraDim {
        name: Cow::Borrowed("m3c2_distance"),
        ty: ExtraType::F32,
        description: "M3C2 distance t2 - t1",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_uncertainty"),
        ty: ExtraType::F32,
        description: "LoD95",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_significant"),
        ty: ExtraType::U8,
        description: "1 when |distance| > LoD95",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_std_dev1"),
        ty: ExtraType::F32,
        description: "std dev along normal, epoch 1",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_std_dev2"),
        ty: ExtraType::F32,
        description: "std dev along normal, epoch 2",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_count1"),
        ty: ExtraType::U32,
        description: "points in cylinder, epoch 1",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_count2"),
        ty: ExtraType::U32,
        description: "points in cylinder, epoch 2",
    },
    ExtraDim {
        name: Cow::Borrowed("normal_x"),
        ty: ExtraType::F32,
        description: "oriented normal, x",
    },
    ExtraDim {
        name: Cow::Borrowed("normal_y"),
        ty: ExtraType::F32,
        description: "oriented normal, y",
    },
    ExtraDim {
        name: Cow::Borrowed("normal_z"),
        ty: ExtraType::F32,
        description: "oriented normal, z",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_smoothed"),
        ty: ExtraType::F32,
        description: "smoothed distance (kept points)",
    },
    ExtraDim {
        name: Cow::Borrowed("event_id"),
        ty: ExtraType::U32,
        description: "change event, 0 = none",
    },
    ExtraDim {
        name: Cow::Borrowed("m3c2_beyond_reach"),
        ty: ExtraType::U8,
        description: "1: other epoch past cyl_halflen",
    },
    ExtraDim {
        name: Cow::Borrowed("normal_sign_unknown"),
        ty: ExtraType::U8,
        description: "1: data cannot tell side out",
    },
];

/// Counts of what m3c2.laz holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct Written {
    pub(crate) core_points: u64,
    pub(crate) computed: u64,
    pub(crate) significant: u64,
    /// Distances found by the walk beyond the cylinder's half-length ([`Reach::Extended`]).
    pub(crate) extended: u64,
    /// Core points whose other epoch lies beyond the user's half-length ([`Reach::Beyond`]).
    pub(crate) beyond_reach: u64,
    /// Core points whose normal's sign the data does not decide (`CoreResult::sign_known`).
    pub(crate) sign_unknown: u64,
}

impl Written {
    /// Nothing written yet.
    pub(crate) fn none() -> Written {
        Written {
            core_points: 0,
            computed: 0,
            significant: 0,
            extended: 0,
            beyond_reach: 0,
            sign_unknown: 0,
        }
    }

    /// The counts of `self` and `other` together (a file written in segments).
    pub(crate) fn add(&mut self, other: &Written) {
        self.core_points += other.core_points;
        self.computed += other.computed;
        self.significant += other.significant;
        self.extended += other.extended;
        self.beyond_reach += other.beyond_reach;
        self.sign_unknown += other.sign_unknown;
    }
}

/// Where m3c2.laz goes: its CRS and coordinate grid.
pub(crate) struct Cloud {
    pub(crate) crs: Crs,
    pub(crate) grid: CoordinateGrid,
}

/// Count what m3c2.laz holds of the pair's `total` results in key order (`results`), with the
/// registration error `reg_error` in LoD95 and significance, and write it into `out` when
/// `cloud` says where (a lean campaign's pair has none: `Plan::lean_pairs`). `event_of(key)`
/// gives the smoothed distance and event id of a core point (NaN, 0 when it is in no event);
/// `each` sees every result in the same order (the viewer's terrain sample rides on this pass
/// instead of merging the results again).
pub(crate) fn write_m3c2_laz(
    out: &mut UnitWriter,
    results: &mut dyn FnMut() -> Result<Option<KeyedResult>>,
    total: u64,
    reg_error: f64,
    cloud: Option<Cloud>,
    event_of: &mut dyn FnMut(u64) -> Result<(f64, u32)>,
    each: &mut dyn FnMut(&KeyedResult),
) -> Result<Written> {
    let mut w = match cloud {
        Some(c) => {
            let path = out.path("m3c2.laz")?;
            Some(ResultWriter::create_on_grid(
                &path,
                &c.crs,
                M3C2_DIMS,
                c.grid,
                Some(total),
            )?)
        }
        None => None,
    };
    let mut written = Written::none();
    while let Some(mut k) = results()? {
        k.r = k.r.with_registration(reg_error);
        each(&k);
        let r = &k.r;
        // Beyond the user's half-length nothing is measured: the flag says why there is none.
        let beyond = r.reach == Reach::Beyond;
        let (uncertainty, significant) = match beyond {
            true => (f64::NAN, false),
            false => (r.uncertainty, r.significant),
        };
        if let Some(w) = w.as_mut() {
            let (smoothed, event) = event_of(k.key)?;
            let extra = [
                r.measured(),
                uncertainty,
                significant as u8 as f64,
                r.std_dev1,
                r.std_dev2,
                r.count1 as f64,
                r.count2 as f64,
                r.normal[0],
                r.normal[1],
                r.normal[2],
                smoothed,
                event as f64,
                beyond as u8 as f64,
                !r.sign_known as u8 as f64,
            ];
            w.write(k.xyz, &extra)?;
        }
        written.core_points += 1;
        written.computed += r.measured().is_finite() as u64;
        written.significant += significant as u64;
        written.extended += (r.reach == Reach::Extended) as u64;
        written.beyond_reach += beyond as u64;
        written.sign_unknown += !r.sign_known as u64;
    }
    if let Some(w) = w {
        w.finish()?;
        out.add_file("m3c2.laz")?;
    }
    Ok(written)
}
