//! Final outputs: m3c2.laz (core points with PDAL-named extra bytes, in canonical key order,
//! whatever the tiling) and summary.json. Both are written under a temporary name and renamed.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::path::Path;

use crate::error::{Error, Result};
use crate::io::las_out::{CoordinateGrid, ExtraDim, ExtraType, ResultWriter};
use crate::io::Crs;
use crate::pipeline::m3c2_pass::{chunk_path, read_chunk, KeyedResult, M3c2Results};
use crate::pipeline::workdir::WorkDir;
use crate::pipeline::Summary;

/// The extra dimensions of m3c2.laz, in record order (SPEC.md §2).
pub const M3C2_DIMS: &[ExtraDim] = &[
    ExtraDim {
        name: "m3c2_distance",
        ty: ExtraType::F64,
        description: "M3C2 distance t2 - t1",
    },
    ExtraDim {
        name: "m3c2_uncertainty",
        ty: ExtraType::F64,
        description: "LoD95",
    },
    ExtraDim {
        name: "m3c2_significant",
        ty: ExtraType::U8,
        description: "1 when |distance| > LoD95",
    },
    ExtraDim {
        name: "m3c2_std_dev1",
        ty: ExtraType::F64,
        description: "std dev along normal, epoch 1",
    },
    ExtraDim {
        name: "m3c2_std_dev2",
        ty: ExtraType::F64,
        description: "std dev along normal, epoch 2",
    },
    ExtraDim {
        name: "m3c2_count1",
        ty: ExtraType::U32,
        description: "points in cylinder, epoch 1",
    },
    ExtraDim {
        name: "m3c2_count2",
        ty: ExtraType::U32,
        description: "points in cylinder, epoch 2",
    },
    ExtraDim {
        name: "normal_x",
        ty: ExtraType::F32,
        description: "oriented normal, x",
    },
    ExtraDim {
        name: "normal_y",
        ty: ExtraType::F32,
        description: "oriented normal, y",
    },
    ExtraDim {
        name: "normal_z",
        ty: ExtraType::F32,
        description: "oriented normal, z",
    },
    ExtraDim {
        name: "m3c2_smoothed",
        ty: ExtraType::F64,
        description: "smoothed distance (kept points)",
    },
    ExtraDim {
        name: "event_id",
        ty: ExtraType::U32,
        description: "change event, 0 = none",
    },
];

/// Counts of what m3c2.laz holds.
pub struct Written {
    pub core_points: u64,
    pub computed: u64,
    pub significant: u64,
}

/// Streams the per-tile result chunks in global key order (a k-way merge holding one chunk per
/// tile), so the output is the same whatever the tile size.
pub struct MergedResults<'a> {
    results: &'a M3c2Results,
    /// Per tile: the loaded chunk, position in it, next chunk number.
    cursors: Vec<(Vec<KeyedResult>, usize, usize)>,
    heap: BinaryHeap<Reverse<(u64, usize)>>,
}

impl<'a> MergedResults<'a> {
    pub fn new(results: &'a M3c2Results) -> Result<Self> {
        let mut m = MergedResults {
            results,
            cursors: vec![(Vec::new(), 0, 0); results.chunks.len()],
            heap: BinaryHeap::new(),
        };
        for t in 0..results.chunks.len() {
            m.advance_chunk(t)?;
        }
        Ok(m)
    }

    fn advance_chunk(&mut self, t: usize) -> Result<()> {
        let (id, n) = self.results.chunks[t];
        let c = &mut self.cursors[t];
        while c.1 >= c.0.len() && c.2 < n {
            c.0 = read_chunk(&chunk_path(&self.results.dir, id, c.2))?;
            c.1 = 0;
            c.2 += 1;
        }
        if c.1 < c.0.len() {
            self.heap.push(Reverse((c.0[c.1].key, t)));
        }
        Ok(())
    }

    /// The next result in key order.
    pub fn next_result(&mut self) -> Result<Option<KeyedResult>> {
        let Some(Reverse((_, t))) = self.heap.pop() else {
            return Ok(None);
        };
        let c = &mut self.cursors[t];
        let r = c.0[c.1];
        c.1 += 1;
        if c.1 < c.0.len() {
            self.heap.push(Reverse((c.0[c.1].key, t)));
        } else {
            self.advance_chunk(t)?;
        }
        Ok(Some(r))
    }
}

/// Write DIR/m3c2.laz. `event_of(key)` gives the smoothed distance and event id of a core point
/// (NaN, 0 when it is in no event); `each` sees every result in the same order (the viewer's
/// terrain sample rides on this pass instead of merging the results again).
pub fn write_m3c2_laz(
    wd: &WorkDir,
    results: &M3c2Results,
    reg_error: f64,
    crs: &Crs,
    grid: CoordinateGrid,
    event_of: &dyn Fn(u64) -> (f64, u32),
    each: &mut dyn FnMut(&KeyedResult),
) -> Result<Written> {
    let path = wd.out.join("m3c2.laz");
    let mut w = ResultWriter::create_on_grid(&path, crs, M3C2_DIMS, grid)?;
    let mut merged = MergedResults::new(results)?;
    let mut written = Written {
        core_points: 0,
        computed: 0,
        significant: 0,
    };
    while let Some(mut k) = merged.next_result()? {
        k.r = k.r.with_registration(reg_error);
        each(&k);
        let r = &k.r;
        let (smoothed, event) = event_of(k.key);
        let extra = [
            r.distance,
            r.uncertainty,
            r.significant as u8 as f64,
            r.std_dev1,
            r.std_dev2,
            r.count1 as f64,
            r.count2 as f64,
            r.normal[0],
            r.normal[1],
            r.normal[2],
            smoothed,
            event as f64,
        ];
        w.write(k.xyz, &extra)?;
        written.core_points += 1;
        written.computed += r.distance.is_finite() as u64;
        written.significant += r.significant as u64;
    }
    w.finish()?;
    Ok(written)
}

/// Write DIR/summary.json atomically.
pub fn write_summary(wd: &WorkDir, summary: &Summary) -> Result<()> {
    let path = wd.out.join("summary.json");
    let text = serde_json::to_string_pretty(summary)
        .map_err(|e| Error::Internal(format!("summary: {e}")))?;
    write_atomic(&path, text.as_bytes())
}

/// Write `bytes` to `path` via a temporary sibling and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    talus_tiling::atomic_write(path, bytes).map_err(crate::pipeline::tiles::tiling_error)
}
