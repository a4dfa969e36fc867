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

/// Status polls at a fixed rate for `seconds`, open loop: request `i` is due
/// at `i / rate` whatever the earlier ones did, and its latency counts from
/// when it was due (so a server that falls behind shows it, instead of the
/// client slowing down with it). Returns (p50, p99, max) in ms and failures.
async fn fixed_rate(
    http: &reqwest::Client,
    url: &str,
    key: &str,
    rate: f64,
    seconds: f64,
) -> (f64, f64, f64, usize) {
    let n = (rate * seconds) as usize;
    let started = tokio::time::Instant::now();
    let mut tasks = tokio::task::JoinSet::new();
    for i in 0..n {
        let due = started + Duration::from_secs_f64(i as f64 / rate);
        tokio::time::sleep_until(due).await;
        let request = http.get(url).bearer_auth(key).send();
        tasks.spawn(async move {
            let ok = matches!(request.await, Ok(r) if r.status() == StatusCode::OK);
            (ok, due.elapsed())
        });
    }
    let mut latencies = Vec::with_capacity(n);
    let mut failed = 0;
    while let Some(r) = tasks.join_next().await {
        let (ok, latency) = r.unwrap();
        failed += usize::from(!ok);
        latencies.push(latency);
    }
    latencies.sort();
    (
        percentile(&latencies, 0.50),
        percentile(&latencies, 0.99),
        percentile(&latencies, 1.0),
        failed,
    )
}

/// Load benchmark of the status read (`GET /v1/augmentations/{id}`) against a
/// real coordinator process (the release binary, default settings): p50 / p99
/// at fixed rates of 200 and 1000 req/s (open loop, 10 s each after a 2 s
/// warm-up), then the most it serves with 64 requests in flight. The
/// augmentation is a noise x 3 + mirror recipe over 50 clips (with
/// `[correct]`: 250 jobs), so a read that aggregated its jobs would show.
/// Run by hand:
/// `cargo test --release -p motionaug-coordinator --test api -- --ignored status_polling --nocapture`
/// (STATUS_RATES="200,1000", STATUS_SECONDS=10 change it).
///
/// Side by side: with `STATUS_BASELINE=<another motionaug-coordinator
/// binary>` (e.g. one built from an earlier commit) both servers run, each
/// on its own database, and every measurement is taken from one then the
/// other, `STATUS_ROUNDS` times (default 3), so that the load others put on
/// the machine falls on both alike; the medians of the rounds are printed
/// with the ratio baseline / this build.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "load benchmark: run by hand"]
async fn status_polling_benchmark() {
    let rates: Vec<f64> = std::env::var("STATUS_RATES")
        .unwrap_or_else(|_| "200,1000".into())
        .split(',')
        .filter_map(|r| r.trim().parse().ok())
        .collect();
    let seconds: f64 = std::env::var("STATUS_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10.0);
    let baseline = std::env::var("STATUS_BASELINE").ok();
    let rounds: usize = match &baseline {
        Some(_) => std::env::var("STATUS_ROUNDS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(3),
        None => 1,
    };
    let http = reqwest::Client::builder()
        .pool_max_idle_per_host(256)
        .build()
        .unwrap();
    let env = [("MOTIONAUG_MAX_FILES", "100")];
    let mut servers = Vec::new();
    if let Some(binary) = &baseline {
        let server = RealCoordinator::start_binary(binary, &env).await;
        let url = polled_augmentation(&http, &server).await;
        servers.push(("baseline", server, url));
    }
    let server = RealCoordinator::start(&env).await;
    let url = polled_augmentation(&http, &server).await;
    servers.push(("this build", server, url));
    let status: Value = http
        .get(&servers[0].2)
        .bearer_auth(&servers[0].1.key)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let jobs = status["jobs"]["total"].as_i64().unwrap();
    for (_, server, url) in &servers {
        fixed_rate(&http, url, &server.key, 200.0, 2.0).await;
    }

    // (server, measurement) -> one figure per round.
    let mut figures: BTreeMap<(usize, String), Vec<[f64; 2]>> = BTreeMap::new();
    for round in 0..rounds {
        for &rate in &rates {
            for (s, (name, server, url)) in servers.iter().enumerate() {
                let cpu = server.cpu_seconds();
                let (p50, p99, max, failed) =
                    fixed_rate(&http, url, &server.key, rate, seconds).await;
                let after = server.cpu_seconds();
                // CPU per request (µs): the coordinator's and its Postgres backends'.
                let per_request = |a: f64, b: f64| (b - a) * 1e6 / (rate * seconds);
                let (own_us, pg_us) = (per_request(cpu.0, after.0), per_request(cpu.1, after.1));
                println!(
                    "[round {round}] {name}: status poll ({jobs} jobs), {rate:.0} req/s for \
                     {seconds:.0} s (open loop): p50 {p50:.2} ms, p99 {p99:.2} ms, max {max:.1} ms, \
                     {failed} failed; CPU per request: coordinator {own_us:.0} µs, \
                     Postgres {pg_us:.0} µs"
                );
                assert_eq!(failed, 0);
                figures
                    .entry((s, format!("{rate:>5.0} req/s p50 / p99 ms")))
                    .or_default()
                    .push([p50, p99]);
                figures
                    .entry((
                        s,
                        format!("{rate:>5.0} req/s CPU µs coordinator / Postgres"),
                    ))
                    .or_default()
                    .push([own_us, pg_us]);
            }
        }
        for (s, (name, server, url)) in servers.iter().enumerate() {
            let (throughput, p50, p99) = closed_loop(&http, url, &server.key, seconds).await;
            println!(
                "[round {round}] {name}: status poll ({jobs} jobs), 64 in flight for {seconds:.0} s \
                 (closed loop): {throughput:.0} req/s, p50 {p50:.2} ms, p99 {p99:.2} ms"
            );
            figures
                .entry((s, "   64 in flight req/s / p99 ms".to_string()))
                .or_default()
                .push([throughput, p99]);
        }
    }
    if servers.len() == 2 {
        let median = |v: &[[f64; 2]], i: usize| {
            let mut x: Vec<f64> = v.iter().map(|f| f[i]).collect();
            x.sort_by(f64::total_cmp);
            x[x.len() / 2]
        };
        println!("\nmedians of {rounds} rounds, baseline vs this build (ratio baseline / this):");
        for ((s, what), base) in figures.iter().filter(|((s, _), _)| *s == 0) {
            let ours = &figures[&(s + 1, what.clone())];
            let (b0, b1, o0, o1) = (
                median(base, 0),
                median(base, 1),
                median(ours, 0),
                median(ours, 1),
            );
            println!(
                "{what}: baseline {b0:.2} / {b1:.2}, this build {o0:.2} / {o1:.2} \
                 (ratios {:.2} / {:.2})",
                b0 / o0,
                b1 / o1
            );
        }
    }
    for (_, server, _) in servers {
        server.stop();
    }
}

/// Uploads 50 clips to `server` and starts an augmentation of 250 jobs on
/// them; returns the URL of its status.
async fn polled_augmentation(http: &reqwest::Client, server: &RealCoordinator) -> String {
    let clip = bvh(60);
    let mut form = Form::new();
    for i in 0..50 {
        form = form.part(
            "file",
            Part::bytes(clip.clone()).file_name(format!("c{i}.bvh")),
        );
    }
    let r = http
        .post(format!("{}/v1/datasets", server.base))
        .bearer_auth(&server.key)
        .multipart(form)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::CREATED);
    let dataset: Value = r.json().await.unwrap();
    let recipe = json!({"ops": [{"op": "noise", "copies": 3}, {"op": "mirror"}],
                        "correct": {"time_budget_s": 1, "warm_start": false}});
    let r = http
        .post(format!(
            "{}/v1/datasets/{}/augmentations",
            server.base,
            dataset["id"].as_str().unwrap()
        ))
        .bearer_auth(&server.key)
        .json(&recipe)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    let aug: Value = r.json().await.unwrap();
    format!(
        "{}/v1/augmentations/{}",
        server.base,
        aug["id"].as_str().unwrap()
    )
}

/// 64 requests in flight for `seconds`: (req/s, p50 ms, p99 ms).
async fn closed_loop(
    http: &reqwest::Client,
    url: &str,
    key: &str,
    seconds: f64,
) -> (f64, f64, f64) {
    let started = std::time::Instant::now();
    let deadline = started + Duration::from_secs_f64(seconds);
    let mut tasks = tokio::task::JoinSet::new();
    for _ in 0..64 {
        let (http, url, key) = (http.clone(), url.to_string(), key.to_string());
        tasks.spawn(async move {
            let mut latencies = Vec::new();
            while std::time::Instant::now() < deadline {
                let t = std::time::Instant::now();
                let r = http.get(&url).bearer_auth(&key).send().await.unwrap();
                assert_eq!(r.status(), StatusCode::OK);
                r.bytes().await.unwrap();
                latencies.push(t.elapsed());
            }
            latencies
        });
    }
    let mut latencies = Vec::new();
    while let Some(r) = tasks.join_next().await {
        latencies.extend(r.unwrap());
    }
    latencies.sort();
    (
        latencies.len() as f64 / started.elapsed().as_secs_f64(),
        percentile(&latencies, 0.50),
        percentile(&latencies, 0.99),
    )
}
