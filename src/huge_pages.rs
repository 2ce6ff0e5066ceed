//! An allocator that backs the large arrays of a simulation with transparent huge pages (issue
//! #16).
//!
//! A step of 10⁵ grains sweeps some 55 MB of per-grain and per-pair arrays (grains, frames,
//! pair records, stress records, the neighbour list), more than the last-level cache holds,
//! in 4 KB pages by default: more pages than the processor's second-level TLB maps, so that
//! its page walks add to each cache miss. Linux backs a range with 2 MB pages where the
//! program asks for them (`madvise(MADV_HUGEPAGE)`, honoured when
//! `/sys/kernel/mm/transparent_hugepage/enabled` is `always` or `madvise`, the usual
//! settings). This allocator asks for them for every allocation of at least
//! [`HUGE_ARRAY_BYTES`], which it places in whole huge pages; all others go to the system
//! allocator unchanged. Results do not depend on it: it changes where arrays lie, not what they
//! hold.
//!
//! Each large array starts a different distance past its first huge page's start (its
//! *colour*): arrays that all began on a 2 MB boundary put the entries of one grain (its
//! state, frame, stress record, ...) at the same low address bits, which the caches index by,
//! and which the processor compares first when it checks a load against earlier stores. Measured on one AMD family-26 machine (10⁵ grains, one thread, alternated
//! rounds): with every large array on a boundary, rigid discs stepped 1.015 times as fast as
//! without huge pages; with the colours, 1.05 (7 rounds), LAMMPS's packing 1.05 and the full
//! level 1.01 (5 rounds each). glibc's own partial version
//! (`GLIBC_TUNABLES=glibc.malloc.hugetlb=1`, 39 of 95 MB in huge pages) gave rigid discs 1.04.
//!
//! The command-line program installs it (`#[global_allocator]` in `main.rs`); a program that
//! links the library chooses its own allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The size of a huge page on x86-64 and most aarch64 Linux systems.
pub const HUGE_PAGE_BYTES: usize = 2 << 20;

/// Allocations from this size on are given whole huge pages: large enough that the rounding
/// (under 2 MB, plus the colours' room of 126 KB) adds at most half to an array, and a sample
/// of a few thousand grains allocates none.
pub const HUGE_ARRAY_BYTES: usize = 4 << 20;

/// The system allocator, with huge pages for large arrays (see the module's documentation).
pub struct HugePageAllocator;

/// How many colours large arrays take in turn.
const COLOURS: usize = 31;

/// The distance between two colours: a 4 KB page and three cache lines, so that the arrays'
/// starts differ in their low twelve bits (by multiples of 192 bytes) and in the bits above
/// them that pick a set of the second-level cache.
const COLOUR_STRIDE: usize = 4096 + 192;

/// The next large array's offset from its first huge page's start: colours in turn.
fn colour_offset() -> usize {
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    NEXT.fetch_add(1, Ordering::Relaxed) % COLOURS * COLOUR_STRIDE
}

/// The layout a large allocation takes from the system: aligned to a huge page and a whole
/// number of them long, with room for the largest colour offset before the caller's bytes. The
/// same function of the caller's layout at allocation and release, as the system allocator
/// needs.
#[inline]
fn huge_layout(layout: Layout) -> Option<Layout> {
    // The colour offsets must keep the caller's alignment: 4288 = 64 x 67 keeps 64 bytes'.
    if layout.size() < HUGE_ARRAY_BYTES || !COLOUR_STRIDE.is_multiple_of(layout.align()) {
        return None;
    }
    let size = layout
        .size()
        .checked_add((COLOURS - 1) * COLOUR_STRIDE)?
        .checked_next_multiple_of(HUGE_PAGE_BYTES)?;
    Layout::from_size_align(size, HUGE_PAGE_BYTES).ok()
}

/// Asks the kernel to back `len` bytes from `at` (a huge page's start) with huge pages. A
/// request the kernel refuses (huge pages disabled) leaves the ordinary pages: nothing to do.
#[inline]
fn advise_huge_pages(at: *mut u8, len: usize) {
    #[cfg(target_os = "linux")]
    // SAFETY: `at..at + len` is memory this allocator just obtained and owns; the advice
    // changes how it is backed, not its contents.
    unsafe {
        libc::madvise(at.cast(), len, libc::MADV_HUGEPAGE);
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (at, len);
}

// SAFETY: every allocation goes to `System` with either the caller's layout or its
// `huge_layout`, and is released to it with the same one (`huge_layout` is a function of the
// caller's layout, which `dealloc` and `realloc` receive as it was given).
unsafe impl GlobalAlloc for HugePageAllocator {
    #[inline]
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        match huge_layout(layout) {
            None => unsafe { System.alloc(layout) },
            Some(huge) => {
                let start = unsafe { System.alloc(huge) };
                if start.is_null() {
                    return start;
                }
                advise_huge_pages(start, huge.size());
                // The offset is a multiple of COLOUR_STRIDE, hence of the caller's alignment
                // (`huge_layout` takes only alignments that divide it), and leaves room for
                // `layout.size()` bytes.
                unsafe { start.add(colour_offset()) }
            }
        }
    }

    #[inline]
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if huge_layout(layout).is_none() {
            return unsafe { System.alloc_zeroed(layout) };
        }
        // Advised before the zeros touch it (pages touched first are small ones).
        let at = unsafe { self.alloc(layout) };
        if !at.is_null() {
            unsafe { std::ptr::write_bytes(at, 0, layout.size()) };
        }
        at
    }

    #[inline]
    unsafe fn dealloc(&self, at: *mut u8, layout: Layout) {
        match huge_layout(layout) {
            None => unsafe { System.dealloc(at, layout) },
            // The allocation's start: the huge page the array begins in (its colour offset is
            // less than a huge page).
            Some(huge) => unsafe {
                let start = at.wrapping_sub(at as usize % HUGE_PAGE_BYTES);
                System.dealloc(start, huge)
            },
        }
    }

    #[inline]
    unsafe fn realloc(&self, at: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY (of the layout): the caller guarantees that `new_size`, rounded up to the
        // alignment, does not overflow `isize`.
        let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        if huge_layout(layout).is_none() && huge_layout(new_layout).is_none() {
            return unsafe { System.realloc(at, layout, new_size) };
        }
        // A large array on either side: a new allocation and a copy (a `Vec` grows by
        // doubling, so rarely).
        let moved = unsafe { self.alloc(new_layout) };
        if !moved.is_null() {
            unsafe {
                std::ptr::copy_nonoverlapping(at, moved, layout.size().min(new_size));
                self.dealloc(at, layout);
            }
        }
        moved
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_arrays_get_huge_pages_of_their_own_colour_and_keep_their_contents() {
        // Expectation: below the threshold, or at an alignment of more than 64 bytes, the
        // caller's layout is kept; from the threshold on, the system's allocation starts on a
        // huge page and spans whole ones, with room for the array past its colour offset (a
        // multiple of the colour stride, different for two arrays in a row); values survive
        // growth across the threshold and back (realloc), and zeroed allocations read zero.
        assert_eq!(huge_layout(Layout::new::<[u8; 64]>()), None);
        let big = Layout::from_size_align(HUGE_ARRAY_BYTES + 1, 8).unwrap();
        let huge = huge_layout(big).unwrap();
        assert_eq!(huge.align(), HUGE_PAGE_BYTES);
        assert_eq!(huge.size(), HUGE_ARRAY_BYTES + HUGE_PAGE_BYTES);
        for align in [128, 4096, 8192] {
            let aligned = Layout::from_size_align(HUGE_ARRAY_BYTES, align).unwrap();
            assert_eq!(
                huge_layout(aligned),
                None,
                "an alignment the colours would break"
            );
        }
        let tight = Layout::from_size_align(3 * HUGE_PAGE_BYTES - 1000, 64).unwrap();
        let huge = huge_layout(tight).unwrap();
        assert_eq!(huge.size(), 4 * HUGE_PAGE_BYTES, "room for the colours");

        let allocator = HugePageAllocator;
        unsafe {
            let small = Layout::from_size_align(1 << 20, 8).unwrap();
            let at = allocator.alloc(small).cast::<u64>();
            assert!(!at.is_null());
            for k in 0..(1 << 17) {
                *at.add(k) = k as u64 * 3;
            }
            let grown = allocator
                .realloc(at.cast(), small, 3 * HUGE_ARRAY_BYTES)
                .cast::<u64>();
            assert!(!grown.is_null());
            assert_eq!(grown as usize % HUGE_PAGE_BYTES % COLOUR_STRIDE, 0);
            assert!((0..(1 << 17)).all(|k| *grown.add(k) == k as u64 * 3));
            let big = Layout::from_size_align(3 * HUGE_ARRAY_BYTES, 8).unwrap();
            let shrunk = allocator.realloc(grown.cast(), big, 1 << 19).cast::<u64>();
            assert!((0..(1 << 16)).all(|k| *shrunk.add(k) == k as u64 * 3));
            allocator.dealloc(shrunk.cast(), Layout::from_size_align(1 << 19, 8).unwrap());

            // Two large arrays in a row take different colours.
            let zeroed = allocator.alloc_zeroed(big).cast::<u64>();
            assert_ne!(
                zeroed as usize % HUGE_PAGE_BYTES,
                grown as usize % HUGE_PAGE_BYTES
            );
            assert!((0..3 * HUGE_ARRAY_BYTES / 8).all(|k| *zeroed.add(k) == 0));
            allocator.dealloc(zeroed.cast(), big);
        }
    }
}
