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

/// Stack of each [`job_pool`] thread: the main thread's 8 MiB was enough for
/// every job, the 2 MiB Rust gives spawned threads was not (a correction's
/// PPO update overflowed it: candle walks the autograd graph recursively).
pub const JOB_STACK_BYTES: usize = 64 << 20;

/// A pool of `n` threads named `{name}-{i}` that run whole jobs side by side
/// (corrections, a table's prediction models), each with [`JOB_STACK_BYTES`]
/// of stack (reserved, not used, until a job needs it).
pub fn job_pool(n: usize, name: &str) -> Result<rayon::ThreadPool, rayon::ThreadPoolBuildError> {
    let name = name.to_string();
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .stack_size(JOB_STACK_BYTES)
        .thread_name(move |i| format!("{name}-{i}"))
        .build()
}
