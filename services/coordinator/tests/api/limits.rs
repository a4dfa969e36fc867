//! Recipe bounds and tenant quotas: refused with problems naming the field or
//! the quota, enforced atomically under concurrent requests, shown at
//! `GET /v1/limits`.

use crate::helpers::*;

async fn job_count(app: &TestApp) -> i64 {
    sqlx::query_scalar("SELECT count(*) FROM jobs")
        .fetch_one(&app.db)
        .await
        .unwrap()
}

/// Absurd recipe values are 422 naming the field and its bound (or the quota
/// of outputs per augmentation), and nothing is planned or stored.
#[tokio::test]
async fn unbounded_recipe_values_are_refused_naming_the_field() {
    let app = spawn_app(&[]).await;
    let (dataset, _) = upload_one(&app).await;
    let cases = [
        (
            json!({"ops": [{"op": "mirror"}], "correct": {"time_budget_s": 1e308}}),
            "[correct]",
            "time_budget_s",
        ),
        (
            json!({"ops": [{"op": "mirror"}], "correct": {"envs": 1_000_000}}),
            "[correct]",
            "envs",
        ),
        (
            json!({"ops": [{"op": "mirror"}], "vae": {"iterations": 1_000_000_000_000u64}}),
            "[vae]",
            "iterations",
        ),
        (
            json!({"ops": [{"op": "mirror"}], "correct": {}, "debias": {"hidden": [1_000_000]}}),
            "[debias]",
            "hidden",
        ),
    ];
    for (recipe, field, name) in cases {
        let (status, body) = problem(app.augment(&dataset, &recipe).await).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{recipe}: {body}");
        assert_eq!(body["field"], field, "{body}");
        let detail = body["detail"].as_str().unwrap();
        assert!(detail.contains(name) && detail.contains("bound"), "{body}");
    }
    // 64 ops x 1000 copies: 64,000 outputs of one clip, past the default quota.
    let ops: Vec<Value> = (0..64)
        .map(|_| json!({"op": "noise", "copies": 1000}))
        .collect();
    let (status, body) = problem(app.augment(&dataset, &json!({"ops": ops})).await).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["limit"], "outputs_per_augmentation");
    assert_eq!(body["max"], 20_000);
    assert!(body["detail"].as_str().unwrap().contains("64000"), "{body}");
    assert_eq!(job_count(&app).await, 0);
    app.cleanup().await;
}

/// Concurrent requests of one tenant cannot pass a quota together: of 8
/// simultaneous augmentations with room for 2, exactly 2 are queued; the
/// correction budget and the outputs per augmentation are quotas too.
#[tokio::test]
async fn quotas_hold_under_concurrent_requests() {
    let app = std::sync::Arc::new(
        spawn_app(&[
            ("MOTIONAUG_QUOTA_ACTIVE_AUGMENTATIONS", "2"),
            ("MOTIONAUG_QUOTA_CORRECTION_SECONDS", "100"),
            ("MOTIONAUG_QUOTA_OUTPUTS_PER_AUGMENTATION", "50"),
            ("MOTIONAUG_DB_POOL_SIZE", "10"),
        ])
        .await,
    );
    let (dataset, _) = upload_one(&app).await;
    let mut tasks = tokio::task::JoinSet::new();
    for _ in 0..8 {
        let app = app.clone();
        let dataset = dataset.clone();
        tasks.spawn(async move { app.augment(&dataset, &noise_recipe()).await });
    }
    let mut accepted = Vec::new();
    let mut refused = 0;
    while let Some(r) = tasks.join_next().await {
        let r = r.unwrap();
        if r.status() == StatusCode::ACCEPTED {
            let body: Value = r.json().await.unwrap();
            accepted.push(body["id"].as_str().unwrap().to_string());
        } else {
            let (status, body) = problem(r).await;
            assert_eq!(status, StatusCode::TOO_MANY_REQUESTS, "{body}");
            assert_eq!(body["limit"], "active_augmentations");
            assert_eq!(body["max"], 2);
            refused += 1;
        }
    }
    assert_eq!((accepted.len(), refused), (2, 6));
    let limits = app.get("/v1/limits").send().await.unwrap();
    assert_eq!(limits.status(), StatusCode::OK);
    let limits: Value = limits.json().await.unwrap();
    let quota = |name: &str| {
        limits["quotas"]
            .as_array()
            .unwrap()
            .iter()
            .find(|q| q["name"] == name)
            .cloned()
            .unwrap_or_else(|| panic!("{name} in {limits}"))
    };
    assert_eq!(quota("active_augmentations")["used"], 2.0);
    assert_eq!(quota("active_augmentations")["max"], 2);
    assert_eq!(quota("outputs_per_augmentation")["max"], 50);
    assert!(quota("stored_bytes")["used"].as_f64().unwrap() > 0.0);
    assert!(limits["recipe"]["bounds"].as_array().unwrap().len() >= 10);

    // Cancelling one makes room for one.
    let r = app
        .http
        .delete(app.url(&format!("/v1/augmentations/{}", accepted[0])))
        .bearer_auth(&app.key)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let r = app.augment(&dataset, &noise_recipe()).await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let last: Value = r.json().await.unwrap();
    for id in [&accepted[1], last["id"].as_str().unwrap()] {
        app.http
            .delete(app.url(&format!("/v1/augmentations/{id}")))
            .bearer_auth(&app.key)
            .send()
            .await
            .unwrap();
    }

    // Correction budget: one original + one mirrored clip x 30 s = 60 s of 100.
    let corrected = json!({"ops": [{"op": "mirror"}], "correct": {"time_budget_s": 30}});
    assert_eq!(
        app.augment(&dataset, &corrected).await.status(),
        StatusCode::ACCEPTED
    );
    let (status, body) = problem(app.augment(&dataset, &corrected).await).await;
    assert_eq!(status, StatusCode::TOO_MANY_REQUESTS, "{body}");
    assert_eq!(body["limit"], "correction_seconds");
    // One that alone needs more than the quota can never fit: 422.
    let huge = json!({"ops": [{"op": "mirror"}], "correct": {"time_budget_s": 300}});
    let (status, body) = problem(app.augment(&dataset, &huge).await).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["limit"], "correction_seconds");
    let (status, body) = problem(
        app.augment(&dataset, &json!({"ops": [{"op": "noise", "copies": 51}]}))
            .await,
    )
    .await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["limit"], "outputs_per_augmentation");
    std::sync::Arc::into_inner(app).unwrap().cleanup().await;
}

/// Stored bytes: of 6 simultaneous uploads with room for 2, exactly 2 are
/// stored; the others are 429 naming the quota.
#[tokio::test]
async fn stored_bytes_quota_holds_under_concurrent_uploads() {
    let clip = bvh(40);
    let quota = (2 * clip.len() + clip.len() / 2).to_string();
    let app = std::sync::Arc::new(
        spawn_app(&[
            ("MOTIONAUG_QUOTA_STORED_BYTES", quota.as_str()),
            ("MOTIONAUG_DB_POOL_SIZE", "10"),
        ])
        .await,
    );
    let mut tasks = tokio::task::JoinSet::new();
    for i in 0..6 {
        let app = app.clone();
        let clip = clip.clone();
        tasks.spawn(async move {
            let name = format!("walk{i}.bvh");
            app.upload(&app.key, &[(name.as_str(), clip)]).await
        });
    }
    let (mut created, mut refused) = (0, 0);
    while let Some(r) = tasks.join_next().await {
        let r = r.unwrap();
        if r.status() == StatusCode::CREATED {
            created += 1;
        } else {
            let (status, body) = problem(r).await;
            assert_eq!(status, StatusCode::TOO_MANY_REQUESTS, "{body}");
            assert_eq!(body["limit"], "stored_bytes");
            refused += 1;
        }
    }
    assert_eq!((created, refused), (2, 4));
    assert_eq!(app.dataset_count().await, 2);
    std::sync::Arc::into_inner(app).unwrap().cleanup().await;
}
