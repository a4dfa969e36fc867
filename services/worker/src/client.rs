//! The coordinator's internal worker API, seen from a worker.
//!
//! Transient failures (coordinator restarting, connection refused, 5xx) are
//! retried with backoff for a while; 409 (lease lost) and 410 (cancelled) are
//! final answers about the job.

use std::time::{Duration, Instant};

use anyhow::{Context, anyhow};
use motionaug_protocol::{
    ClaimRequest, ClaimedJob, HeartbeatReply, HeartbeatRequest, WORKER_API_PREFIX,
};
use reqwest::StatusCode;
use serde::Serialize;
use uuid::Uuid;

/// What the coordinator said about a report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply<T> {
    Ok(T),
    /// 409: the lease is no longer ours.
    LeaseLost,
    /// 410 (or cancelled heartbeat): the job was cancelled.
    Cancelled,
}

#[derive(Debug)]
pub enum CallError {
    /// Worth retrying: network, 5xx, 429.
    Transient(String),
    /// Not worth retrying.
    Permanent(String),
}

impl std::error::Error for CallError {}

impl std::fmt::Display for CallError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CallError::Transient(m) => write!(f, "transient: {m}"),
            CallError::Permanent(m) => write!(f, "{m}"),
        }
    }
}

#[derive(Clone)]
pub struct Coordinator {
    http: reqwest::Client,
    base: String,
    token: String,
}

impl Coordinator {
    pub fn new(base: &str, token: &str) -> anyhow::Result<Self> {
        let http = reqwest::Client::builder()
            .connect_timeout(Duration::from_secs(5))
            .timeout(Duration::from_secs(120))
            .build()
            .context("building the HTTP client")?;
        Ok(Coordinator {
            http,
            base: format!("{}{}", base.trim_end_matches('/'), WORKER_API_PREFIX),
            token: token.to_string(),
        })
    }

    fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    async fn send(&self, request: reqwest::RequestBuilder) -> Result<reqwest::Response, CallError> {
        let response = request
            .bearer_auth(&self.token)
            .send()
            .await
            .map_err(|e| CallError::Transient(e.to_string()))?;
        let status = response.status();
        if status.is_server_error() || status == StatusCode::TOO_MANY_REQUESTS {
            let text = response.text().await.unwrap_or_default();
            return Err(CallError::Transient(format!("{status}: {text}")));
        }
        Ok(response)
    }

    /// Long-polls for a job; `None` when none became runnable within `wait`.
    pub async fn claim(
        &self,
        worker_id: &str,
        kinds: &[&str],
        wait: Duration,
    ) -> Result<Option<ClaimedJob>, CallError> {
        let body = ClaimRequest {
            worker_id: worker_id.to_string(),
            kinds: kinds.iter().map(|k| k.to_string()).collect(),
            wait_ms: wait.as_millis() as u64,
        };
        let response = self
            .send(
                self.http
                    .post(self.url("/jobs/claim"))
                    .timeout(wait + Duration::from_secs(30))
                    .json(&body),
            )
            .await?;
        match response.status() {
            StatusCode::NO_CONTENT => Ok(None),
            StatusCode::OK => response
                .json()
                .await
                .map(Some)
                .map_err(|e| CallError::Transient(format!("bad claim answer: {e}"))),
            other => Err(CallError::Permanent(format!(
                "claim refused: {other}: {}",
                response.text().await.unwrap_or_default()
            ))),
        }
    }

    fn interpret(status: StatusCode, what: &str, text: String) -> Result<Reply<()>, CallError> {
        match status {
            s if s.is_success() => Ok(Reply::Ok(())),
            StatusCode::CONFLICT => Ok(Reply::LeaseLost),
            StatusCode::GONE => Ok(Reply::Cancelled),
            other => Err(CallError::Permanent(format!("{what}: {other}: {text}"))),
        }
    }

    pub async fn heartbeat(
        &self,
        job: Uuid,
        epoch: i64,
        progress: f64,
    ) -> Result<Reply<()>, CallError> {
        let response = self
            .send(
                self.http
                    .post(self.url(&format!("/jobs/{job}/heartbeat")))
                    .timeout(Duration::from_secs(10))
                    .json(&HeartbeatRequest { epoch, progress }),
            )
            .await?;
        if response.status() == StatusCode::OK {
            let reply: HeartbeatReply = response
                .json()
                .await
                .map_err(|e| CallError::Transient(format!("bad heartbeat answer: {e}")))?;
            return Ok(if reply.cancelled {
                Reply::Cancelled
            } else {
                Reply::Ok(())
            });
        }
        let status = response.status();
        Self::interpret(
            status,
            "heartbeat",
            response.text().await.unwrap_or_default(),
        )
    }

    pub async fn post<B: Serialize>(&self, path: &str, body: &B) -> Result<Reply<()>, CallError> {
        let response = self.send(self.http.post(self.url(path)).json(body)).await?;
        let status = response.status();
        Self::interpret(status, path, response.text().await.unwrap_or_default())
    }

    pub async fn put(&self, path: &str, body: Vec<u8>) -> Result<Reply<()>, CallError> {
        let response = self.send(self.http.put(self.url(path)).body(body)).await?;
        let status = response.status();
        Self::interpret(status, path, response.text().await.unwrap_or_default())
    }

    /// GET raw bytes; `Ok(None)` for 404.
    pub async fn get(&self, path: &str) -> Result<Reply<Option<Vec<u8>>>, CallError> {
        let response = self.send(self.http.get(self.url(path))).await?;
        match response.status() {
            StatusCode::NOT_FOUND => Ok(Reply::Ok(None)),
            s if s.is_success() => response
                .bytes()
                .await
                .map(|b| Reply::Ok(Some(b.to_vec())))
                .map_err(|e| CallError::Transient(e.to_string())),
            s => {
                let text = response.text().await.unwrap_or_default();
                Self::interpret(s, path, text).map(|r| match r {
                    Reply::Ok(()) => Reply::Ok(None),
                    Reply::LeaseLost => Reply::LeaseLost,
                    Reply::Cancelled => Reply::Cancelled,
                })
            }
        }
    }
}

/// Retries `call` on transient errors with backoff until `patience` runs out.
pub async fn with_retries<T, F, Fut>(
    what: &str,
    patience: Duration,
    mut call: F,
) -> anyhow::Result<T>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T, CallError>>,
{
    let deadline = Instant::now() + patience;
    let mut pause = Duration::from_millis(100);
    loop {
        match call().await {
            Ok(value) => return Ok(value),
            Err(CallError::Permanent(m)) => return Err(anyhow!("{what}: {m}")),
            Err(CallError::Transient(m)) => {
                if Instant::now() + pause > deadline {
                    return Err(anyhow!("{what}: coordinator unreachable: {m}"));
                }
                tracing::warn!(what, error = %m, "coordinator call failed; retrying");
                tokio::time::sleep(pause).await;
                pause = (pause * 2).min(Duration::from_secs(2));
            }
        }
    }
}
