//! The job queue: leases, retries, and the job states of the schema.

use crate::helpers::*;

#[tokio::test]
async fn expired_leases_are_reclaimed_and_old_leases_cannot_report() {
    let app = spawn_app(&[("MOTIONAUG_LEASE_MS", "1000")]).await;
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app.augment_json(&dataset, &noise_recipe()).await;
    let aug = aug["id"].as_str().unwrap();
    let first = app.claim().await.unwrap();
    let epoch1 = first["epoch"].as_i64().unwrap();
    let id = first["id"].as_str().unwrap();
    let r = app
        .worker(
            reqwest::Method::PUT,
            &format!("/jobs/{id}/checkpoint?epoch={epoch1}"),
        )
        .body("step 3")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::NO_CONTENT);
    // The first worker goes silent; the lease expires and the job is claimable again.
    let mut second = None;
    for _ in 0..200 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        if let Some(job) = app.claim().await {
            second = Some(job);
            break;
        }
    }
    let second = second.expect("job reclaimed after lease expiry");
    assert_eq!(second["id"], first["id"]);
    assert_eq!(second["attempt"], 2);
    assert_eq!(second["has_checkpoint"], true);
    let epoch2 = second["epoch"].as_i64().unwrap();
    assert!(epoch2 > epoch1);
    let checkpoint = app
        .worker(
            reqwest::Method::GET,
            &format!("/jobs/{id}/checkpoint?epoch={epoch2}"),
        )
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert_eq!(checkpoint, "step 3");
    // The old worker wakes up: everything it says is refused.
    let output = empty_output();
    assert_eq!(
        app.report(
            &first,
            "heartbeat",
            json!({"epoch": epoch1, "progress": 0.9})
        )
        .await,
        StatusCode::CONFLICT
    );
    assert_eq!(
        app.report(
            &first,
            "complete",
            json!({"epoch": epoch1, "output": output})
        )
        .await,
        StatusCode::CONFLICT
    );
    assert_eq!(
        app.report(
            &second,
            "complete",
            json!({"epoch": epoch2, "output": output})
        )
        .await,
        StatusCode::NO_CONTENT
    );
    let (state, completions, attempts): (String, i32, i32) =
        sqlx::query_as("SELECT state, completions, attempts FROM jobs WHERE id = $1::uuid")
            .bind(id)
            .fetch_one(&app.db)
            .await
            .unwrap();
    assert_eq!((state.as_str(), completions, attempts), ("succeeded", 1, 2));
    assert_eq!(app.status(aug).await["status"], "succeeded");
    app.cleanup().await;
}

#[tokio::test]
async fn failures_are_retried_then_kept() {
    let app = spawn_app(&[]).await;
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app.augment_json(&dataset, &noise_recipe()).await;
    let aug = aug["id"].as_str().unwrap();
    // Max attempts is 3: two retryable failures go back to the queue, the third is final.
    for attempt in 1..=3 {
        let mut job = None;
        for _ in 0..100 {
            if let Some(j) = app.claim().await {
                job = Some(j);
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        let job = job.expect("job to retry");
        assert_eq!(job["attempt"], attempt);
        let epoch = job["epoch"].as_i64().unwrap();
        let body = json!({"epoch": epoch, "error": format!("boom {attempt}"), "retryable": true});
        assert_eq!(app.report(&job, "fail", body).await, StatusCode::NO_CONTENT);
    }
    let status = app.status(aug).await;
    assert_eq!(status["status"], "failed");
    assert_eq!(status["jobs"]["failed"], 1);
    assert_eq!(status["errors"][0]["error"], "boom 3");
    assert_eq!(status["errors"][0]["clip"], "walk");
    assert!(app.claim().await.is_none());
    // A permanent failure is not retried.
    let aug2: Value = app.augment_json(&dataset, &noise_recipe()).await;
    let job = app.claim().await.unwrap();
    let epoch = job["epoch"].as_i64().unwrap();
    let body = json!({"epoch": epoch, "error": "bad input", "retryable": false});
    assert_eq!(app.report(&job, "fail", body).await, StatusCode::NO_CONTENT);
    assert_eq!(
        app.status(aug2["id"].as_str().unwrap()).await["status"],
        "failed"
    );
    app.cleanup().await;
}

/// `JobState` names exactly the states the `jobs.state` CHECK constraint allows.
#[tokio::test]
async fn job_states_match_the_schema() {
    let app = spawn_app(&[]).await;
    let check: String = sqlx::query_scalar(
        "SELECT pg_get_constraintdef(c.oid) FROM pg_constraint c
         WHERE c.conrelid = 'jobs'::regclass AND c.contype = 'c'
           AND pg_get_constraintdef(c.oid) LIKE '%state%'",
    )
    .fetch_one(&app.db)
    .await
    .unwrap();
    let allowed: Vec<&str> = check.split('\'').skip(1).step_by(2).collect();
    let ours: Vec<&str> = JobState::ALL.iter().map(|s| s.as_str()).collect();
    assert_eq!(allowed, ours, "{check}");
    app.cleanup().await;
}
