//! Wiring: database pool and migrations, Redis events, metrics, the router and the
//! background tasks (lease reaper, Redis subscriber) of one coordinator process.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use axum::extract::{MatchedPath, Request, State};
use axum::middleware::{self, Next};
use axum::response::Response;
use axum::{Extension, Router};
use sqlx::postgres::PgPoolOptions;
use sqlx::{Connection, PgPool};
use tokio::net::TcpListener;
use tokio::task::JoinHandle;

use crate::auth::KeyCache;
use crate::configuration::Config;
use crate::events::{Event, Events};
use crate::metrics::{FailureLabel, Metrics, RouteLabel};
use crate::openapi::{self, OpenApiJson};
use crate::state::JobState;
use crate::upload_memory::UploadMemory;
use crate::{error, queue, routes};

/// Shared state of the request handlers.
#[derive(Clone)]
pub struct AppState {
    pub db: PgPool,
    pub config: Arc<Config>,
    pub events: Events,
    pub metrics: Arc<Metrics>,
    /// Upload slots and the memory budget of uploads.
    pub uploads: UploadMemory,
    /// API keys looked up recently.
    pub keys: KeyCache,
}

/// A pooled connection idle this long is checked (a round trip) before use.
const PING_IF_IDLE_FOR: Duration = Duration::from_secs(30);

/// The pool's settings. sqlx checks every connection it hands out with a
/// round trip to Postgres by default, which doubles the round trips of a
/// one-query request such as a status poll; here only a connection idle for
/// [`PING_IF_IDLE_FOR`] is checked. (A connection that broke sooner, say by
/// a Postgres restart, fails the one request that meets it ("try again", 500), and
/// sqlx drops it.)
fn pool_options(pool_size: u32) -> PgPoolOptions {
    PgPoolOptions::new()
        .max_connections(pool_size)
        .acquire_timeout(Duration::from_secs(5))
        .test_before_acquire(false)
        .before_acquire(|conn, meta| {
            Box::pin(async move {
                if meta.idle_for >= PING_IF_IDLE_FOR {
                    conn.ping().await?;
                }
                Ok(true)
            })
        })
}

/// Connects to Postgres, waiting up to a minute for it to come up (containers
/// start in any order), and applies the migrations.
pub async fn connect_and_migrate(database_url: &str, pool_size: u32) -> anyhow::Result<PgPool> {
    let deadline = Instant::now() + Duration::from_secs(60);
    let db = loop {
        match pool_options(pool_size).connect(database_url).await {
            Ok(db) => break db,
            Err(e) if Instant::now() < deadline => {
                tracing::warn!(error = %e, "database not reachable yet; retrying");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
            Err(e) => return Err(e).context("cannot connect to the database (DATABASE_URL)"),
        }
    };
    sqlx::migrate!("../../migrations")
        .run(&db)
        .await
        .context("applying database migrations")?;
    Ok(db)
}

pub struct Application {
    listener: TcpListener,
    state: AppState,
}

impl Application {
    pub async fn build(config: Config) -> anyhow::Result<Self> {
        let db = connect_and_migrate(&config.database_url, config.db_pool_size).await?;
        let metrics = Arc::new(Metrics::new());
        let events = Events::new(config.redis_url.as_deref(), &config.redis_prefix, &metrics)?;
        let listener = TcpListener::bind(&config.listen)
            .await
            .with_context(|| format!("cannot listen on {} (MOTIONAUG_LISTEN)", config.listen))?;
        let uploads = UploadMemory::new(
            config.limits.max_concurrent_uploads,
            config.limits.upload_memory_bytes,
        );
        Ok(Application {
            listener,
            state: AppState {
                uploads,
                keys: KeyCache::default(),
                db,
                config: Arc::new(config),
                events,
                metrics,
            },
        })
    }

    pub fn port(&self) -> u16 {
        self.listener.local_addr().map(|a| a.port()).unwrap_or(0)
    }

    pub fn state(&self) -> &AppState {
        &self.state
    }

    /// Serves until `shutdown` resolves, then finishes open requests and stops the
    /// background tasks.
    pub async fn run_until_stopped(
        self,
        shutdown: impl std::future::Future<Output = ()> + Send + 'static,
    ) -> anyhow::Result<()> {
        let background = spawn_background(&self.state);
        let router = router(self.state.clone());
        tracing::info!(addr = ?self.listener.local_addr().ok(), "coordinator listening");
        let served = axum::serve(self.listener, router)
            .with_graceful_shutdown(shutdown)
            .await;
        for task in background {
            task.abort();
        }
        served.context("http server failed")
    }
}

/// The application's router, serving the OpenAPI document that its routes make.
pub fn router(state: AppState) -> Router {
    let (routes, api) = routes::router(&state.config.limits).split_for_parts();
    let document = OpenApiJson::new(&openapi::finish(api));
    routes
        .layer(Extension(document))
        .layer(middleware::from_fn(error::problem_for_every_error))
        .layer(middleware::from_fn_with_state(
            state.clone(),
            track_requests,
        ))
        .with_state(state)
}

/// Logs every request and records its latency by route.
async fn track_requests(State(state): State<AppState>, request: Request, next: Next) -> Response {
    let started = Instant::now();
    let method = request.method().to_string();
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    let response = next.run(request).await;
    let elapsed = started.elapsed();
    let status = response.status().as_u16();
    state
        .metrics
        .http_requests
        .get_or_create(&RouteLabel {
            method: method.clone(),
            route: route.clone(),
            status,
        })
        .observe(elapsed.as_secs_f64());
    if route != "/metrics" && route != "/healthz" {
        tracing::info!(%method, %route, status, elapsed_ms = elapsed.as_secs_f64() * 1e3, "request");
    }
    response
}

fn spawn_background(state: &AppState) -> Vec<JoinHandle<()>> {
    let subscriber = tokio::spawn(state.events.clone().run_subscriber());
    let reaper_state = state.clone();
    let reaper = tokio::spawn(async move {
        let mut tick = tokio::time::interval(reaper_state.config.queue.reap_interval);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tick.tick().await;
            reap_once(&reaper_state).await;
        }
    });
    vec![subscriber, reaper]
}

async fn reap_once(state: &AppState) {
    match queue::reap(&state.db, state.config.queue.retry_base).await {
        Ok(reaped) => {
            for job in reaped {
                tracing::warn!(job = %job.id, kind = %job.kind, new_state = %job.state, "lease expired");
                state
                    .metrics
                    .job_failures
                    .get_or_create(&FailureLabel {
                        kind: job.kind.clone(),
                        reason: "lease_expired".into(),
                    })
                    .inc();
                state
                    .events
                    .publish(Event::Augmentation {
                        id: job.augmentation_id,
                    })
                    .await;
                if job.state == JobState::Queued {
                    state.events.publish(Event::Wake { kind: job.kind }).await;
                }
            }
        }
        Err(e) => tracing::warn!(error = %e, "lease reaper failed; will retry"),
    }
}
