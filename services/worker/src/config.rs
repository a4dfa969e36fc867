//! Worker configuration from the environment (see docs/SERVICE.md).

use std::time::Duration;

use anyhow::{Context, bail};

#[derive(Debug, Clone)]
pub struct WorkerConfig {
    /// `MOTIONAUG_COORDINATOR_URL`, e.g. `http://coordinator:8080`.
    pub coordinator_url: String,
    /// `MOTIONAUG_WORKER_TOKEN`: the shared worker token.
    pub token: String,
    /// `MOTIONAUG_WORKER_ID` (default: host name, process id and a random suffix).
    pub worker_id: String,
    /// `MOTIONAUG_WORKER_CONCURRENCY`: jobs run at once (default 1).
    pub concurrency: usize,
    /// `MOTIONAUG_WORKER_SHUTDOWN_GRACE_MS`: on SIGTERM, how long running jobs may take
    /// to reach their next checkpoint and be handed back (default 30000).
    pub shutdown_grace: Duration,
    /// `MOTIONAUG_WORKER_TEST_DELAY_MS` (TEST ONLY): sleep this long before storing each
    /// output, so tests can kill a worker in the middle of a job. Never set it in production.
    pub test_delay: Option<Duration>,
    /// `MOTIONAUG_WORKER_WORK_DIR`: scratch space of running jobs (default: the
    /// system temp dir + `motionaug-worker`).
    pub work_dir: std::path::PathBuf,
    /// `MOTIONAUG_WORKER_CHECKPOINT_EVERY_S`: how often a correction stores and
    /// uploads a checkpoint (default 30; at most this much training is redone
    /// when a worker dies).
    pub checkpoint_every: Duration,
}

impl WorkerConfig {
    pub fn from_env() -> anyhow::Result<Self> {
        Self::from_lookup(|k| std::env::var(k).ok())
    }

    pub fn from_lookup(get: impl Fn(&str) -> Option<String>) -> anyhow::Result<Self> {
        let get = |k: &str| get(k).filter(|v| !v.trim().is_empty());
        let number = |k: &str, default: u64| -> anyhow::Result<u64> {
            match get(k) {
                None => Ok(default),
                Some(v) => v
                    .trim()
                    .parse()
                    .with_context(|| format!("{k}={v:?} is not a non-negative integer")),
            }
        };
        let coordinator_url = get("MOTIONAUG_COORDINATOR_URL")
            .context("MOTIONAUG_COORDINATOR_URL is not set")?
            .trim_end_matches('/')
            .to_string();
        if !coordinator_url.starts_with("http://") {
            bail!("MOTIONAUG_COORDINATOR_URL must start with http:// (got {coordinator_url:?})");
        }
        let token = get("MOTIONAUG_WORKER_TOKEN").context("MOTIONAUG_WORKER_TOKEN is not set")?;
        let concurrency = number("MOTIONAUG_WORKER_CONCURRENCY", 1)? as usize;
        if !(1..=256).contains(&concurrency) {
            bail!("MOTIONAUG_WORKER_CONCURRENCY must be between 1 and 256");
        }
        let worker_id = match get("MOTIONAUG_WORKER_ID") {
            Some(id) => id,
            None => {
                let host = get("HOSTNAME")
                    .or_else(|| std::fs::read_to_string("/etc/hostname").ok())
                    .map(|h| h.trim().to_string())
                    .filter(|h| !h.is_empty())
                    .unwrap_or_else(|| "worker".into());
                let suffix = uuid::Uuid::new_v4().simple().to_string();
                format!("{host}-{}-{}", std::process::id(), &suffix[..8])
            }
        };
        let test_delay = match number("MOTIONAUG_WORKER_TEST_DELAY_MS", 0)? {
            0 => None,
            ms => Some(Duration::from_millis(ms)),
        };
        Ok(WorkerConfig {
            coordinator_url,
            token,
            worker_id,
            concurrency,
            shutdown_grace: Duration::from_millis(number(
                "MOTIONAUG_WORKER_SHUTDOWN_GRACE_MS",
                30_000,
            )?),
            test_delay,
            work_dir: get("MOTIONAUG_WORKER_WORK_DIR")
                .map(std::path::PathBuf::from)
                .unwrap_or_else(|| std::env::temp_dir().join("motionaug-worker")),
            checkpoint_every: Duration::from_secs(
                number("MOTIONAUG_WORKER_CHECKPOINT_EVERY_S", 30)?.max(1),
            ),
        })
    }
}
