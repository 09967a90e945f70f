//! Whether the memory budget can hold a pair's densest tile, the one need the tile layout cannot
//! shrink (a tile is at least four halos wide, so a neighbourhood is never cut): refused with
//! exit 2 and the smallest budget that works, as early as it is certain.
//!
//! Before anything runs, from the plan alone: every point is owned by exactly one tile, so some
//! tile's halo box holds at least a pair's points over the number of tiles (a bound that holds
//! whatever the points' layout; with one tile, the whole pair). Right after the pair's tilings,
//! from their records' per-tile counts: the densest tile exactly, before any M3C2 unit holds
//! anything (`super::run`), so a dense patch late in the tile order does not cost the
//! stage's other tiles first.

use super::need;
use crate::error::{Error, Result};
use crate::memory::refuse_unless_fits;
use crate::plan::Plan;
use crate::units::tiling::TilingMeta;

/// Refuse the plan when pair `pair`'s densest tile certainly does not fit the budget.
pub(crate) fn check_planned(plan: &Plan, pair: usize) -> Result<()> {
    let p = &plan.pairs[pair];
    let points = plan.surveys[p.before].points + plan.surveys[p.after].points;
    let tiles = plan.layout.len() as u64;
    let least = points.div_ceil(tiles.max(1));
    let whose = match plan.pairs.len() {
        1 => "the pair's".to_string(),
        _ => format!("pair {}'s", p.label),
    };
    let what = if tiles == 1 {
        format!(
            "{whose} one tile ({points} points; a tile is at least {:.1} units wide, four halos)",
            4.0 * plan.layout.halo
        )
    } else {
        format!(
            "{whose} densest tile (at least {least} points: {points} over {tiles} tiles of side {:.1})",
            plan.layout.tile_size
        )
    };
    refuse_unless_fits(need(least), plan.params.memory_bytes.value, &what)
}

/// Points per tile of a pair (both surveys, halos included, in grid order) from its two tilings'
/// records.
pub(crate) fn pair_tile_points(
    plan: &Plan,
    before: &TilingMeta,
    after: &TilingMeta,
) -> Result<Vec<u64>> {
    let tiles = plan.layout.len();
    if before.tile_points.len() != tiles || after.tile_points.len() != tiles {
        return Err(Error::Internal(format!(
            "tilings of {} and {} tiles for a layout of {tiles}",
            before.tile_points.len(),
            after.tile_points.len()
        )));
    }
    Ok(before
        .tile_points
        .iter()
        .zip(&after.tile_points)
        .map(|(b, a)| b + a)
        .collect())
}

/// Refuse the budget when the densest of a pair's tiles (`points` per tile, in grid order, see
/// [`pair_tile_points`]) does not fit it, naming the first such tile in grid order (the same
/// whichever unit checks).
pub(crate) fn check_tiled(plan: &Plan, points: &[u64]) -> Result<()> {
    let grid = plan.layout.grid()?;
    let Some((densest, &n)) = grid
        .tiles()
        .map(|t| (t, &points[grid.index(t)]))
        .min_by_key(|&(_, n)| std::cmp::Reverse(*n))
    else {
        return Ok(());
    };
    refuse_unless_fits(
        need(n),
        plan.params.memory_bytes.value,
        &format!(
            "tile {} ({n} points with its halo, the pair's densest)",
            densest.name()
        ),
    )
}
