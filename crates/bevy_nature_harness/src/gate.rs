//! [`GpuAppPass`]: one headless GPU app at a time in a process.
//!
//! Rust's test runner runs a test binary's tests on several threads, and every render test builds
//! its own Bevy app with its own wgpu device. With two such devices created and driven side by
//! side in one process, Mesa's software Vulkan driver (lavapipe, the CI's adapter) has been seen to
//! corrupt its heap (`malloc(): unsorted double linked list corrupted`, then SIGABRT), which kills
//! every test of the binary and stops `cargo test` there. Render tests gain little from running
//! side by side on a software rasteriser, which spreads each draw over every core anyway; so every
//! app [`add_headless_plugins`](crate::headless::add_headless_plugins) builds holds a pass from
//! before its renderer is created until the app (and, in a
//! [`RenderHarness`](crate::RenderHarness), its renderer) is dropped, and other threads wait for
//! it. Tests without a GPU app never touch the gate and still run side by side.
//!
//! The gate is re-entrant per thread: a test may hold several apps at once (to compare two
//! renders), as long as it builds them on one thread.

use bevy::prelude::Resource;
use std::sync::{Condvar, Mutex, PoisonError};
use std::thread::ThreadId;

/// Who holds the gate, and how many passes they hold.
struct GateState {
    owner: Option<ThreadId>,
    held: usize,
}

static GATE: Mutex<GateState> = Mutex::new(GateState {
    owner: None,
    held: 0,
});
static RELEASED: Condvar = Condvar::new();

/// A pass through the process-wide GPU app gate (see the module docs): while any pass is alive,
/// only the thread that took it can take another; the gate opens when the last is dropped, on
/// whatever thread.
#[derive(Resource, Debug)]
pub struct GpuAppPass {
    _private: (),
}

impl GpuAppPass {
    /// Waits until no other thread holds the gate, then takes a pass.
    pub fn acquire() -> Self {
        let me = std::thread::current().id();
        // A panic never happens while the lock is held (the state is two plain fields), so a
        // poisoned lock still holds a consistent state.
        let mut state = GATE.lock().unwrap_or_else(PoisonError::into_inner);
        while state.owner.is_some_and(|owner| owner != me) {
            state = RELEASED.wait(state).unwrap_or_else(PoisonError::into_inner);
        }
        state.owner = Some(me);
        state.held += 1;
        Self { _private: () }
    }
}

impl Drop for GpuAppPass {
    fn drop(&mut self) {
        let mut state = GATE.lock().unwrap_or_else(PoisonError::into_inner);
        state.held = state.held.saturating_sub(1);
        if state.held == 0 {
            state.owner = None;
            RELEASED.notify_all();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::mpsc;
    use std::time::Duration;

    #[test]
    fn threads_take_turns_and_one_thread_may_hold_several_passes() {
        // Four threads each take the gate three times, holding it for a while, and count how
        // many are inside at once; without the gate (a pass that waits for nothing) several are.
        let inside = Arc::new(AtomicUsize::new(0));
        let most = Arc::new(AtomicUsize::new(0));
        let threads: Vec<_> = (0..4)
            .map(|_| {
                let (inside, most) = (inside.clone(), most.clone());
                std::thread::spawn(move || {
                    for _ in 0..3 {
                        let first = GpuAppPass::acquire();
                        // A second app on the same thread does not wait for itself.
                        let second = GpuAppPass::acquire();
                        let now = inside.fetch_add(1, Ordering::SeqCst) + 1;
                        most.fetch_max(now, Ordering::SeqCst);
                        std::thread::sleep(Duration::from_millis(15));
                        inside.fetch_sub(1, Ordering::SeqCst);
                        drop(first);
                        drop(second);
                    }
                })
            })
            .collect();
        let (done, finished) = mpsc::channel();
        std::thread::spawn(move || {
            for t in threads {
                t.join().expect("a gate thread panicked");
            }
            done.send(()).ok();
        });
        finished
            .recv_timeout(Duration::from_secs(30))
            .expect("the gate deadlocked");
        assert_eq!(
            most.load(Ordering::SeqCst),
            1,
            "two threads held the gate at once"
        );
        // And it is open again: another thread gets a pass at once.
        std::thread::spawn(GpuAppPass::acquire)
            .join()
            .expect("the gate stayed shut");
    }
}
