//! Work split over the machine's cores with its results in the order of the work, so that they
//! are the same, bit for bit, as one thread's: each item's result depends on that item alone,
//! and the results are joined in item order (no sum is split between threads).

use std::sync::{Mutex, PoisonError};
use std::thread::{Scope, ScopedJoinHandle};

/// Threads to use: the cores this process may run on, at most 8.
pub fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get).min(8)
}

/// Work waiting to be run once, by a thread or, where none could be started, by the caller.
type Slot<F> = Mutex<Option<F>>;

fn take<F>(slot: &Slot<F>) -> Option<F> {
    slot.lock().unwrap_or_else(PoisonError::into_inner).take()
}

/// Starts a named thread that runs the slot's work; `None` where no thread can be started.
fn spawn_in<'s, 'e, R: Send + 's, F: FnOnce() -> R + Send + 'e>(
    s: &'s Scope<'s, 'e>,
    slot: &'e Slot<F>,
) -> Option<ScopedJoinHandle<'s, Option<R>>> {
    std::thread::Builder::new().name("xsurf-par".into()).spawn_scoped(s, move || take(slot).map(|f| f())).ok()
}

/// The slot's result: its thread's (a panic there is raised here), or run here.
fn finish<R, F: FnOnce() -> R>(handle: Option<ScopedJoinHandle<'_, Option<R>>>, slot: &Slot<F>) -> Option<R> {
    handle.and_then(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e))).or_else(|| take(slot).map(|f| f()))
}

/// Work started on a thread of its own by [`background`], or done already where no thread could
/// be started.
pub enum Background<R> {
    /// On its thread (its result `None` if the thread failed).
    Thread(std::thread::JoinHandle<Option<R>>),
    /// Done here (`None` only if the work was gone from its slot).
    Done(Option<R>),
}

impl<R> Background<R> {
    /// True once the result can be taken without waiting.
    pub fn is_finished(&self) -> bool {
        match self {
            Background::Thread(h) => h.is_finished(),
            Background::Done(_) => true,
        }
    }
    /// The result, waiting for it; `None` where its thread failed.
    pub fn join(self) -> Option<R> {
        match self {
            Background::Thread(h) => h.join().ok().flatten(),
            Background::Done(r) => r,
        }
    }
}

/// Runs `f` on a thread named `name` that outlives the caller's scope, or here where no thread
/// can be started (the work is kept in a slot until the thread takes it, so it is never lost).
pub fn background<R: Send + 'static>(name: String, f: impl FnOnce() -> R + Send + 'static) -> Background<R> {
    let slot = std::sync::Arc::new(Mutex::new(Some(f)));
    let theirs = slot.clone();
    match std::thread::Builder::new().name(name).spawn(move || take(&theirs).map(|f| f())) {
        Ok(h) => Background::Thread(h),
        Err(_) => Background::Done(take(&slot).map(|f| f())),
    }
}

/// Runs `a` here and `b` on a thread of its own, side by side (one after the other on one
/// core, or where no thread can be started). A panic in either is raised here.
pub fn join<A, B: Send>(a: impl FnOnce() -> A, b: impl FnOnce() -> B + Send) -> (A, B) {
    let slot = Mutex::new(Some(b));
    std::thread::scope(|s| {
        let handle = if threads() > 1 { spawn_in(s, &slot) } else { None };
        let ra = a();
        match finish(handle, &slot) {
            Some(rb) => (ra, rb),
            // The work leaves its slot only to run: on the thread, or here.
            None => unreachable!("b neither ran on its thread nor here"),
        }
    })
}

/// `f(index, item)` for every item, the kept results in item order; split in contiguous parts
/// of at least `min_part` items over up to [`threads`] threads.
pub fn filter_map<T: Sync, R: Send>(items: &[T], min_part: usize, f: impl Fn(usize, &T) -> Option<R> + Sync) -> Vec<R> {
    let run =
        |start: usize, part: &[T]| -> Vec<R> { part.iter().enumerate().filter_map(|(i, x)| f(start + i, x)).collect() };
    let n = threads().min(items.len() / min_part.max(1)).max(1);
    if n < 2 {
        return run(0, items);
    }
    let per = items.len().div_ceil(n);
    let slots: Vec<Slot<_>> =
        items.chunks(per).enumerate().skip(1).map(|(k, part)| Mutex::new(Some(move || run(k * per, part)))).collect();
    std::thread::scope(|s| {
        let handles: Vec<_> = slots.iter().map(|slot| spawn_in(s, slot)).collect();
        let mut out = run(0, &items[..per]);
        for (handle, slot) in handles.into_iter().zip(&slots) {
            out.extend(finish(handle, slot).into_iter().flatten());
        }
        out
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_in_item_order_as_one_threads() {
        let items: Vec<u64> = (0..10_007).collect();
        let f = |i: usize, &x: &u64| (x % 3 != 0).then(|| ((i as u64) * 1_000_003) ^ x);
        let one: Vec<u64> = items.iter().enumerate().filter_map(|(i, x)| f(i, x)).collect();
        for min_part in [1, 100, 5_000, 20_000] {
            assert_eq!(filter_map(&items, min_part, f), one);
        }
        assert!(filter_map(&[] as &[u64], 1, f).is_empty());
        let (a, b) = join(|| items.iter().sum::<u64>(), || items.len());
        assert_eq!((a, b), (items.iter().sum::<u64>(), 10_007));
    }

    #[test]
    fn a_panic_on_the_thread_is_raised_here() {
        let r = std::panic::catch_unwind(|| join(|| 1, || -> i32 { panic!("on the thread") }));
        assert!(r.is_err());
    }
}
