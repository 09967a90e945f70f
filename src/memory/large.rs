//! The process's allocator: glibc's malloc for small blocks, and large blocks (at least
//! [`super::MMAP_THRESHOLD`]) mapped on their own with their whole 2 MiB stretches on
//! transparent huge pages.
//!
//! Why: a large block's pages are faulted in one at a time as it is first written, and on a
//! virtual machine a fault costs ≈ 3.4 µs per 4 KiB page (a 64 MiB block: 55 ms to touch; 28 ms
//! with the pages populated in one call; 5 ms on huge pages — measured here with mmap, madvise
//! and a write per page). The M3C2 benchmark's run (2 × 1M points) faulted 102,000 times, a
//! fifth of its CPU time, nearly all in the tiles, column indexes and decoded surveys — blocks
//! of megabytes written whole right after they are allocated.
//!
//! What it keeps from glibc's handling of such blocks (mapped on their own since
//! `MMAP_THRESHOLD`): a freed block goes back to the system at once, so a unit's peak never
//! stacks on the last one's leftovers. A block starts on a 2 MiB boundary and is advised huge
//! (`madvise(MADV_HUGEPAGE)`, honoured where the system's THP mode is `madvise` or `always`);
//! the kernel puts huge pages only on the 2 MiB stretches it covers whole, so its tail stays on
//! 4 KiB pages and a block is never resident beyond its last 4 KiB page; a block written only in
//! part is resident in whole 2 MiB pages (the 120M pair's peak at `--memory 164MiB`: 150.4 →
//! 164.5 MiB). Where the kernel ignores the advice, this is glibc's behaviour.

use std::alloc::{GlobalAlloc, Layout, System};

/// Blocks of at least this many bytes are mapped here.
const LARGE: usize = super::MMAP_THRESHOLD as usize;
/// A transparent huge page (x86-64, aarch64 with 4 KiB pages).
const HUGE: usize = 2 << 20;
const PAGE: usize = 4096;

/// See the module doc.
pub(crate) struct Allocator;

fn large(layout: &Layout) -> bool {
    cfg!(target_os = "linux") && layout.size() >= LARGE && layout.align() <= PAGE
}

fn pages(size: usize) -> usize {
    size.div_ceil(PAGE) * PAGE
}

/// A fresh zeroed mapping of `size` bytes starting on a 2 MiB boundary; null when the system
/// refuses.
#[cfg(target_os = "linux")]
unsafe fn map(size: usize) -> *mut u8 {
    let len = pages(size);
    // Over-map by a huge page to choose an aligned start, then hand the rest back.
    let raw = libc::mmap(
        std::ptr::null_mut(),
        len + HUGE,
        libc::PROT_READ | libc::PROT_WRITE,
        libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
        -1,
        0,
    );
    if raw == libc::MAP_FAILED {
        return std::ptr::null_mut();
    }
    let raw = raw as usize;
    let start = raw.next_multiple_of(HUGE);
    if start > raw {
        libc::munmap(raw as *mut libc::c_void, start - raw);
    }
    let end = raw + len + HUGE;
    if end > start + len {
        libc::munmap((start + len) as *mut libc::c_void, end - (start + len));
    }
    advise(start, len);
    start as *mut u8
}

#[cfg(not(target_os = "linux"))]
unsafe fn map(_size: usize) -> *mut u8 {
    unreachable!("large blocks are mapped here on Linux only")
}

/// Advise `[start, start + len)` (one whole mapping) huge. The kernel puts a huge page only on
/// an aligned 2 MiB stretch the mapping covers whole, so the tail stays on 4 KiB pages; advising
/// the whole mapping, not just those stretches, keeps it one mapping, which `mremap` needs.
/// Advice: a failure is harmless.
#[cfg(target_os = "linux")]
unsafe fn advise(start: usize, len: usize) {
    if len >= HUGE {
        libc::madvise(start as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
    }
}

#[cfg(target_os = "linux")]
unsafe fn unmap(ptr: *mut u8, size: usize) {
    libc::munmap(ptr as *mut libc::c_void, pages(size));
}

#[cfg(not(target_os = "linux"))]
unsafe fn unmap(_ptr: *mut u8, _size: usize) {
    unreachable!("large blocks are mapped here on Linux only")
}

// SAFETY: every block is either System's (small or over-aligned, both ways by `large` of the
// same layout) or a private anonymous mapping of `pages(size)` bytes made here, page-aligned
// (so aligned for any `align() <= PAGE`), zeroed, and unmapped only by `dealloc`/`realloc` with
// the size it was made for.
unsafe impl GlobalAlloc for Allocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if large(&layout) {
            map(layout.size())
        } else {
            System.alloc(layout)
        }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if large(&layout) {
            // A fresh anonymous mapping is zeroed.
            map(layout.size())
        } else {
            System.alloc_zeroed(layout)
        }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if large(&layout) {
            unmap(ptr, layout.size())
        } else {
            System.dealloc(ptr, layout)
        }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let new = Layout::from_size_align_unchecked(new_size, layout.align());
        match (large(&layout), large(&new)) {
            (false, false) => System.realloc(ptr, layout, new_size),
            #[cfg(target_os = "linux")]
            (true, true) => {
                // The kernel moves the pages (no copy); a grown block's new stretches advised.
                let (old_len, new_len) = (pages(layout.size()), pages(new_size));
                if old_len == new_len {
                    return ptr;
                }
                let p = libc::mremap(
                    ptr as *mut libc::c_void,
                    old_len,
                    new_len,
                    libc::MREMAP_MAYMOVE,
                );
                if p == libc::MAP_FAILED {
                    return std::ptr::null_mut();
                }
                advise(p as usize, new_len);
                p as *mut u8
            }
            _ => {
                // Across the threshold: a new block, the contents copied.
                let p = self.alloc(new);
                if !p.is_null() {
                    std::ptr::copy_nonoverlapping(ptr, p, layout.size().min(new_size));
                    self.dealloc(ptr, layout);
                }
                p
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Large blocks come zeroed where asked, keep their contents across growth and shrinking
    /// (within the large size, across the threshold both ways), and are aligned as asked.
    #[test]
    fn large_blocks_behave_as_the_system_allocator_s() {
        let a = Allocator;
        unsafe {
            let l = Layout::from_size_align(LARGE + 12345, 64).unwrap();
            let p = a.alloc_zeroed(l);
            assert!(!p.is_null() && (p as usize).is_multiple_of(64));
            let s = std::slice::from_raw_parts_mut(p, l.size());
            assert!(s.iter().all(|&b| b == 0));
            for (i, b) in s.iter_mut().enumerate() {
                *b = (i % 251) as u8;
            }
            let check = |p: *mut u8, n: usize| {
                let s = std::slice::from_raw_parts(p, n);
                assert!(s.iter().enumerate().all(|(i, &b)| b == (i % 251) as u8));
            };
            // Grow (moved by the kernel), shrink within large, shrink below, grow above.
            let p = a.realloc(p, l, 3 * LARGE);
            check(p, l.size());
            let l = Layout::from_size_align(3 * LARGE, 64).unwrap();
            let p = a.realloc(p, l, LARGE + 7);
            check(p, LARGE + 7);
            let l = Layout::from_size_align(LARGE + 7, 64).unwrap();
            let p = a.realloc(p, l, 1000);
            check(p, 1000);
            let l = Layout::from_size_align(1000, 64).unwrap();
            let p = a.realloc(p, l, 2 * LARGE);
            check(p, 1000);
            a.dealloc(p, Layout::from_size_align(2 * LARGE, 64).unwrap());
        }
        // Through Vec, as the program uses it.
        let mut v: Vec<u64> = Vec::with_capacity(LARGE / 8);
        v.extend(0..(LARGE as u64));
        assert_eq!(v[LARGE - 1], LARGE as u64 - 1);
        v.truncate(10);
        v.shrink_to_fit();
        assert_eq!(v, (0..10).collect::<Vec<u64>>());
    }
}
