//! A campaign pair's column of the time series: its M3C2 distance at every one of the
//! campaign's core points, in key order (every pair of a campaign has the same core points), as
//! little-endian f32 (as m3c2.laz, timeseries.laz and timeseries.parquet store it: 0.06 µm at
//! 1 m, below any survey's precision) — the first pair's rows also hold each core point's x, y,
//! z as f64 before it (exact: the LAS grid's values). Not compressed: the distances' low bits
//! are noise (zstd saves little), and the campaign reads
//! every pair's column at once, a few pages each, where a zstd stream's decoder holds a
//! window and tables (≈ 0.2 MiB a pair: 80 MiB at 400 pairs).
//!
//! The campaign unit reads these columns, not the pairs' M3C2 results: those are
//! intermediate (released after the run, `Stage::INTERMEDIATE`), and a survey appended to the
//! campaign years later must not compute every old pair's M3C2 again to extend its time series.

use std::io::{BufReader, Read, Write};

use serde::{Deserialize, Serialize};

use super::stage::{Line, Planner, Scope, Stage, Total};
use super::Ctx;
use crate::error::{Error, Result};
use crate::plan::Spec;
use crate::store::UnitWriter;

/// The file of a series unit.
pub(crate) const FILE: &str = "series.bin";

/// One pair's column of the campaign's time series.
pub(crate) struct SeriesStage;

/// What a series unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct SeriesMeta {
    /// Core points (rows).
    pub(crate) core_points: u64,
    /// FNV-1a 64 over the core points' keys in order: every pair's must be the first's.
    pub(crate) keys: String,
    /// Values a row: 4 (x, y, z, distance) for the first pair, 1 for the others.
    pub(crate) width: usize,
}

impl Stage for SeriesStage {
    const KIND: &'static str = "series";
    const SCOPE: Scope = Scope::Pair;
    /// 2: the distance as f32 (was f64), in `series.bin`.
    const VERSION: u32 = 2;
    const LINE: Line = Line {
        name: "time series",
        counts: "core points",
        total: Total::Unknown,
    };
    type Meta = SeriesMeta;

    /// With a campaign: one per pair, over the pair's M3C2 results.
    fn plan(p: &mut Planner) -> Result<()> {
        if p.campaign.is_none() {
            return Ok(());
        }
        for pair in 0..p.plan.pairs.len() {
            let deps = p.pair_results(pair);
            let label = p.plan.pairs[pair].label.clone();
            let width = if pair == 0 { "xyz d" } else { "d" };
            p.add(Spec::pair(Self::KIND, pair), &label, &[width], deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<SeriesMeta> {
        let pair = ctx.pair(unit)?;
        let _held = ctx.reserve(
            super::merged::pair_merge_need(ctx.plan) + crate::memory::IO_HEADROOM,
            "a pair's column of the time series (its merge)",
        )?;
        let path = out.path(FILE)?;
        let file = std::fs::File::create(&path).map_err(|e| Error::output(&path, e))?;
        let mut z = std::io::BufWriter::with_capacity(super::scratch::BUFFER, file);
        let width = if pair == 0 { 4 } else { 1 };
        let mut merged = super::m3c2::Merged::new(ctx, pair)?;
        let (mut n, mut h) = (0u64, talus_tiling::Fnv64::new());
        let mut row = Vec::with_capacity(32);
        while let Some(r) = merged.next_result()? {
            h.write_u64(r.key);
            n += 1;
            row.clear();
            if width == 4 {
                for v in r.xyz {
                    row.extend_from_slice(&v.to_le_bytes());
                }
            }
            row.extend_from_slice(&(r.r.measured() as f32).to_le_bytes());
            z.write_all(&row).map_err(|e| Error::output(&path, e))?;
            if n % (1 << 16) == 0 {
                (ctx.progress)(1 << 16);
                crate::interrupt::check()?;
            }
        }
        (ctx.progress)(n % (1 << 16));
        z.flush().map_err(|e| Error::output(&path, e))?;
        out.add_file(FILE)?;
        Ok(SeriesMeta {
            core_points: n,
            keys: h.hex(),
            width,
        })
    }
}

/// A column read in order, a batch of values at a time (the Parquet writer's sources: a series
/// unit's column, the campaign's scratch columns).
pub(crate) trait Values {
    /// The next `out.len()` values.
    fn next_values(&mut self, out: &mut [f64]) -> Result<()>;
}

impl Values for super::scratch::RowsReader {
    fn next_values(&mut self, out: &mut [f64]) -> Result<()> {
        super::scratch::RowsReader::next_values(self, out)
    }
}

impl Values for SeriesReader {
    /// Of a one-value-a-row column.
    fn next_values(&mut self, out: &mut [f64]) -> Result<()> {
        for v in out {
            *v = self.next_row()?[0];
        }
        Ok(())
    }
}

/// The bytes of a row of `width` values: x, y, z as f64 (when `width` is 4), the distance as f32.
fn row_bytes(width: usize) -> usize {
    8 * (width - 1) + 4
}

/// A series unit's rows, read in order.
pub(crate) struct SeriesReader {
    input: BufReader<std::fs::File>,
    path: std::path::PathBuf,
    row: Vec<f64>,
    bytes: Vec<u8>,
}

impl SeriesReader {
    /// The rows of series unit `unit` (of the plan), `width` values each.
    pub(crate) fn open(ctx: &Ctx, unit: usize, width: usize) -> Result<SeriesReader> {
        let path = ctx.input(unit, FILE)?;
        let file = crate::store::open_store_file(&path).map_err(|e| Error::Damaged {
            path: path.clone(),
            problem: e.to_string(),
        })?;
        let input = BufReader::with_capacity(super::scratch::BUFFER, file);
        Ok(SeriesReader {
            input,
            path,
            row: vec![0.0; width],
            bytes: vec![0; row_bytes(width)],
        })
    }

    /// The next row (an error past the last: the caller knows the count).
    pub(crate) fn next_row(&mut self) -> Result<&[f64]> {
        self.input
            .read_exact(&mut self.bytes)
            .map_err(|e| Error::Damaged {
                path: self.path.clone(),
                problem: format!("a row of the time series: {e}"),
            })?;
        let (xyz, d) = self.bytes.split_at(self.bytes.len() - 4);
        for (v, b) in self.row.iter_mut().zip(xyz.chunks_exact(8)) {
            *v = f64::from_le_bytes(b.try_into().expect("8 bytes"));
        }
        let last = self.row.len() - 1;
        self.row[last] = f64::from(f32::from_le_bytes(d.try_into().expect("4 bytes")));
        Ok(&self.row)
    }
}
