//! How many threads candle's CPU kernels use, set once at program start.
//!
//! Why this exists: candle 0.11 runs its CPU ops on a pool of worker threads
//! (`CANDLE_NUM_THREADS`, default: the physical cores) that are pinned to
//! cores and spin while they wait, and it sizes its matrix products from
//! `RAYON_NUM_THREADS`, parsing `/proc/cpuinfo` on every product when that is
//! unset. Our networks are small (MLPs of 256, graph nets of 64 channels) and
//! our trainers already run their own threads (PPO's rollout pool, one
//! process per job), so those workers mostly spin against our threads for the
//! same two cores: a 4-iteration correction of the bundled kick took 31-34 s
//! of wall time and 17 s of CPU by default, 12 s and 5 s with candle on one
//! thread (side by side, 2 rounds, `motionaug correct ... --max-iterations 4`).
//!
//! [`init`] keeps candle to one thread unless `CANDLE_NUM_THREADS` is set,
//! and builds rayon's global pool (our own data-parallel work: synthesis
//! batches, evaluation) with `RAYON_NUM_THREADS` threads when that is set,
//! else one per core, so only candle's kernels become serial.

/// Call first thing in `main`, before any thread starts or any tensor op.
/// Idempotent; does nothing to variables the user set for candle.
pub fn init() {
    let parse = |name: &str| {
        std::env::var(name)
            .ok()
            .and_then(|v| v.parse::<usize>().ok())
            .filter(|&n| n > 0)
    };
    let ours = parse("RAYON_NUM_THREADS").unwrap_or_else(|| {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    });
    if parse("CANDLE_NUM_THREADS").is_none() {
        // SAFETY: `init` runs at the start of `main`, before the program
        // starts any thread, so nothing reads the environment concurrently.
        unsafe {
            std::env::set_var("CANDLE_NUM_THREADS", "1");
            std::env::set_var("RAYON_NUM_THREADS", "1");
        }
    }
    // Fails only when the global pool already exists (a second call): then
    // it keeps the size it was built with.
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(ours)
        .build_global();
}

/// Stack of each [`side_by_side`] thread: the main thread's 8 MiB, on
/// which every job runs when run one at a time (Rust gives spawned threads
/// 2 MiB; the stack overflow first seen with corrections side by side came
/// from the rayon pool described below, which nested corrections inside
/// each other's waits).
pub const JOB_STACK_BYTES: usize = 8 << 20;

/// `f` on every item, `n` items at a time on `n` threads named
/// `{name}-{i}` (items taken in order), results in item order; with `n` <= 1
/// on the calling thread, one after the other.
///
/// Plain threads, not a rayon pool: a rayon worker that waits on another
/// pool (as a correction waits on its PPO rollout pool) runs other items
/// of its own pool meanwhile, so a correction sat out whole corrections of
/// others and ran over its time budget (measured: 110 of 358 corrections of
/// a kick fold stopped after one PPO iteration "at" 690 s).
pub fn side_by_side<T: Send, R: Send>(
    items: Vec<T>,
    n: usize,
    name: &str,
    f: impl Fn(T) -> R + Sync,
) -> std::io::Result<Vec<R>> {
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicUsize, Ordering};
    if n <= 1 {
        return Ok(items.into_iter().map(f).collect());
    }
    let count = items.len();
    let items: Vec<Mutex<Option<T>>> = items.into_iter().map(|t| Mutex::new(Some(t))).collect();
    let results: Vec<Mutex<Option<R>>> = (0..count).map(|_| Mutex::new(None)).collect();
    let next = AtomicUsize::new(0);
    let work = || {
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(slot) = items.get(i) else { break };
            let item = slot.lock().ok().and_then(|mut s| s.take());
            if let Some(item) = item {
                let r = f(item);
                if let Ok(mut out) = results[i].lock() {
                    *out = Some(r);
                }
            }
        }
    };
    std::thread::scope(|scope| -> std::io::Result<()> {
        for t in 0..n.clamp(1, count.max(1)) {
            std::thread::Builder::new()
                .name(format!("{name}-{t}"))
                .stack_size(JOB_STACK_BYTES)
                .spawn_scoped(scope, work)?;
        }
        Ok(())
    })?;
    results
        .into_iter()
        .map(|r| r.into_inner().ok().flatten())
        .collect::<Option<Vec<R>>>()
        .ok_or_else(|| std::io::Error::other("a job of a side-by-side run did not finish"))
}

/// `a` on the calling thread and `b` at the same time on a thread named
/// `name` (with [`JOB_STACK_BYTES`] of stack, like [`side_by_side`]'s):
/// two different jobs that need nothing from each other, e.g. a VAE's
/// training beside the originals' corrections. A panic in `b` is resumed
/// on the caller once `a` is done.
pub fn beside<RA, RB: Send>(
    name: &str,
    a: impl FnOnce() -> RA,
    b: impl FnOnce() -> RB + Send,
) -> std::io::Result<(RA, RB)> {
    std::thread::scope(|scope| {
        let other = std::thread::Builder::new()
            .name(name.to_string())
            .stack_size(JOB_STACK_BYTES)
            .spawn_scoped(scope, b)?;
        let ra = a();
        match other.join() {
            Ok(rb) => Ok((ra, rb)),
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn side_by_side_keeps_item_order_and_uses_the_threads_asked_for() {
        let names = std::sync::Mutex::new(std::collections::BTreeSet::new());
        let out = side_by_side((0..20).collect(), 3, "sq", |i: u64| {
            if let Some(n) = std::thread::current().name() {
                names.lock().unwrap().insert(n.to_string());
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
            i * i
        })
        .unwrap();
        assert_eq!(out, (0..20).map(|i| i * i).collect::<Vec<u64>>());
        let names = names.into_inner().unwrap();
        assert!(names.iter().all(|n| n.starts_with("sq-")), "{names:?}");
        assert!(names.len() > 1 && names.len() <= 3, "{names:?}");
        assert!(
            side_by_side(Vec::<u8>::new(), 2, "none", |x| x)
                .unwrap()
                .is_empty()
        );
    }

    #[test]
    fn beside_runs_both_jobs_at_once_and_returns_both_results() {
        // Each job waits for the other to start: they can only both finish
        // when they run at the same time.
        let started = std::sync::Barrier::new(2);
        let (a, b) = beside(
            "other",
            || {
                started.wait();
                std::thread::current().name().map(str::to_string)
            },
            || {
                started.wait();
                std::thread::current().name().map(str::to_string)
            },
        )
        .unwrap();
        assert_ne!(a.as_deref(), Some("other"));
        assert_eq!(b.as_deref(), Some("other"));
    }

    #[test]
    fn a_job_waiting_on_a_rayon_pool_does_not_run_other_jobs_meanwhile() {
        // Each job waits on a pool of its own, as a correction waits on
        // its PPO rollouts; a job must run start to end on its thread.
        let overlapping = std::sync::atomic::AtomicUsize::new(0);
        let running = std::sync::Mutex::new(std::collections::HashMap::new());
        side_by_side((0..8).collect(), 2, "job", |i: usize| {
            let me = std::thread::current().id();
            if running.lock().unwrap().insert(me, i).is_some() {
                overlapping.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap();
            pool.install(|| std::thread::sleep(std::time::Duration::from_millis(5)));
            running.lock().unwrap().remove(&me);
        })
        .unwrap();
        assert_eq!(overlapping.into_inner(), 0);
    }
}
