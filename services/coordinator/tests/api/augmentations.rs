//! Augmentations: recipes refused or planned into the job graph, driven through the
//! worker API to a download, cancellation and the event stream.

use crate::helpers::*;

#[tokio::test]
async fn bad_recipes_name_the_field() {
    let app = spawn_app(&[]).await;
    let (dataset, _) = upload_one(&app).await;
    let r = app
        .augment(&dataset, &json!({"ops": [{"op": "noise", "copies": 0}]}))
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(body["field"].as_str().unwrap().contains("ops[0]"), "{body}");
    assert!(
        body["detail"].as_str().unwrap().contains("copies"),
        "{body}"
    );
    let r = app
        .augment(&dataset, &json!({"ops": [{"op": "explode"}]}))
        .await;
    let (_, body) = problem(r).await;
    assert!(body["detail"].as_str().unwrap().contains("explode"));
    let r = app
        .http
        .post(app.url(&format!("/v1/datasets/{dataset}/augmentations")))
        .bearer_auth(&app.key)
        .body("{\"ops\": [")
        .send()
        .await
        .unwrap();
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["line"], 1);
    let jobs: i64 = sqlx::query_scalar("SELECT count(*) FROM jobs")
        .fetch_one(&app.db)
        .await
        .unwrap();
    assert_eq!(jobs, 0);
    app.cleanup().await;
}

/// The whole flow through the worker API: claim, heartbeat, artifacts,
/// checkpoint, completion; stale and duplicate reports; results zip.
#[tokio::test]
async fn augment_poll_and_download_through_the_worker_api() {
    let app = spawn_app(&[]).await;
    let r = app
        .upload(&app.key, &[("walk.bvh", bvh(30)), ("jump.bvh", bvh(20))])
        .await;
    let dataset: Value = r.json().await.unwrap();
    let dataset = dataset["id"].as_str().unwrap();
    let r = app.augment(dataset, &noise_recipe()).await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let aug: Value = r.json().await.unwrap();
    assert_eq!(aug["status"], "queued");
    let aug = aug["id"].as_str().unwrap();
    let status = app.status(aug).await;
    assert_eq!(status["jobs"]["total"], 2);
    assert_eq!(status["jobs"]["queued"], 2);
    assert_eq!(status["progress"], 0.0);
    let r = app
        .get(&format!("/v1/augmentations/{aug}/results"))
        .send()
        .await
        .unwrap();
    assert_eq!(problem(r).await.0, StatusCode::CONFLICT);

    for expected_clip in ["walk", "jump"] {
        let job = app.claim().await.expect("a job");
        let id = job["id"].as_str().unwrap();
        let epoch = job["epoch"].as_i64().unwrap();
        assert_eq!(job["input"]["clip_name"], expected_clip);
        // The job is stored as planned, seeded by the augmentation's seed (3).
        let recipe = pipeline::Recipe::from_value(noise_recipe()).unwrap();
        let names = ["walk".to_string(), "jump".to_string()];
        let planned = pipeline::plan(&recipe, &names, 3);
        let key = format!("synthesize:{expected_clip}");
        assert_eq!(
            job["input"]["job"],
            serde_json::to_value(planned.job(&key).unwrap()).unwrap()
        );
        assert_eq!(job["has_checkpoint"], false);
        // The worker can read the clip it was given.
        let clip_id = job["input"]["clips"][0]["clip_id"].as_str().unwrap();
        let source = app
            .worker(reqwest::Method::GET, &format!("/clips/{clip_id}/source"))
            .send()
            .await
            .unwrap()
            .bytes()
            .await
            .unwrap();
        assert!(source.starts_with(b"HIERARCHY"));
        assert_eq!(
            app.report(&job, "heartbeat", json!({"epoch": epoch, "progress": 0.5}))
                .await,
            StatusCode::OK
        );
        let s = app.status(aug).await;
        assert_eq!(s["status"], "running");
        assert!(s["progress"].as_f64().unwrap() > 0.0);
        let file = format!("{expected_clip}_out.bvh");
        let r = app
            .worker(
                reqwest::Method::PUT,
                &format!("/jobs/{id}/artifacts/{file}?epoch={epoch}"),
            )
            .body(format!("content of {expected_clip}"))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::NO_CONTENT);
        let r = app
            .worker(
                reqwest::Method::PUT,
                &format!("/jobs/{id}/checkpoint?epoch={epoch}"),
            )
            .body("cp")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::NO_CONTENT);
        // A wrong epoch is refused everywhere.
        let stale = epoch - 1;
        assert_eq!(
            app.report(&job, "heartbeat", json!({"epoch": stale, "progress": 0.1}))
                .await,
            StatusCode::CONFLICT
        );
        let r = app
            .worker(
                reqwest::Method::PUT,
                &format!("/jobs/{id}/artifacts/x.bvh?epoch={stale}"),
            )
            .body("old")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::CONFLICT);
        // An output naming a file that was never uploaded is refused.
        let bad = json!({"manifest": [], "files": ["never.bvh"]});
        assert_eq!(
            app.report(&job, "complete", json!({"epoch": epoch, "output": bad}))
                .await,
            StatusCode::UNPROCESSABLE_ENTITY
        );
        let bad = json!({"manifest": [{"file": "x"}], "files": []});
        assert_eq!(
            app.report(&job, "complete", json!({"epoch": epoch, "output": bad}))
                .await,
            StatusCode::UNPROCESSABLE_ENTITY
        );
        let output =
            json!({"manifest": [entry(&file, &format!("{expected_clip}.bvh"))], "files": [file]});
        assert_eq!(
            app.report(&job, "complete", json!({"epoch": stale, "output": output}))
                .await,
            StatusCode::CONFLICT
        );
        assert_eq!(
            app.report(&job, "complete", json!({"epoch": epoch, "output": output}))
                .await,
            StatusCode::NO_CONTENT
        );
        // A duplicate of the accepted report changes nothing and is not an error.
        assert_eq!(
            app.report(
                &job,
                "complete",
                json!({"epoch": epoch, "output": empty_output()})
            )
            .await,
            StatusCode::NO_CONTENT
        );
        // Reports after completion are refused.
        let r = app
            .worker(
                reqwest::Method::PUT,
                &format!("/jobs/{id}/artifacts/late.bvh?epoch={epoch}"),
            )
            .body("late")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), StatusCode::CONFLICT);
    }
    assert!(app.claim().await.is_none());
    let status = app.status(aug).await;
    assert_eq!(status["status"], "succeeded");
    assert_eq!(status["progress"], 1.0);
    assert_eq!(status["jobs"]["succeeded"], 2);
    let completions: Vec<i32> = sqlx::query_scalar("SELECT completions FROM jobs")
        .fetch_all(&app.db)
        .await
        .unwrap();
    assert_eq!(completions, vec![1, 1]);

    let r = app
        .get(&format!("/v1/augmentations/{aug}/results"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::OK);
    assert_eq!(r.headers()["content-type"], "application/zip");
    let bytes = r.bytes().await.unwrap();
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes.to_vec())).unwrap();
    let mut names: Vec<String> = zip.file_names().map(|n| n.unwrap().to_string()).collect();
    names.sort();
    assert_eq!(names, vec!["jump_out.bvh", "manifest.json", "walk_out.bvh"]);
    let mut manifest = String::new();
    zip.by_name("manifest.json")
        .unwrap()
        .read_to_string(&mut manifest)
        .unwrap();
    let manifest: Value = serde_json::from_str(&manifest).unwrap();
    // Sorted by source as the CLI does.
    assert_eq!(manifest[0]["file"], "jump_out.bvh");
    assert_eq!(manifest[1]["file"], "walk_out.bvh");
    let mut content = String::new();
    zip.by_name("walk_out.bvh")
        .unwrap()
        .read_to_string(&mut content)
        .unwrap();
    assert_eq!(content, "content of walk");

    let metrics = app
        .http
        .get(app.url("/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        metrics.contains("motionaug_jobs{state=\"succeeded\"} 2"),
        "{metrics}"
    );
    assert!(metrics.contains("motionaug_workers_active 1"), "{metrics}");
    assert!(
        metrics.contains("motionaug_job_duration_seconds_count{kind=\"synthesize\"} 2"),
        "{metrics}"
    );
    app.cleanup().await;
}

#[tokio::test]
async fn cancellation_reaches_running_jobs_and_events_stream() {
    let app = spawn_app(&[]).await;
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app.augment_json(&dataset, &noise_recipe()).await;
    let aug = aug["id"].as_str().unwrap().to_string();

    // Follow the augmentation's events while a worker runs and it is cancelled.
    let events = app
        .get(&format!("/v1/augmentations/{aug}/events"))
        .send()
        .await
        .unwrap();
    assert_eq!(events.status(), StatusCode::OK);
    assert!(
        events.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/event-stream")
    );
    // The first event (sent as soon as the stream is read) is the queued state.
    let mut stream = events;
    let first = stream.chunk().await.unwrap().expect("a first event");
    let first = String::from_utf8_lossy(&first).into_owned();
    assert!(first.contains("\"status\":\"queued\""), "{first}");
    let seen = std::sync::Arc::new(std::sync::Mutex::new(first));
    let seen_by_reader = seen.clone();
    let reader = tokio::spawn(async move {
        while let Ok(Some(chunk)) = stream.chunk().await {
            seen_by_reader
                .lock()
                .unwrap()
                .push_str(&String::from_utf8_lossy(&chunk));
        }
        seen_by_reader.lock().unwrap().clone()
    });

    let job = app.claim().await.unwrap();
    let epoch = job["epoch"].as_i64().unwrap();
    let reply: Value = app
        .worker(
            reqwest::Method::POST,
            &format!("/jobs/{}/heartbeat", job["id"].as_str().unwrap()),
        )
        .json(&json!({"epoch": epoch, "progress": 0.25}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(reply["cancelled"], false);
    // The stream reports the running job before it is cancelled.
    for _ in 0..400 {
        if seen.lock().unwrap().contains("\"status\":\"running\"") {
            break;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    let r = app
        .http
        .delete(app.url(&format!("/v1/augmentations/{aug}")))
        .bearer_auth(&app.key)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let reply: Value = app
        .worker(
            reqwest::Method::POST,
            &format!("/jobs/{}/heartbeat", job["id"].as_str().unwrap()),
        )
        .json(&json!({"epoch": epoch, "progress": 0.5}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(reply["cancelled"], true);
    let output = empty_output();
    assert_eq!(
        app.report(&job, "complete", json!({"epoch": epoch, "output": output}))
            .await,
        StatusCode::GONE
    );
    assert_eq!(app.status(&aug).await["status"], "cancelled");

    let text = tokio::time::timeout(Duration::from_secs(10), reader)
        .await
        .expect("stream ends")
        .unwrap();
    let statuses: Vec<Value> = text
        .lines()
        .filter_map(|l| l.strip_prefix("data: "))
        .map(|d| serde_json::from_str(d).unwrap())
        .collect();
    let names: Vec<&str> = statuses
        .iter()
        .map(|s| s["status"].as_str().unwrap())
        .collect();
    assert_eq!(names.first(), Some(&"queued"), "{text}");
    assert!(names.contains(&"running"), "{text}");
    assert_eq!(names.last(), Some(&"cancelled"), "{text}");
    assert!(text.contains("event: status"));
    app.cleanup().await;
}

/// A job runs only when the jobs it depends on have succeeded (the job graph
/// that correction jobs will use; built here by hand in the database).
#[tokio::test]
async fn dependent_jobs_wait_for_their_inputs() {
    let app = spawn_app(&[]).await;
    let r = app
        .upload(&app.key, &[("walk.bvh", bvh(30)), ("jump.bvh", bvh(20))])
        .await;
    let dataset: Value = r.json().await.unwrap();
    let aug: Value = app
        .augment_json(dataset["id"].as_str().unwrap(), &noise_recipe())
        .await;
    let jobs: Vec<Uuid> = sqlx::query_scalar("SELECT id FROM jobs ORDER BY seq")
        .fetch_all(&app.db)
        .await
        .unwrap();
    // The first job (walk) now waits for the second (jump).
    sqlx::query("INSERT INTO job_dependencies (job_id, depends_on) VALUES ($1, $2)")
        .bind(jobs[0])
        .bind(jobs[1])
        .execute(&app.db)
        .await
        .unwrap();
    let first = app.claim().await.unwrap();
    assert_eq!(first["id"], jobs[1].to_string());
    assert!(app.claim().await.is_none(), "the dependent job must wait");
    let epoch = first["epoch"].as_i64().unwrap();
    let body = json!({"epoch": epoch, "output": empty_output()});
    assert_eq!(
        app.report(&first, "complete", body).await,
        StatusCode::NO_CONTENT
    );
    let second = app
        .claim()
        .await
        .expect("runnable once its input succeeded");
    assert_eq!(second["id"], jobs[0].to_string());
    assert_eq!(
        app.status(aug["id"].as_str().unwrap()).await["jobs"]["running"],
        1
    );
    app.cleanup().await;
}

/// A recipe with every table becomes the graph of `pipeline::plan`: one
/// `synthesize` job per clip, VAE per class, interaction per pair, a correction
/// per original and per new (non-interaction) clip, debiasing; dependents wait
/// for their inputs, and when an input fails for good its dependents fail too.
#[tokio::test]
async fn full_recipes_become_the_job_graph() {
    let app = spawn_app(&[]).await;
    let files = [
        ("walk_1.bvh", bvh(40)),
        ("walk_2.bvh", bvh(30)),
        ("shake_A.bvh", bvh(20)),
        ("shake_B.bvh", bvh(20)),
    ];
    let r = app.upload(&app.key, &files).await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let dataset: Value = r.json().await.unwrap();
    let dataset = dataset["id"].as_str().unwrap();
    let recipe = json!({
        "seed": 5,
        "ops": [{"op": "noise", "copies": 2}],
        "vae": {"copies": 3, "iterations": 1},
        "interaction": {"copies": 2},
        "correct": {"time_budget_s": 1, "envs": 2},
        "debias": {"iterations": 1}
    });
    let r = app.augment(dataset, &recipe).await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let aug: Value = r.json().await.unwrap();
    let aug = aug["id"].as_str().unwrap();
    let status = app.status(aug).await;
    // 4 clips x 2 noise copies + 3 VAE samples of class `walk` (the `shake_*`
    // classes have one clip each, below `min_clips`) = 11 corrected clips.
    let expected = json!({
        "synthesize": 4, "vae": 1, "interaction": 1, "correct_original": 4,
        "correct": 11, "debias_train": 1, "debias_apply": 11
    });
    assert_eq!(status["kinds"], expected, "{status}");
    assert_eq!(status["jobs"]["total"], 33);
    let deps: Vec<String> = sqlx::query_scalar(
        "SELECT p.key FROM job_dependencies d JOIN jobs j ON j.id = d.job_id
         JOIN jobs p ON p.id = d.depends_on
         WHERE j.key = 'correct:walk_1__00_noise_001' ORDER BY p.key",
    )
    .fetch_all(&app.db)
    .await
    .unwrap();
    assert_eq!(deps, ["correct_original:walk_1", "synthesize:walk_1"]);
    let deps: i64 = sqlx::query_scalar(
        "SELECT count(*) FROM job_dependencies d JOIN jobs j ON j.id = d.job_id
         WHERE j.key = 'debias_train'",
    )
    .fetch_one(&app.db)
    .await
    .unwrap();
    assert_eq!(deps, 4);
    // Only jobs without inputs are claimable: the four syntheses first.
    for expected in ["walk_1", "walk_2", "shake_A", "shake_B"] {
        let job = app.claim().await.expect("a synthesize job");
        assert_eq!(job["input"]["clip_name"], expected);
        assert_eq!(job["deps"], json!([]));
        if expected == "walk_1" {
            let epoch = job["epoch"].as_i64().unwrap();
            let body = json!({"epoch": epoch, "error": "unreadable", "retryable": false});
            assert_eq!(app.report(&job, "fail", body).await, StatusCode::NO_CONTENT);
        }
    }
    let r = app
        .worker(reqwest::Method::POST, "/jobs/claim")
        .json(&json!({"worker_id": "w", "kinds": ["correct", "debias_apply"], "wait_ms": 0}))
        .send()
        .await
        .unwrap();
    assert_eq!(
        r.status(),
        StatusCode::NO_CONTENT,
        "corrections wait for synthesis"
    );
    let status = app.status(aug).await;
    // walk_1's two corrections and their two debias_apply jobs can never run.
    assert_eq!(status["jobs"]["failed"], 5, "{status}");
    let skipped: Vec<&Value> = status["errors"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["error"] == "not run: its input synthesize:walk_1 failed")
        .collect();
    assert_eq!(skipped.len(), 4, "{status}");
    assert!(
        skipped
            .iter()
            .any(|e| e["key"] == "debias_apply:walk_1__00_noise_000")
    );
    // Corrections of the originals need no other job: claimable at once, with
    // the source clip in their input.
    let original = {
        let r = app
            .worker(reqwest::Method::POST, "/jobs/claim")
            .json(&json!({"worker_id": "w", "kinds": ["correct_original"], "wait_ms": 0}))
            .send()
            .await
            .unwrap();
        r.json::<Value>().await.unwrap()
    };
    assert_eq!(original["input"]["job"]["key"], "correct_original:walk_1");
    assert_eq!(original["input"]["clips"][0]["clip_name"], "walk_1");
    app.cleanup().await;
}

#[tokio::test]
async fn bad_tables_and_pairs_are_refused_with_the_field() {
    let app = spawn_app(&[]).await;
    let (dataset, _) = upload_one(&app).await;
    let cases = [
        (
            json!({"ops": [{"op": "mirror"}], "correct": {"time_budget": 1}}),
            "[correct]",
            "time_budget",
        ),
        (json!({"vae": {"copies": 0}}), "[vae]", "copies"),
        (
            json!({"ops": [{"op": "mirror"}], "debias": {}}),
            "[debias]",
            "[correct]",
        ),
        (
            json!({"ops": [{"op": "mirror"}], "correct": {"accept_threshold": 2}}),
            "[correct]",
            "accept_threshold",
        ),
        (
            json!({"ops": [{"op": "mirror"}], "colour": 1}),
            "recipe",
            "colour",
        ),
    ];
    for (recipe, field, mentions) in cases {
        let (status, body) = problem(app.augment(&dataset, &recipe).await).await;
        assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{recipe}: {body}");
        assert_eq!(body["field"], field, "{recipe}: {body}");
        assert!(
            body["detail"].as_str().unwrap().contains(mentions),
            "{recipe}: {body}"
        );
    }
    // A VAE recipe on a dataset with no class of two clips makes nothing.
    let (status, body) = problem(app.augment(&dataset, &json!({"vae": {}})).await).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(body["detail"].as_str().unwrap().contains("makes nothing"));
    // The partners of a pair must match in length.
    let r = app
        .upload(&app.key, &[("hug_A.bvh", bvh(20)), ("hug_B.bvh", bvh(21))])
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        body["detail"].as_str().unwrap().contains("pair `hug`"),
        "{body}"
    );
    assert_eq!(body["file"], "hug_B.bvh");
    let jobs: i64 = sqlx::query_scalar("SELECT count(*) FROM jobs")
        .fetch_one(&app.db)
        .await
        .unwrap();
    assert_eq!(jobs, 0);
    app.cleanup().await;
}
