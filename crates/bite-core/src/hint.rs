//! Cache hints for walks over many robots' states.

/// Ask the CPU to bring the cache line at `p` in ahead of its use. A hint
/// only: it never faults and changes nothing the program can observe.
#[inline(always)]
pub fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `prefetcht0` reads nothing into a register and never faults,
    // whatever the address (even a dangling or null one); `_mm_prefetch`
    // needs the `sse` target feature, which is part of the x86-64 baseline
    // every x86-64 target enables.
    unsafe {
        core::arch::x86_64::_mm_prefetch::<{ core::arch::x86_64::_MM_HINT_T0 }>(p.cast())
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// [`prefetch`] the first `lines` cache lines from `p`.
#[inline(always)]
pub fn prefetch_lines<T>(p: *const T, lines: usize) {
    let p = p.cast::<u8>();
    for k in 0..lines {
        prefetch(p.wrapping_add(64 * k));
    }
}

/// [`prefetch`] the cache lines of `items`, up to `max_lines` of them.
#[inline(always)]
pub fn prefetch_slice<T>(items: &[T], max_lines: usize) {
    let lines = std::mem::size_of_val(items).div_ceil(64).min(max_lines);
    prefetch_lines(items.as_ptr(), lines);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hint on any address, the null one and past the end included,
    /// changes nothing and never faults.
    #[test]
    fn prefetching_any_address_is_harmless() {
        let v = vec![7u64; 100];
        prefetch(std::ptr::null::<u8>());
        prefetch(usize::MAX as *const u8);
        prefetch_lines(v.as_ptr(), 1000);
        prefetch_slice(&v, 4);
        prefetch_slice::<u64>(&[], 4);
        assert_eq!(v.iter().sum::<u64>(), 700);
    }
}
