//! The steady control tick allocates nothing: a robot at work whose
//! percepts do not change pays Algorithm 1's monitoring every tick, and a
//! team of 100,000 pays it 100,000 times per tick; an allocation there is
//! a malloc and a free per robot per tick, and memory churn across cores.
//!
//! Counted with a global allocator that counts only on the thread that
//! asked (other tests of this binary may run meanwhile).

use bite_core::Config;
use bite_core::graph::load_str;
use bite_core::ids::RobotId;
use bite_core::interaction::Registry;
use bite_core::kernel::Kernel;
use bite_core::mission::Mission;
use bite_core::time::Time;
use bite_core::value::Value;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::Arc;

struct Counting;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded unchanged to the system allocator; the
// counter is a thread-local `Cell` that never allocates (const-initialised),
// touched with `try_with` so that a thread being torn down is skipped.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = COUNTING.try_with(|on| {
            if on.get() {
                let _ = COUNT.try_with(|c| c.set(c.get() + 1));
            }
        });
        // SAFETY: the caller's contract for `alloc` is passed on as is.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from `System.alloc` above with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = COUNTING.try_with(|on| {
            if on.get() {
                let _ = COUNT.try_with(|c| c.set(c.get() + 1));
            }
        });
        // SAFETY: the caller's contract for `realloc` is passed on as is.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Allocations made by `f` on this thread.
fn allocations(f: impl FnOnce()) -> u64 {
    COUNT.with(|c| c.set(0));
    COUNTING.with(|on| on.set(true));
    f();
    COUNTING.with(|on| on.set(false));
    COUNT.with(|c| c.get())
}

#[test]
fn the_steady_tick_allocates_nothing() {
    let g = load_str(
        &Arc::from("formation.yaml"),
        include_str!("../../../examples/formation.yaml"),
    )
    .expect("formation graph");
    let cfg = Config::load_str(
        &Arc::from("silent.yaml"),
        "defaults: { terminate: term.local }\nbindings: { formation.terminate: term.local }",
    )
    .expect("config");
    let m = Arc::new(
        Mission::new(g.with_config(&cfg).expect("config"), &Registry::core()).expect("mission"),
    );
    let peers = m.graph().symbols().get("peers_located").expect("belief");
    let mut k = Kernel::new(m, RobotId(0), 1);
    k.tick(Time::ZERO, &[]);
    k.tick(Time::from_millis(100), &[(peers, Value::Bool(true))]);
    let mut now = Time::from_millis(200);
    k.tick(now, &[]);
    while k.poll_output().is_some() {}
    assert_eq!(k.stack().len(), 4, "walking a leg as the lead");
    // Warm up (buffers reach their working size), then count.
    for _ in 0..10 {
        now += std::time::Duration::from_millis(100);
        k.tick(now, &[]);
        while k.poll_output().is_some() {}
    }
    let n = allocations(|| {
        for _ in 0..100 {
            now += std::time::Duration::from_millis(100);
            k.tick(now, &[]);
            while k.poll_output().is_some() {}
        }
    });
    assert_eq!(n, 0, "allocations in 100 steady ticks");
    // The counter counts.
    let one = allocations(|| drop(std::hint::black_box(Vec::<u8>::with_capacity(8))));
    assert_eq!(one, 1, "the counting allocator works");
    assert_eq!(k.stack().len(), 4, "still walking");
}
