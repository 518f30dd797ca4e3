//! The option index `keep_freed_memory` sets is mimalloc's `purge_delay`:
//! read in a process of its own, before anything sets it, it holds that
//! option's documented default (1000 ms in mimalloc 3's `options.c`). A
//! mimalloc whose options were renumbered fails here, not silently.

use libmimalloc_sys as ffi;

#[test]
fn the_purge_delay_option_holds_its_default_until_set() {
    if std::env::var_os("MIMALLOC_PURGE_DELAY").is_some() {
        // The environment's value wins: nothing is set.
        assert!(!bite_alloc::keep_freed_memory());
        return;
    }
    // SAFETY: reads one option's value (15: `mi_option_purge_delay`).
    assert_eq!(unsafe { ffi::mi_option_get(15) }, 1000);
    assert!(bite_alloc::keep_freed_memory());
    // SAFETY: as above.
    assert_eq!(unsafe { ffi::mi_option_get(15) }, -1);
}
