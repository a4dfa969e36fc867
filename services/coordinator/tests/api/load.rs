//! A bounded loopback load test, run by hand.

use crate::helpers::*;

/// Latency percentile (nearest rank) in milliseconds.
fn percentile(sorted: &[Duration], p: f64) -> f64 {
    let rank = ((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1].as_secs_f64() * 1e3
}

/// Bounded loopback load test (run by hand; prints figures, asserts only that
/// every request succeeded):
/// `cargo test -p motionaug-coordinator --test api -- --ignored load_test --nocapture`.
/// LOAD_UPLOADS, LOAD_POLLS and LOAD_CONCURRENCY change the sizes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "load test: run by hand"]
async fn load_test() {
    let env_or = |k: &str, d: usize| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let uploads = env_or("LOAD_UPLOADS", 200);
    let polls = env_or("LOAD_POLLS", 2000);
    let concurrency = env_or("LOAD_CONCURRENCY", 16);
    let app = spawn_app(&[
        ("MOTIONAUG_MAX_FILES", "10"),
        ("MOTIONAUG_DB_POOL_SIZE", "20"),
    ])
    .await;
    let app = std::sync::Arc::new(app);
    let clip = bvh(120);

    let run = |n: usize, kind: &'static str, aug: Option<String>| {
        let app = app.clone();
        let clip = clip.clone();
        async move {
            let semaphore = std::sync::Arc::new(tokio::sync::Semaphore::new(concurrency));
            let started = std::time::Instant::now();
            let mut tasks = tokio::task::JoinSet::new();
            for i in 0..n {
                let permit = semaphore.clone().acquire_owned().await.unwrap();
                let app = app.clone();
                let clip = clip.clone();
                let aug = aug.clone();
                tasks.spawn(async move {
                    let t = std::time::Instant::now();
                    let ok = match &aug {
                        None => {
                            let name = format!("clip{i}.bvh");
                            app.upload(&app.key, &[(name.as_str(), clip)])
                                .await
                                .status()
                                == StatusCode::CREATED
                        }
                        Some(aug) => {
                            app.get(&format!("/v1/augmentations/{aug}"))
                                .send()
                                .await
                                .unwrap()
                                .status()
                                == StatusCode::OK
                        }
                    };
                    drop(permit);
                    (ok, t.elapsed())
                });
            }
            let mut latencies = Vec::with_capacity(n);
            while let Some(r) = tasks.join_next().await {
                let (ok, latency) = r.unwrap();
                assert!(ok, "a {kind} request failed");
                latencies.push(latency);
            }
            let wall = started.elapsed().as_secs_f64();
            latencies.sort();
            println!(
                "{kind}: {n} requests, concurrency {concurrency}: {:.0} req/s, p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
                n as f64 / wall,
                percentile(&latencies, 0.50),
                percentile(&latencies, 0.99),
                percentile(&latencies, 1.0)
            );
        }
    };
    run(uploads, "upload (1 BVH, 120 frames, 3 joints)", None).await;
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app.augment_json(&dataset, &noise_recipe()).await;
    run(
        polls,
        "status poll",
        Some(aug["id"].as_str().unwrap().to_string()),
    )
    .await;
    match std::sync::Arc::try_unwrap(app) {
        Ok(app) => app.cleanup().await,
        Err(_) => panic!("app still shared"),
    }
}
