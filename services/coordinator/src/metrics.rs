//! Prometheus metrics served at `/metrics`.
//!
//! Queue depth and worker count are read from Postgres at scrape time, so every
//! coordinator reports the same cluster-wide figures; durations, failures and
//! request latencies are counted by the process that saw them.

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;
use sqlx::PgPool;

use crate::state::JobState;

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct StateLabel {
    pub state: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct KindLabel {
    pub kind: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct FailureLabel {
    pub kind: String,
    /// `error` (worker reported), `lease_expired` (worker vanished).
    pub reason: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
pub struct RouteLabel {
    pub method: String,
    pub route: String,
    pub status: u16,
}

fn histogram_factory() -> Histogram {
    Histogram::new(exponential_buckets(0.001, 2.0, 16))
}

fn job_histogram_factory() -> Histogram {
    Histogram::new(exponential_buckets(0.05, 2.0, 20))
}

type HistogramFamily<L> = Family<L, Histogram, fn() -> Histogram>;

pub struct Metrics {
    registry: Registry,
    pub jobs: Family<StateLabel, Gauge>,
    pub workers_active: Gauge,
    pub job_duration: HistogramFamily<KindLabel>,
    pub job_failures: Family<FailureLabel, Counter>,
    pub jobs_completed: Family<KindLabel, Counter>,
    pub stale_reports: Counter,
    pub http_requests: HistogramFamily<RouteLabel>,
    pub events_published: Counter,
    pub event_publish_errors: Counter,
}

impl Default for Metrics {
    fn default() -> Self {
        Self::new()
    }
}

impl Metrics {
    pub fn new() -> Self {
        let mut registry = Registry::with_prefix("motionaug");
        let jobs = Family::<StateLabel, Gauge>::default();
        registry.register(
            "jobs",
            "Jobs by state (queue depth = state queued)",
            jobs.clone(),
        );
        let workers_active = Gauge::default();
        registry.register(
            "workers_active",
            "Workers that contacted a coordinator within two lease periods",
            workers_active.clone(),
        );
        let job_duration: HistogramFamily<KindLabel> =
            Family::new_with_constructor(job_histogram_factory);
        registry.register(
            "job_duration_seconds",
            "Wall time of successful job attempts, claim to completion",
            job_duration.clone(),
        );
        let job_failures = Family::<FailureLabel, Counter>::default();
        registry.register("job_failures", "Failed job attempts", job_failures.clone());
        let jobs_completed = Family::<KindLabel, Counter>::default();
        registry.register("jobs_completed", "Jobs completed", jobs_completed.clone());
        let stale_reports = Counter::default();
        registry.register(
            "stale_reports",
            "Worker reports refused because their lease was no longer current",
            stale_reports.clone(),
        );
        let http_requests: HistogramFamily<RouteLabel> =
            Family::new_with_constructor(histogram_factory);
        registry.register(
            "http_request_duration_seconds",
            "HTTP request latency by route and status",
            http_requests.clone(),
        );
        let events_published = Counter::default();
        registry.register(
            "events_published",
            "Events published to Redis",
            events_published.clone(),
        );
        let event_publish_errors = Counter::default();
        registry.register(
            "event_publish_errors",
            "Events that could not be published to Redis",
            event_publish_errors.clone(),
        );
        // Known kinds are exported from the start, so dashboards see zeros, not gaps.
        for kind in motionaug_protocol::kinds::ALL {
            let label = KindLabel {
                kind: kind.to_string(),
            };
            let _ = job_duration.get_or_create(&label);
            let _ = jobs_completed.get_or_create(&label);
            for reason in ["error", "lease_expired"] {
                let _ = job_failures.get_or_create(&FailureLabel {
                    kind: kind.to_string(),
                    reason: reason.into(),
                });
            }
        }
        Metrics {
            registry,
            jobs,
            workers_active,
            job_duration,
            job_failures,
            jobs_completed,
            stale_reports,
            http_requests,
            events_published,
            event_publish_errors,
        }
    }

    /// Refreshes the database-derived gauges and renders the text format.
    pub async fn render(
        &self,
        db: &PgPool,
        lease: std::time::Duration,
    ) -> Result<String, sqlx::Error> {
        let counts: Vec<(JobState, i64)> =
            sqlx::query_as("SELECT state, count(*) FROM jobs GROUP BY state")
                .fetch_all(db)
                .await?;
        for state in JobState::ALL {
            let n = counts
                .iter()
                .find(|(s, _)| *s == state)
                .map_or(0, |(_, n)| *n);
            self.jobs
                .get_or_create(&StateLabel {
                    state: state.as_str().into(),
                })
                .set(n);
        }
        let window = (lease * 2).as_secs_f64();
        let workers: i64 = sqlx::query_scalar(
            "SELECT count(*) FROM workers WHERE last_seen > now() - make_interval(secs => $1)",
        )
        .bind(window)
        .fetch_one(db)
        .await?;
        self.workers_active.set(workers);
        let mut out = String::new();
        prometheus_client::encoding::text::encode(&mut out, &self.registry)
            .map_err(|e| sqlx::Error::Protocol(format!("metrics encoding failed: {e}")))?;
        Ok(out)
    }
}
