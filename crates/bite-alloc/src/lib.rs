//! The `bite` binary's global allocator (and the benches', so that they
//! measure what the binary runs): mimalloc, called the way its fast path
//! expects.
//!
//! The `mimalloc` crate hands every request to `mi_malloc_aligned`, with
//! the layout's alignment. In mimalloc 3 that call takes the small-block
//! fast path only when the next free block happens to suit; otherwise (a
//! page whose free list ran out, a block over 1 KiB) it falls to a generic
//! path that, for a block size that is not a power of two, over-allocates
//! by the alignment and marks the page as holding aligned blocks (which
//! slows their frees too). Every block of mimalloc is 8-byte aligned, so
//! a request aligned to 8 or less needs none of that: it goes to plain
//! `mi_malloc`, the rest to the aligned calls. A kernel's decision step
//! ran 3.5 % fewer instructions (docs/performance.md, "2026-12-02,
//! night").

use libmimalloc_sys as ffi;
use std::alloc::{GlobalAlloc, Layout};
use std::ffi::c_void;

/// The alignment every mimalloc block has, whatever its size: blocks are
/// whole machine words, laid from word-aligned page starts.
const BLOCK_ALIGN: usize = std::mem::size_of::<usize>();

/// mimalloc, with requests aligned to a word or less on its plain calls.
pub struct MiMalloc;

/// A new block for `layout`: from `plain` when a word's alignment does,
/// else from `aligned`.
///
/// # Safety
/// `plain` and `aligned` are mimalloc's allocation calls (see the impl).
#[inline(always)]
unsafe fn fresh(
    layout: Layout,
    plain: unsafe extern "C" fn(usize) -> *mut c_void,
    aligned: unsafe extern "C" fn(usize, usize) -> *mut c_void,
) -> *mut u8 {
    // SAFETY: the caller's contract; sizes and alignments as `Layout` has them.
    unsafe {
        if layout.align() <= BLOCK_ALIGN {
            plain(layout.size()) as *mut u8
        } else {
            aligned(layout.size(), layout.align()) as *mut u8
        }
    }
}

// SAFETY: every method hands mimalloc a request it documents as valid and
// returns what mimalloc returns. A layout aligned to `BLOCK_ALIGN` or less
// goes to `mi_malloc` / `mi_zalloc` / `mi_realloc`, whose blocks are always
// word-aligned (mimalloc's minimal block is a word and block sizes are
// multiples of it), so the pointer meets the layout's alignment; any other
// goes to the `_aligned` variant with the layout's alignment (a power of
// two, as `Layout` guarantees). `dealloc` frees with `mi_free`, which takes
// a block from any of these calls. Null is returned on exhaustion, as
// `GlobalAlloc` expects.
unsafe impl GlobalAlloc for MiMalloc {
    #[inline]
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: see the impl.
        unsafe { fresh(layout, ffi::mi_malloc, ffi::mi_malloc_aligned) }
    }

    #[inline]
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: see the impl.
        unsafe { fresh(layout, ffi::mi_zalloc, ffi::mi_zalloc_aligned) }
    }

    #[inline]
    unsafe fn dealloc(&self, ptr: *mut u8, _layout: Layout) {
        // SAFETY: `ptr` came from this allocator (the caller's contract).
        unsafe { ffi::mi_free(ptr as *mut c_void) }
    }

    #[inline]
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: `ptr` came from this allocator with `layout` (the
        // caller's contract); the new block keeps the alignment, as above.
        unsafe {
            if layout.align() <= BLOCK_ALIGN {
                ffi::mi_realloc(ptr as *mut c_void, new_size) as *mut u8
            } else {
                ffi::mi_realloc_aligned(ptr as *mut c_void, new_size, layout.align()) as *mut u8
            }
        }
    }
}

/// mimalloc's option `purge_delay` (its place in `mi_option_t`,
/// `mimalloc.h`; the sys crate names no constant for it).
const MI_OPTION_PURGE_DELAY: ffi::mi_option_t = 15;

/// The environment variable through which mimalloc reads that option.
const PURGE_DELAY_ENV: &str = "MIMALLOC_PURGE_DELAY";

/// Keep the memory the process frees for its own next allocations instead
/// of handing it back to the system (mimalloc's `purge_delay` of -1, "no
/// purging at all"), unless `MIMALLOC_PURGE_DELAY` in the environment says
/// otherwise. Returns whether it was set.
///
/// For a process that ends with its work (a run, a sweep, a bench): by
/// default mimalloc gives back pages left unused for a second, and every
/// page a large team's run takes back is faulted in and cleared again by
/// the kernel (5.5 % of a 100,000-robot team's samples on one thread;
/// with this, that team ran 1-35 % faster in nine alternated pairs:
/// docs/performance.md, "2026-12-02, afternoon"). The peak grows a little
/// (10-45 MB there), and the process keeps it until it exits, so the
/// long-running services (`bite studio`, `bite robot`) keep the default.
/// Call it first in `main`, before other threads start.
pub fn keep_freed_memory() -> bool {
    if std::env::var_os(PURGE_DELAY_ENV).is_some() {
        return false;
    }
    // SAFETY: `mi_option_set` stores one value in mimalloc's option table;
    // the option is in range and -1 is a value it documents for it.
    unsafe { ffi::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every alignment up to a page, sizes from zero-adjacent to large:
    /// the blocks are aligned, zeroed when asked, keep their bytes through
    /// a growing and a shrinking realloc, and free.
    #[test]
    fn blocks_meet_their_layout_through_alloc_zero_realloc_and_free() {
        let a = MiMalloc;
        for align in [1, 2, 4, 8, 16, 32, 64, 4096] {
            for size in [1, 7, 8, 24, 40, 48, 100, 1000, 1025, 5000, 70_000] {
                let l = Layout::from_size_align(size, align).expect("layout");
                // SAFETY: non-zero sizes; each block freed once with its layout.
                unsafe {
                    let p = a.alloc(l);
                    assert!(!p.is_null());
                    assert_eq!(p as usize % align, 0, "size {size} align {align}");
                    std::ptr::write_bytes(p, 0xAB, size);
                    let z = a.alloc_zeroed(l);
                    assert_eq!(z as usize % align, 0);
                    assert!(std::slice::from_raw_parts(z, size).iter().all(|&b| b == 0));
                    a.dealloc(z, l);
                    let q = a.realloc(p, l, size * 3);
                    assert_eq!(q as usize % align, 0);
                    assert!(
                        std::slice::from_raw_parts(q, size)
                            .iter()
                            .all(|&b| b == 0xAB)
                    );
                    let l3 = Layout::from_size_align(size * 3, align).expect("layout");
                    let r = a.realloc(q, l3, size.div_ceil(2));
                    assert_eq!(r as usize % align, 0);
                    let half = size.div_ceil(2);
                    assert!(
                        std::slice::from_raw_parts(r, half)
                            .iter()
                            .all(|&b| b == 0xAB)
                    );
                    a.dealloc(r, Layout::from_size_align(half, align).expect("layout"));
                }
            }
        }
    }

    /// A block's alignment is the word even where a size class is not a
    /// multiple of 16 (the case the aligned calls over-allocated for).
    #[test]
    fn thousands_of_small_blocks_are_word_aligned() {
        let a = MiMalloc;
        let l = Layout::from_size_align(24, 8).expect("layout");
        // SAFETY: each block freed once with its layout.
        unsafe {
            let ps: Vec<*mut u8> = (0..10_000).map(|_| a.alloc(l)).collect();
            assert!(
                ps.iter()
                    .all(|p| !p.is_null() && (*p as usize).is_multiple_of(8))
            );
            for p in ps {
                a.dealloc(p, l);
            }
        }
    }
}
