//! Memory: the budget (`--memory`) and what the allocator keeps.
//!
//! `--memory` bounds the whole process's resident memory (what `/usr/bin/time -v` reports and a
//! Slurm task is killed for). The budget is split as: the process's own base (`BASE`: code,
//! thread stacks, the plan), the allocator's slack (`SLACK` of the budget), and the `Pool`
//! the units reserve from before they hold anything large (each unit's need comes from its
//! inputs' counts and a measured cost per item, see the `need` constants of each unit kind).
//!
//! glibc's malloc gives each thread that contends for the heap an arena of its own (up to 8 per
//! core) and returns freed memory to the system only from the top of a heap: after a large unit,
//! megabytes of free pages stay resident in arenas no thread uses any more, and the next unit's
//! peak stacks on top of them. Two remedies, both measured on the 5.2M-point cliff
//! (benches/memory.sh): at most `ARENAS` arenas, and every free page handed back
//! (`malloc_trim`) after each unit. A third, measured on the 120M-point pair: large blocks
//! always mapped on their own (`MMAP_THRESHOLD`), by the process's allocator (`large`),
//! on transparent huge pages where they span them.

pub(crate) mod large;
pub(crate) mod pool;

pub(crate) use pool::{Pool, Reservation};

use crate::error::{Error, Result};

/// Resident bytes of the process whatever runs: the binary, thread stacks, the plan, the
/// progress lines (measured: 10–12 MiB with no unit running; volumes units without events), and
/// the alignment sample's memo of the first survey (at most 4 MiB, `units::sample::MEMO`).
pub(crate) const BASE: u64 = 16 << 20;

/// Share of the budget left to the allocator's slack (freed memory not yet handed back, arena
/// headers): measured peak minus the sum of reservations on the 5.2M-point cliff at 300 MiB.
pub(crate) const SLACK: f64 = 0.05;

/// The smallest budget: the one whose pool holds the points unit (m3c2.laz) and the stable
/// ground's fixed sample, the largest needs that do not depend on the data (a tiling unit's need
/// is a share of the budget; see `units::tiling::need`).
pub(crate) const MIN_BUDGET: u64 = 160 << 20;

/// What a unit holds beside what its need counts per item (small vectors, a thread's locals,
/// an index's fixed part): added to the need of every unit that computes over points in memory
/// (a tile's M3C2, the orientation field, core points, an event's volume).
pub(crate) const HEADROOM: u64 = 4 << 20;

/// [`HEADROOM`] for a unit that also streams files through buffers of their own: a tiling's
/// reader, decoder and writer, a merge of sorted runs, the Parquet writer.
pub(crate) const IO_HEADROOM: u64 = 8 << 20;

/// The pool of a budget of `budget` bytes: what is left after `BASE` and `SLACK`.
pub fn pool_for(budget: u64) -> Pool {
    Pool::new(pool_bytes(budget))
}

/// The pool's size for a budget.
pub(crate) fn pool_bytes(budget: u64) -> u64 {
    budget.saturating_sub(BASE + (SLACK * budget as f64) as u64)
}

/// The smallest budget whose pool holds `need` bytes.
pub(crate) fn budget_for(need: u64) -> u64 {
    ((need + BASE) as f64 / (1.0 - SLACK)).ceil() as u64
}

/// Bytes in MiB, rounded up (a budget, a need or a peak, for messages and reports: never shown
/// below what it is).
pub(crate) fn mib(bytes: u64) -> u64 {
    bytes.div_ceil(1 << 20)
}

/// Refuse (exit 2) a need no pool of a `budget`-byte budget could hold, with the smallest
/// budget that would.
pub(crate) fn refuse_unless_fits(need: u64, budget: u64, what: &str) -> Result<()> {
    if need > pool_bytes(budget) {
        return Err(too_small(need, budget, what));
    }
    Ok(())
}

fn too_small(need: u64, budget: u64, what: &str) -> Error {
    Error::Usage(format!(
        "--memory {} MiB is too small: {what} needs {} MiB; the smallest budget that works is --memory {}MiB",
        mib(budget),
        mib(need),
        mib(budget_for(need))
    ))
}

/// Reserve `need` bytes for `what` from `pool` (a `budget`-byte budget's), waiting for others
/// to give back theirs; refused as [`refuse_unless_fits`] when the pool could never hold it.
pub(crate) fn reserve<'a>(
    pool: &'a Pool,
    need: u64,
    budget: u64,
    what: &str,
) -> Result<Reservation<'a>> {
    if need > pool.limit() {
        return Err(too_small(need, budget, what));
    }
    pool.reserve(need, &crate::interrupt::requested)
        .ok_or(Error::Interrupted)
}

/// Resident bytes of this process now (`None` where /proc is not there).
pub fn resident_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * page_size())
}

fn page_size() -> u64 {
    // SAFETY: sysconf has no preconditions; it only reads a system constant.
    let n = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    if n > 0 {
        n as u64
    } else {
        4096
    }
}

/// Arenas allowed: one per core of these 2-core machines; more only fragments.
pub(crate) const ARENAS: i32 = 2;

/// Allocations of at least this many bytes get pages of their own, handed back when freed.
///
/// glibc starts this threshold at 128 KiB but raises it (up to 32 MiB) each time such a block
/// is freed, so after the first units the large buffers (decoded chunks, merge chunks, LAZ
/// chunks, triangulations) come from the arenas, where the holes they leave between smaller
/// live blocks stay resident and the next unit's peak stacks on them. Setting it fixes it
/// (and turns the raising off). Measured on the 120M-point pair at `--memory 164MiB`, its
/// floor: peak 200 and 185 MiB in two runs with glibc's rule (1.22 ×, 1.13 ×; the outputs unit
/// alone in a process 157 MiB), 160 MiB at 1 MiB, 151 MiB at 4 MiB, the run's time unchanged
/// at 4 MiB (261 s) and 5 % longer at 1 MiB (the volumes' page faults).
pub(crate) const MMAP_THRESHOLD: i32 = 4 << 20;

/// Limit glibc's arenas and fix its mmap threshold (call once, before threads start).
pub(crate) fn limit_arenas() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets an allocator parameter; called before other threads exist.
    unsafe {
        libc::mallopt(libc::M_ARENA_MAX, ARENAS);
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD);
    }
}

/// Hand every free page of every arena back to the system.
pub(crate) fn trim() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim is thread-safe and only releases memory the allocator holds free.
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budget_for_inverts_pool_bytes() {
        for need in [1u64 << 20, 100 << 20, 3 << 30] {
            let b = budget_for(need);
            assert!(pool_bytes(b) >= need);
            assert!(pool_bytes(b - (1 << 20)) < need + (1 << 20));
        }
    }

    #[test]
    fn a_need_beyond_the_pool_is_refused_with_the_budget_that_works() {
        let budget = 300 << 20;
        let pool = pool_for(budget);
        let e = reserve(
            &pool,
            400 << 20,
            budget,
            "tile t_0001_0002 (4000000 points)",
        )
        .expect_err("refused");
        let msg = e.to_string();
        assert_eq!(e.exit_code(), 2);
        assert!(
            msg.contains("--memory 300 MiB is too small: tile t_0001_0002"),
            "{msg}"
        );
        let want = format!("--memory {}MiB", mib(budget_for(400 << 20)));
        assert!(msg.ends_with(&want), "{msg}");
        // What fits is granted and given back.
        drop(reserve(&pool, pool.limit(), budget, "all").expect("fits"));
        assert_eq!(pool.used(), 0);
    }
}
