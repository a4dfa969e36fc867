//! Live events between coordinator processes over Redis pub/sub.
//!
//! Redis is only a hint channel: every fact lives in Postgres. Events wake up
//! long-polling workers when work is enqueued and push progress to SSE clients;
//! when Redis is down, publishing fails quietly and the listeners fall back to
//! polling the database, so nothing is lost, only a little latency.
//!
//! Every published event is also delivered to this process's own listeners
//! directly, so a single coordinator gives prompt events without Redis.

use std::sync::Arc;
use std::time::Duration;

use futures_util::StreamExt;
use serde::{Deserialize, Serialize};
use tokio::sync::{Mutex, broadcast};
use uuid::Uuid;

/// What happened (kept small: listeners re-read the database).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// New runnable work of this kind may exist.
    Wake { kind: String },
    /// A job of this augmentation changed (state, progress) or it was cancelled.
    Augmentation { id: Uuid },
}

#[derive(Clone)]
pub struct Events {
    inner: Arc<Inner>,
}

struct Inner {
    client: Option<redis::Client>,
    channel: String,
    local: broadcast::Sender<Event>,
    publisher: Mutex<Option<redis::aio::MultiplexedConnection>>,
    published: prometheus_client::metrics::counter::Counter,
    publish_errors: prometheus_client::metrics::counter::Counter,
}

const REDIS_TIMEOUT: Duration = Duration::from_millis(500);

impl Events {
    /// `redis_url = None` runs without Redis (events stay inside this process).
    pub fn new(
        redis_url: Option<&str>,
        prefix: &str,
        metrics: &crate::metrics::Metrics,
    ) -> anyhow::Result<Self> {
        let client = match redis_url {
            Some(url) => Some(redis::Client::open(url)?),
            None => None,
        };
        let (local, _) = broadcast::channel(1024);
        Ok(Events {
            inner: Arc::new(Inner {
                client,
                channel: format!("{prefix}:events"),
                local,
                publisher: Mutex::new(None),
                published: metrics.events_published.clone(),
                publish_errors: metrics.event_publish_errors.clone(),
            }),
        })
    }

    pub fn subscribe(&self) -> broadcast::Receiver<Event> {
        self.inner.local.subscribe()
    }

    /// Delivers locally and publishes to Redis; never fails (errors are logged).
    pub async fn publish(&self, event: Event) {
        let _ = self.inner.local.send(event.clone());
        let Some(client) = &self.inner.client else {
            return;
        };
        let Ok(payload) = serde_json::to_string(&event) else {
            return;
        };
        let mut guard = self.inner.publisher.lock().await;
        let result = tokio::time::timeout(REDIS_TIMEOUT, async {
            if guard.is_none() {
                *guard = Some(client.get_multiplexed_async_connection().await?);
            }
            let conn = guard.as_mut().expect("connection was just set");
            redis::cmd("PUBLISH")
                .arg(&self.inner.channel)
                .arg(&payload)
                .query_async::<i64>(conn)
                .await
        })
        .await;
        match result {
            Ok(Ok(_)) => {
                self.inner.published.inc();
            }
            Ok(Err(e)) => {
                *guard = None;
                self.inner.publish_errors.inc();
                tracing::warn!(error = %e, "redis publish failed; listeners will poll");
            }
            Err(_) => {
                *guard = None;
                self.inner.publish_errors.inc();
                tracing::warn!("redis publish timed out; listeners will poll");
            }
        }
    }

    /// Whether Redis answers a PING (for `/readyz`); `None` without Redis.
    pub async fn redis_ok(&self) -> Option<bool> {
        let client = self.inner.client.as_ref()?;
        let ping = tokio::time::timeout(REDIS_TIMEOUT, async {
            let mut conn = client.get_multiplexed_async_connection().await?;
            redis::cmd("PING").query_async::<String>(&mut conn).await
        })
        .await;
        Some(matches!(ping, Ok(Ok(_))))
    }

    /// Forwards events published by other coordinators to the local listeners,
    /// reconnecting with backoff whenever Redis goes away. Runs until aborted.
    pub async fn run_subscriber(self) {
        let Some(client) = self.inner.client.clone() else {
            return;
        };
        let mut backoff = Duration::from_millis(100);
        loop {
            match self.subscribe_once(&client).await {
                Ok(()) => {
                    tracing::warn!("redis subscription ended; reconnecting");
                    backoff = Duration::from_millis(100);
                }
                Err(e) => tracing::warn!(error = %e, "redis subscription failed; reconnecting"),
            }
            tokio::time::sleep(backoff).await;
            backoff = (backoff * 2).min(Duration::from_secs(5));
        }
    }

    async fn subscribe_once(&self, client: &redis::Client) -> redis::RedisResult<()> {
        let mut pubsub = tokio::time::timeout(REDIS_TIMEOUT, client.get_async_pubsub())
            .await
            .map_err(|_| redis::RedisError::from((redis::ErrorKind::Io, "connect timed out")))??;
        pubsub.subscribe(&self.inner.channel).await?;
        tracing::info!(channel = %self.inner.channel, "subscribed to redis events");
        let mut messages = pubsub.on_message();
        while let Some(message) = messages.next().await {
            let Ok(payload) = message.get_payload::<String>() else {
                continue;
            };
            if let Ok(event) = serde_json::from_str::<Event>(&payload) {
                let _ = self.inner.local.send(event);
            }
        }
        Ok(())
    }
}
