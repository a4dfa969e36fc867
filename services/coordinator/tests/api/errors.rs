//! Every error answer is `application/problem+json`, including those the router
//! and axum's extractors make before a handler runs, and each says what is true.

use crate::helpers::*;

/// A bad UUID in a path, bad query values, a JSON body over its limit, a
/// method a route does not serve, a body that is not the expected JSON, an
/// unknown route: all problems, with the status they always had.
#[tokio::test]
async fn errors_made_outside_the_handlers_are_problems() {
    let app = spawn_app(&[]).await;
    let (dataset, _) = upload_one(&app).await;

    let r = app.get("/v1/datasets/not-a-uuid").send().await.unwrap();
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::BAD_REQUEST);
    assert!(body["detail"].as_str().unwrap().contains("UUID"), "{body}");
    assert_eq!(body["status"], 400);

    for seed in ["-1", "abc", "18446744073709551616", "1.5"] {
        let r = app
            .http
            .post(app.url(&format!("/v1/datasets/{dataset}/augmentations?seed={seed}")))
            .bearer_auth(&app.key)
            .json(&noise_recipe())
            .send()
            .await
            .unwrap();
        let (status, body) = problem(r).await;
        assert_eq!(status, StatusCode::BAD_REQUEST, "seed={seed}");
        assert!(body["detail"].as_str().unwrap().contains("seed"), "{body}");
    }

    // A recipe over the 4 MiB JSON limit.
    let padding = "x".repeat(5 << 20);
    let r = app
        .http
        .post(app.url(&format!("/v1/datasets/{dataset}/augmentations")))
        .bearer_auth(&app.key)
        .header("content-type", "application/json")
        .body(format!(
            "{{\"ops\": [{{\"op\": \"noise\"}}], \"pad\": \"{padding}\"}}"
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r).await.0, StatusCode::PAYLOAD_TOO_LARGE);

    // 405 keeps its Allow header and gains a body.
    let r = app
        .http
        .patch(app.url("/v1/datasets"))
        .bearer_auth(&app.key)
        .send()
        .await
        .unwrap();
    let allow = r.headers().get("allow").cloned();
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::METHOD_NOT_ALLOWED);
    let allow = allow.expect("405 keeps Allow");
    assert!(allow.to_str().unwrap().contains("POST"), "{allow:?}");
    assert!(body["detail"].as_str().unwrap().contains("PATCH"), "{body}");

    // The worker API: a bad id, a body that is not JSON, a body that does not match.
    let r = app
        .worker(reqwest::Method::POST, "/jobs/not-a-uuid/heartbeat")
        .json(&json!({"epoch": 1, "progress": 0.5}))
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r).await.0, StatusCode::BAD_REQUEST);
    let r = app
        .worker(reqwest::Method::POST, "/jobs/claim")
        .header("content-type", "application/json")
        .body("{")
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r).await.0, StatusCode::BAD_REQUEST);
    let r = app
        .worker(reqwest::Method::POST, "/jobs/claim")
        .json(&json!({"worker_id": 7}))
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r).await.0, StatusCode::UNPROCESSABLE_ENTITY);
    let r = app
        .worker(
            reqwest::Method::PUT,
            &format!("/jobs/{}/checkpoint?epoch=x", Uuid::new_v4()),
        )
        .body("x")
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r).await.0, StatusCode::BAD_REQUEST);

    let r = app.get("/v1/nothing-here").send().await.unwrap();
    assert_eq!(problem(r).await.0, StatusCode::NOT_FOUND);
    app.cleanup().await;
}

/// A report about a job that does not exist says so (and still tells the
/// worker to drop it with 410), instead of claiming it was cancelled.
#[tokio::test]
async fn a_missing_job_is_not_called_cancelled() {
    let app = spawn_app(&[]).await;
    let id = Uuid::new_v4();
    let reports = [
        (
            reqwest::Method::POST,
            format!("/jobs/{id}/heartbeat"),
            json!({"epoch": 1, "progress": 0.1}),
        ),
        (
            reqwest::Method::POST,
            format!("/jobs/{id}/complete"),
            json!({"epoch": 1, "output": empty_output()}),
        ),
        (
            reqwest::Method::POST,
            format!("/jobs/{id}/fail"),
            json!({"epoch": 1, "error": "x", "retryable": true}),
        ),
        (
            reqwest::Method::POST,
            format!("/jobs/{id}/release"),
            json!({"epoch": 1}),
        ),
    ];
    for (method, path, body) in reports {
        let r = app.worker(method, &path).json(&body).send().await.unwrap();
        let (status, problem) = problem(r).await;
        assert_eq!(status, StatusCode::GONE, "{path}");
        let detail = problem["detail"].as_str().unwrap();
        assert!(
            detail.contains("no job") && !detail.contains("cancelled"),
            "{path}: {detail}"
        );
    }
    let r = app
        .worker(
            reqwest::Method::GET,
            &format!("/jobs/{id}/checkpoint?epoch=1"),
        )
        .send()
        .await
        .unwrap();
    let (status, problem) = problem(r).await;
    assert_eq!(status, StatusCode::GONE);
    assert!(problem["detail"].as_str().unwrap().contains("no job"));
    app.cleanup().await;
}
