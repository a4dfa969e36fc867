//! Configuration from the environment.
//!
//! Every setting has an environment variable; only `DATABASE_URL` and
//! `MOTIONAUG_WORKER_TOKEN` are required. `docs/SERVICE.md` lists them all.

use std::time::Duration;

use anyhow::{Context, bail};

#[derive(Debug, Clone)]
pub struct Config {
    /// `DATABASE_URL`, e.g. `postgres://postgres@127.0.0.1:5432/motionaug`.
    pub database_url: String,
    /// `REDIS_URL`, e.g. `redis://127.0.0.1:6379/0`. Optional: without it live events
    /// fall back to polling the database.
    pub redis_url: Option<String>,
    /// `MOTIONAUG_REDIS_PREFIX`: prefix of the pub/sub channel names (default `motionaug`).
    pub redis_prefix: String,
    /// `MOTIONAUG_DB_POOL_SIZE`: Postgres connections of this process (default 20).
    pub db_pool_size: u32,
    /// `MOTIONAUG_LISTEN`: address to listen on (default `127.0.0.1:8080`).
    pub listen: String,
    /// `MOTIONAUG_WORKER_TOKEN`: shared secret of the internal worker API.
    pub worker_token: String,
    pub limits: Limits,
    pub quotas: Quotas,
    pub queue: QueueConfig,
}

/// What each tenant may use (documented in docs/SERVICE.md and shown at
/// `GET /v1/limits`). The same for every tenant; checked and taken in the
/// transaction that stores the new dataset or augmentation, under the
/// tenant's row lock (see `crate::quota`).
#[derive(Debug, Clone)]
pub struct Quotas {
    /// `MOTIONAUG_QUOTA_OUTPUTS_PER_AUGMENTATION`: new clips one augmentation may
    /// make (default 20000); more is a 422.
    pub outputs_per_augmentation: u64,
    /// `MOTIONAUG_QUOTA_ACTIVE_AUGMENTATIONS`: augmentations of a tenant that may be
    /// unfinished at once (default 10); one more is a 429.
    pub active_augmentations: u64,
    /// `MOTIONAUG_QUOTA_CORRECTION_SECONDS`: correction budget (`[correct]
    /// time_budget_s` x correction jobs) of a tenant's unfinished augmentations
    /// together (default 1000000); more is a 429 (a 422 for one augmentation
    /// that alone needs more).
    pub correction_seconds: u64,
    /// `MOTIONAUG_QUOTA_STORED_BYTES`: bytes a tenant may keep stored: uploaded
    /// files, results and checkpoints (default 10 GiB). An upload that would pass
    /// it, or a new augmentation once it is reached, is a 429.
    pub stored_bytes: u64,
}

impl Default for Quotas {
    fn default() -> Self {
        Quotas {
            outputs_per_augmentation: 20_000,
            active_augmentations: 10,
            correction_seconds: 1_000_000,
            stored_bytes: 10 << 30,
        }
    }
}

/// Request limits (documented in docs/SERVICE.md).
#[derive(Debug, Clone)]
pub struct Limits {
    /// `MOTIONAUG_MAX_UPLOAD_BYTES`: whole request body of an upload (default 64 MiB).
    pub max_upload_bytes: usize,
    /// `MOTIONAUG_MAX_FILES`: files per upload, counting the entries of zips (default 1000).
    pub max_files: usize,
    /// `MOTIONAUG_MAX_FRAMES`: frames per clip (default 200000).
    pub max_frames: usize,
    /// `MOTIONAUG_MAX_UNZIPPED_BYTES`: total bytes after unpacking the zips of one
    /// upload (default 128 MiB).
    pub max_unzipped_bytes: u64,
    /// `MOTIONAUG_MAX_CONCURRENT_UPLOADS`: uploads read and checked at once; others
    /// wait (default 4).
    pub max_concurrent_uploads: usize,
    /// `MOTIONAUG_UPLOAD_MEMORY_BYTES`: memory all uploads of the process may hold
    /// together: bodies and unpacked zip entries (default 192 MiB, one largest
    /// upload: 64 MiB of zip unpacking to 128 MiB).
    pub upload_memory_bytes: u64,
    /// `MOTIONAUG_MAX_ARTIFACT_BYTES`: one result file or checkpoint from a worker (default 256 MiB).
    pub max_artifact_bytes: usize,
}

/// Job queue timing.
#[derive(Debug, Clone)]
pub struct QueueConfig {
    /// `MOTIONAUG_LEASE_MS`: a job's lease lasts this long after its last heartbeat (default 30000).
    pub lease: Duration,
    /// `MOTIONAUG_MAX_ATTEMPTS`: runs of a job before it fails for good (default 5).
    pub max_attempts: i32,
    /// `MOTIONAUG_RETRY_BASE_MS`: backoff before retry n is base * 2^(n-1), capped at 5 min (default 1000).
    pub retry_base: Duration,
    /// `MOTIONAUG_REAP_INTERVAL_MS`: how often expired leases are collected (default 1000).
    pub reap_interval: Duration,
    /// `MOTIONAUG_POLL_INTERVAL_MS`: database polling interval of long polls and SSE when no
    /// Redis event arrives (default 1000).
    pub poll_interval: Duration,
    /// `MOTIONAUG_MAX_CLAIM_WAIT_MS`: cap of a worker's long poll (default 20000).
    pub max_claim_wait: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_upload_bytes: 64 << 20,
            max_files: 1000,
            max_frames: 200_000,
            max_unzipped_bytes: 128 << 20,
            max_concurrent_uploads: 4,
            upload_memory_bytes: 192 << 20,
            max_artifact_bytes: 256 << 20,
        }
    }
}

impl Default for QueueConfig {
    fn default() -> Self {
        QueueConfig {
            lease: Duration::from_secs(30),
            max_attempts: 5,
            retry_base: Duration::from_secs(1),
            reap_interval: Duration::from_secs(1),
            poll_interval: Duration::from_secs(1),
            max_claim_wait: Duration::from_secs(20),
        }
    }
}

impl Config {
    /// Reads the configuration from the process environment.
    pub fn from_env() -> anyhow::Result<Self> {
        Self::from_lookup(|k| std::env::var(k).ok())
    }

    /// Reads the configuration from any key lookup (tests pass a map).
    pub fn from_lookup(get: impl Fn(&str) -> Option<String>) -> anyhow::Result<Self> {
        let required = |k: &str| {
            get(k)
                .filter(|v| !v.is_empty())
                .with_context(|| format!("{k} is not set"))
        };
        let number = |k: &str, default: u64| -> anyhow::Result<u64> {
            match get(k).filter(|v| !v.is_empty()) {
                None => Ok(default),
                Some(v) => v
                    .trim()
                    .parse::<u64>()
                    .with_context(|| format!("{k}={v:?} is not a non-negative integer")),
            }
        };
        let ms = |k: &str, default: Duration| -> anyhow::Result<Duration> {
            Ok(Duration::from_millis(number(
                k,
                default.as_millis() as u64,
            )?))
        };
        let worker_token = required("MOTIONAUG_WORKER_TOKEN")?;
        if worker_token.len() < 16 {
            bail!("MOTIONAUG_WORKER_TOKEN must be at least 16 characters long");
        }
        let dl = Limits::default();
        let dquota = Quotas::default();
        let dq = QueueConfig::default();
        let max_attempts = number("MOTIONAUG_MAX_ATTEMPTS", dq.max_attempts as u64)?;
        if !(1..=100).contains(&max_attempts) {
            bail!("MOTIONAUG_MAX_ATTEMPTS must be between 1 and 100");
        }
        let queue = QueueConfig {
            lease: ms("MOTIONAUG_LEASE_MS", dq.lease)?,
            max_attempts: max_attempts as i32,
            retry_base: ms("MOTIONAUG_RETRY_BASE_MS", dq.retry_base)?,
            reap_interval: ms("MOTIONAUG_REAP_INTERVAL_MS", dq.reap_interval)?,
            poll_interval: ms("MOTIONAUG_POLL_INTERVAL_MS", dq.poll_interval)?,
            max_claim_wait: ms("MOTIONAUG_MAX_CLAIM_WAIT_MS", dq.max_claim_wait)?,
        };
        if queue.lease < Duration::from_millis(200) {
            bail!("MOTIONAUG_LEASE_MS must be at least 200");
        }
        for (k, d) in [
            ("MOTIONAUG_REAP_INTERVAL_MS", queue.reap_interval),
            ("MOTIONAUG_POLL_INTERVAL_MS", queue.poll_interval),
        ] {
            if d < Duration::from_millis(10) {
                bail!("{k} must be at least 10");
            }
        }
        let db_pool_size = number("MOTIONAUG_DB_POOL_SIZE", 20)?;
        if !(2..=1000).contains(&db_pool_size) {
            bail!("MOTIONAUG_DB_POOL_SIZE must be between 2 and 1000");
        }
        let config = Config {
            database_url: required("DATABASE_URL")?,
            db_pool_size: db_pool_size as u32,
            redis_url: get("REDIS_URL").filter(|v| !v.is_empty()),
            redis_prefix: get("MOTIONAUG_REDIS_PREFIX")
                .filter(|v| !v.is_empty())
                .unwrap_or_else(|| "motionaug".into()),
            listen: get("MOTIONAUG_LISTEN")
                .filter(|v| !v.is_empty())
                .unwrap_or_else(|| "127.0.0.1:8080".into()),
            worker_token,
            limits: Limits {
                max_upload_bytes: number("MOTIONAUG_MAX_UPLOAD_BYTES", dl.max_upload_bytes as u64)?
                    as usize,
                max_files: number("MOTIONAUG_MAX_FILES", dl.max_files as u64)? as usize,
                max_frames: number("MOTIONAUG_MAX_FRAMES", dl.max_frames as u64)? as usize,
                max_unzipped_bytes: number("MOTIONAUG_MAX_UNZIPPED_BYTES", dl.max_unzipped_bytes)?,
                max_concurrent_uploads: number(
                    "MOTIONAUG_MAX_CONCURRENT_UPLOADS",
                    dl.max_concurrent_uploads as u64,
                )?
                .clamp(1, 1024) as usize,
                upload_memory_bytes: number(
                    "MOTIONAUG_UPLOAD_MEMORY_BYTES",
                    dl.upload_memory_bytes,
                )?,
                max_artifact_bytes: number(
                    "MOTIONAUG_MAX_ARTIFACT_BYTES",
                    dl.max_artifact_bytes as u64,
                )? as usize,
            },
            quotas: Quotas {
                outputs_per_augmentation: number(
                    "MOTIONAUG_QUOTA_OUTPUTS_PER_AUGMENTATION",
                    dquota.outputs_per_augmentation,
                )?,
                active_augmentations: number(
                    "MOTIONAUG_QUOTA_ACTIVE_AUGMENTATIONS",
                    dquota.active_augmentations,
                )?,
                correction_seconds: number(
                    "MOTIONAUG_QUOTA_CORRECTION_SECONDS",
                    dquota.correction_seconds,
                )?,
                stored_bytes: number("MOTIONAUG_QUOTA_STORED_BYTES", dquota.stored_bytes)?,
            },
            queue,
        };
        let limits = &config.limits;
        if limits.max_upload_bytes as u64 > limits.upload_memory_bytes {
            bail!(
                "MOTIONAUG_MAX_UPLOAD_BYTES ({}) is more than MOTIONAUG_UPLOAD_MEMORY_BYTES ({}): \
                 such an upload could never be read",
                limits.max_upload_bytes,
                limits.upload_memory_bytes
            );
        }
        Ok(config)
    }
}
