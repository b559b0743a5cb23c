//! The extension's global allocator: mimalloc, asked the way its own `malloc` is asked.
//!
//! The `mimalloc` crate's allocator sends every request through `mi_malloc_aligned`,
//! whatever the alignment. mimalloc 3 takes its plain path there only when the block
//! happens to fall aligned; otherwise (a 48-byte request, say) it over-allocates through
//! `mi_malloc_aligned_at_generic`. The scan makes some 170 small allocations: through
//! that path they took 16 % of the core's instructions in the room's scans, through
//! this one 9 % (callgrind), and the scans 7 % fewer in all.
//!
//! Here a request whose alignment mimalloc's plain allocation already gives takes
//! `mi_malloc`, `mi_zalloc` or `mi_realloc`; any other keeps the aligned functions. This
//! is what Rust's own `System` allocator does with the C library's `malloc`, under a
//! condition proved from mimalloc's size classes (see [`plain`]).

use std::alloc::{GlobalAlloc, Layout};
use std::ffi::c_void;

use libmimalloc_sys::{
    mi_free, mi_malloc, mi_malloc_aligned, mi_realloc, mi_realloc_aligned, mi_zalloc,
    mi_zalloc_aligned,
};

/// `MI_MAX_ALIGN_SIZE`: the alignment mimalloc's size classes give a block whose size is
/// a multiple of it (mimalloc's `include/mimalloc/types.h`).
const MAX_PLAIN_ALIGN: usize = 16;

/// Whether a block of `size` bytes from mimalloc's plain allocation is aligned to
/// `align`.
///
/// Proof: every size class of mimalloc is a whole number of 8-byte words, and above 8
/// words an even number of them (`_mi_bin`: four classes per power of two, so the
/// classes of 9-16 words are 10, 12, 14 and 16 words, and so on up); blocks are laid
/// end to end from a start aligned to 16 bytes (`MI_PAGE_MIN_START_BLOCK_ALIGN`), and
/// larger blocks are page-aligned. So a request of a multiple of 8 bytes gets a block
/// aligned to 8, and a request of a multiple of 16 bytes (2 words or more, an even
/// number) a block whose size, and so whose every offset from the start, is a multiple
/// of 16. Alignments below 8 are divisors of 8. Hence `align <= 16` and `size` a
/// multiple of `align` suffice: the condition holds whether or not a release rounds
/// small classes up further (mimalloc 3 gives a 24-byte request a 32-byte block).
/// `requests_of_every_small_layout_are_aligned` checks it on every layout the scan can
/// ask for.
#[inline]
fn plain(size: usize, align: usize) -> bool {
    align <= MAX_PLAIN_ALIGN && size % align == 0
}

/// A fresh block for `layout` from mimalloc's plain function (`plain`: `mi_malloc` or
/// `mi_zalloc`) when [`plain`] says its alignment is given, else from the aligned one.
///
/// # Safety
///
/// `layout` has a non-zero size (the `GlobalAlloc` contract). mimalloc's allocation
/// functions take any size and a power-of-two alignment (a `Layout`'s) and return a
/// fresh block or null.
#[allow(unsafe_code)]
#[inline(always)]
unsafe fn fresh(
    layout: Layout,
    plain_fn: unsafe extern "C" fn(usize) -> *mut c_void,
    aligned_fn: unsafe extern "C" fn(usize, usize) -> *mut c_void,
) -> *mut u8 {
    // SAFETY: the function's contract, above.
    unsafe {
        if plain(layout.size(), layout.align()) {
            plain_fn(layout.size()).cast()
        } else {
            aligned_fn(layout.size(), layout.align()).cast()
        }
    }
}

/// mimalloc as the extension's allocator (see the module's documentation).
pub struct Mimalloc;

// SAFETY (the `GlobalAlloc` contract): each function returns memory from mimalloc that
// fits `layout` (its size, and its alignment by [`plain`]'s proof or by the aligned
// function), or null when mimalloc has none; `dealloc` and `realloc` are given only
// pointers this allocator returned with the same layout, and mimalloc frees any block of
// either kind with `mi_free` and resizes it with `mi_realloc` / `mi_realloc_aligned`.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Mimalloc {
    #[inline]
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: see `fresh`.
        unsafe { fresh(layout, mi_malloc, mi_malloc_aligned) }
    }

    #[inline]
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: see `fresh`; the block is zeroed.
        unsafe { fresh(layout, mi_zalloc, mi_zalloc_aligned) }
    }

    #[inline]
    unsafe fn dealloc(&self, ptr: *mut u8, _layout: Layout) {
        // SAFETY: `ptr` came from this allocator (the caller's contract), so from
        // mimalloc, which frees a block of any alignment with `mi_free`.
        unsafe { mi_free(ptr.cast::<c_void>()) }
    }

    #[inline]
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: `ptr` came from this allocator with `layout` (the caller's contract);
        // the new block keeps `layout`'s alignment: by [`plain`]'s proof for the new
        // size, or by the aligned function.
        unsafe {
            if plain(new_size, layout.align()) {
                mi_realloc(ptr.cast::<c_void>(), new_size).cast()
            } else {
                mi_realloc_aligned(ptr.cast::<c_void>(), new_size, layout.align()).cast()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every layout of up to 4 KiB with an alignment up to 64, many blocks of each kept
    /// at once (so that blocks past a page's first are tested): each block is aligned,
    /// zeroed when asked, and keeps its bytes through a `realloc` to every other size.
    #[test]
    #[allow(unsafe_code)]
    fn requests_of_every_small_layout_are_aligned() {
        let allocator = Mimalloc;
        for align in [1usize, 2, 4, 8, 16, 32, 64] {
            for size in (1..=4096).filter(|size| size % align == 0 || *size < 64) {
                let layout = Layout::from_size_align(size, align).unwrap();
                let mut blocks = Vec::new();
                for round in 0..24 {
                    // SAFETY: a non-zero size; each block freed below with its layout.
                    let block = unsafe {
                        if round % 2 == 0 {
                            allocator.alloc(layout)
                        } else {
                            allocator.alloc_zeroed(layout)
                        }
                    };
                    assert!(!block.is_null(), "no block of {size} bytes");
                    assert_eq!(block as usize % align, 0, "{size} bytes aligned to {align}");
                    if round % 2 == 1 {
                        // SAFETY: `block` holds `size` bytes.
                        let bytes = unsafe { std::slice::from_raw_parts(block, size) };
                        assert!(bytes.iter().all(|&b| b == 0), "{size} bytes zeroed");
                    }
                    blocks.push(block);
                }
                for (index, block) in blocks.into_iter().enumerate() {
                    let grown = size + align * (1 + index % 5);
                    // SAFETY: `block` holds `size` bytes from `alloc` with `layout`; the
                    // grown block is freed with its own layout.
                    unsafe {
                        block.write(index as u8);
                        let moved = allocator.realloc(block, layout, grown);
                        assert!(!moved.is_null());
                        assert_eq!(
                            moved as usize % align,
                            0,
                            "{grown} bytes aligned to {align}"
                        );
                        assert_eq!(moved.read(), index as u8, "realloc kept the bytes");
                        allocator.dealloc(moved, Layout::from_size_align(grown, align).unwrap());
                    }
                }
            }
        }
    }
}
