//! Operational endpoints, API keys, and running without Redis.

use crate::helpers::*;

#[tokio::test]
async fn operational_endpoints_work_without_a_key() {
    let app = spawn_app(&[]).await;
    let r = app.http.get(app.url("/healthz")).send().await.unwrap();
    assert_eq!(r.status(), StatusCode::OK);
    let ready: Value = app.public_json("/readyz").await;
    assert_eq!(ready["database"], "ok");
    assert_eq!(ready["redis"], "ok");
    let metrics = app
        .http
        .get(app.url("/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    for name in [
        "motionaug_jobs{state=\"queued\"}",
        "motionaug_workers_active",
        "motionaug_job_duration_seconds",
        "motionaug_job_failures",
    ] {
        assert!(metrics.contains(name), "metrics lack {name}:\n{metrics}");
    }
    let openapi: Value = app.public_json("/openapi.json").await;
    for path in [
        "/v1/datasets",
        "/v1/datasets/{id}",
        "/v1/datasets/{id}/augmentations",
        "/v1/augmentations/{id}",
        "/v1/augmentations/{id}/events",
        "/v1/augmentations/{id}/results",
    ] {
        assert!(openapi["paths"].get(path).is_some(), "{path} undocumented");
    }
    let page = app
        .http
        .get(app.url("/docs"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(page.contains("/openapi.json") && !page.contains("https://"));
    app.cleanup().await;
}

#[tokio::test]
async fn requests_without_a_valid_key_are_refused() {
    let app = spawn_app(&[]).await;
    let r = app.http.get(app.url("/v1/datasets")).send().await.unwrap();
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNAUTHORIZED);
    assert!(body["detail"].as_str().unwrap().contains("Bearer"));
    let r = app
        .http
        .get(app.url("/v1/datasets"))
        .bearer_auth("mak_nope")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::UNAUTHORIZED);
    // The worker API does not accept tenant keys, nor tenants the worker token.
    let r = app
        .http
        .post(app.url("/internal/v1/jobs/claim"))
        .bearer_auth(&app.key)
        .json(&json!({"worker_id": "w", "kinds": ["synthesize"]}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::UNAUTHORIZED);
    let r = app
        .http
        .get(app.url("/v1/datasets"))
        .bearer_auth(WORKER_TOKEN)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::UNAUTHORIZED);
    app.cleanup().await;
}

#[tokio::test]
async fn works_without_redis() {
    // Nothing listens on port 1: events stay in-process and listeners poll.
    let app = spawn_app(&[("REDIS_URL", "redis://127.0.0.1:1/0")]).await;
    let ready: Value = app.public_json("/readyz").await;
    assert_eq!(ready["redis"], "unreachable");
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app.augment_json(&dataset, &noise_recipe()).await;
    let job = app.claim().await.unwrap();
    let output = empty_output();
    let epoch = job["epoch"].as_i64().unwrap();
    assert_eq!(
        app.report(&job, "complete", json!({"epoch": epoch, "output": output}))
            .await,
        StatusCode::NO_CONTENT
    );
    assert_eq!(
        app.status(aug["id"].as_str().unwrap()).await["status"],
        "succeeded"
    );
    app.cleanup().await;
}
