//! Guards of long work: buffers proportional to the record allocated fallibly (an allocation
//! that cannot be satisfied is `Error::OutOfMemory`, not an abort of the process), and the
//! interruption check that long loops make every `CHUNK` samples.
//!
//! Interruption: the caller (the Python binding) runs work under `interruptible(hook, ..)`;
//! `check()` in a loop calls the hook (at most every `HOOK_EVERY`) and, once it says stop,
//! returns `Error::Interrupted` from then on, on that thread and on the threads the work's
//! parallel folds started (`scope` / `adopt`). Without a hook `check()` only costs a
//! thread-local read, and the core's results do not depend on it.

use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::error::{Error, Result};

/// Samples between two interruption checks in a long loop (a check is a thread-local read;
/// the hook runs at most every `HOOK_EVERY`).
pub const CHUNK: usize = 1 << 20;

/// The least time between two calls of the hook (the binding's hook takes the GIL).
const HOOK_EVERY: Duration = Duration::from_millis(50);

/// An empty vector with room for exactly `n` elements; `Error::OutOfMemory` naming `what`
/// where the allocation cannot be satisfied (too large for the address space or the memory
/// limit).
pub fn buffer<T>(n: usize, what: &str) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)
        .map_err(|_| out_of_memory::<T>(n, what))?;
    Ok(v)
}

/// `n` copies of `value`, allocated as `buffer` does.
pub fn filled<T: Clone>(n: usize, value: T, what: &str) -> Result<Vec<T>> {
    let mut v = buffer(n, what)?;
    v.resize(n, value);
    Ok(v)
}

/// A copy of `values`, allocated as `buffer` does.
pub fn copied<T: Copy>(values: &[T], what: &str) -> Result<Vec<T>> {
    let mut v = buffer(values.len(), what)?;
    v.extend_from_slice(values);
    Ok(v)
}

fn out_of_memory<T>(n: usize, what: &str) -> Error {
    let bytes = (n as f64) * std::mem::size_of::<T>() as f64;
    Error::OutOfMemory(format!(
        "cannot allocate {what}: {n} values ({:.3} GB) do not fit in the memory available; \
         use a shorter record or split it into several",
        bytes / 1e9
    ))
}

/// The interruption state of one piece of work, shared with the threads it starts.
struct Scope {
    stop: Arc<AtomicBool>,
    /// The caller's hook (on the thread that started the work only) and its last call.
    hook: Option<(fn() -> bool, Instant)>,
}

thread_local! {
    static SCOPE: RefCell<Option<Scope>> = const { RefCell::new(None) };
}

/// Run `work` with `hook` asked every `HOOK_EVERY` (from `check()`) whether to stop; also
/// returns whether it said so (then `work`'s loops returned `Error::Interrupted`, or a fold
/// stopped early: the result must be discarded).
pub fn interruptible<T>(hook: fn() -> bool, work: impl FnOnce() -> T) -> (T, bool) {
    let stop = Arc::new(AtomicBool::new(false));
    let previous = SCOPE.with(|s| {
        s.replace(Some(Scope {
            stop: Arc::clone(&stop),
            hook: Some((hook, Instant::now())),
        }))
    });
    // restored even if `work` panics (the binding catches panics)
    struct Restore(Option<Option<Scope>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            if let Some(previous) = self.0.take() {
                SCOPE.with(|s| *s.borrow_mut() = previous);
            }
        }
    }
    let restore = Restore(Some(previous));
    let out = work();
    drop(restore);
    (out, stop.load(Ordering::Relaxed))
}

/// Whether the work running on this thread was asked to stop (asks the hook when it is due).
pub fn interrupted() -> bool {
    SCOPE.with(|s| {
        let mut s = s.borrow_mut();
        let Some(scope) = s.as_mut() else {
            return false;
        };
        if scope.stop.load(Ordering::Relaxed) {
            return true;
        }
        if let Some((hook, last)) = &mut scope.hook {
            let now = Instant::now();
            if now.duration_since(*last) >= HOOK_EVERY {
                *last = now;
                if hook() {
                    scope.stop.store(true, Ordering::Relaxed);
                    return true;
                }
            }
        }
        false
    })
}

/// `Error::Interrupted` if the work was asked to stop: the check long loops make every
/// `CHUNK` samples.
pub fn check() -> Result<()> {
    if interrupted() {
        Err(Error::Interrupted)
    } else {
        Ok(())
    }
}

/// The stop flag of this thread's work, to hand to the threads it starts (`adopt`).
pub(crate) fn scope() -> Option<Arc<AtomicBool>> {
    SCOPE.with(|s| s.borrow().as_ref().map(|scope| Arc::clone(&scope.stop)))
}

/// On a thread started by the work: share its stop flag (no hook: only the starting thread
/// asks the caller).
pub(crate) fn adopt(stop: Option<Arc<AtomicBool>>) {
    SCOPE.with(|s| *s.borrow_mut() = stop.map(|stop| Scope { stop, hook: None }));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffer_refuses_what_cannot_be_allocated() {
        let err = buffer::<f64>(usize::MAX / 4, "y").unwrap_err();
        assert!(matches!(err, Error::OutOfMemory(ref m) if m.contains("cannot allocate y")));
        assert_eq!(buffer::<f64>(10, "y").unwrap().capacity(), 10);
        assert_eq!(filled(3, 1.5, "y").unwrap(), vec![1.5; 3]);
        assert_eq!(copied(&[1.0, 2.0], "y").unwrap(), vec![1.0, 2.0]);
    }

    #[test]
    fn check_follows_the_hook() {
        assert!(check().is_ok()); // no scope
        let (out, stopped) = interruptible(
            || true,
            || {
                std::thread::sleep(HOOK_EVERY);
                let first = check();
                // sticky, and shared with the threads the work starts
                let stop = scope();
                let other = std::thread::spawn(move || {
                    adopt(stop);
                    check()
                })
                .join()
                .unwrap();
                (first, check(), other)
            },
        );
        assert!(stopped);
        assert_eq!(out.0, Err(Error::Interrupted));
        assert_eq!(out.1, Err(Error::Interrupted));
        assert_eq!(out.2, Err(Error::Interrupted));
        assert!(check().is_ok()); // the scope ended
        let (_, stopped) = interruptible(|| false, check);
        assert!(!stopped);
    }

    #[test]
    fn a_long_simulation_stops_when_interrupted() {
        let model = crate::test_params::example1_model();
        let u: Vec<f64> = (0..3 * CHUNK).map(|k| (k as f64 * 0.01).sin()).collect();
        let (out, stopped) = interruptible(
            || true,
            || {
                std::thread::sleep(HOOK_EVERY);
                model.simulate(&u, &model.rest_state())
            },
        );
        assert!(stopped);
        assert_eq!(out, Err(Error::Interrupted));
        // without an interruption: the whole record
        let (out, stopped) = interruptible(|| false, || model.simulate(&u, &model.rest_state()));
        assert!(!stopped && out.unwrap().len() == u.len());
    }
}
