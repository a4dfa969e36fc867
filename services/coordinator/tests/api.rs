//! API tests against the real application, a real Postgres (a fresh database per
//! test, dropped afterwards) and the machine's Redis.
//!
//! Jobs are driven through the internal worker API by the test itself, which lets
//! it check the lease rules precisely (stale epochs, duplicate completions,
//! cancellation, retries). Real worker processes are exercised by the worker
//! crate's end-to-end test.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::{Read, Write};
use std::time::Duration;

use motionaug_coordinator::configuration::Config;
use motionaug_coordinator::openapi::spec_path;
use motionaug_coordinator::startup;
use motionaug_coordinator::startup::{AppState, Application};
use motionaug_coordinator::state::JobState;
use reqwest::StatusCode;
use reqwest::multipart::{Form, Part};
use serde_json::{Value, json};
use sqlx::{Connection, PgConnection, PgPool};
use uuid::Uuid;

const ADMIN_URL: &str = "postgres://postgres@127.0.0.1:5432/test";
const WORKER_TOKEN: &str = "test-worker-token-0123456789";

struct TestApp {
    base: String,
    db: PgPool,
    /// The state the served router was built with.
    state: AppState,
    db_name: String,
    http: reqwest::Client,
    key: String,
    server: tokio::task::JoinHandle<anyhow::Result<()>>,
    cleaned: bool,
}

/// Drops the test database from a separate thread.
fn drop_database(name: &str) {
    let name = name.to_string();
    let _ = std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        runtime.block_on(async {
            if let Ok(mut admin) = PgConnection::connect(ADMIN_URL).await {
                let sql = format!("DROP DATABASE IF EXISTS {name} WITH (FORCE)");
                let _ = sqlx::query(sqlx::AssertSqlSafe(sql))
                    .execute(&mut admin)
                    .await;
            }
        });
    })
    .join();
}

/// A test that panics before `cleanup` still drops its database.
impl Drop for TestApp {
    fn drop(&mut self) {
        if !self.cleaned {
            self.server.abort();
            drop_database(&self.db_name);
        }
    }
}

async fn spawn_app(overrides: &[(&str, &str)]) -> TestApp {
    let db_name = format!("test_{}", Uuid::new_v4().simple());
    let mut admin = PgConnection::connect(ADMIN_URL)
        .await
        .expect("postgres at 127.0.0.1:5432");
    sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {db_name}")))
        .execute(&mut admin)
        .await
        .unwrap();
    let database_url = format!("postgres://postgres@127.0.0.1:5432/{db_name}");
    let mut env: HashMap<String, String> = [
        ("DATABASE_URL", database_url.as_str()),
        ("REDIS_URL", "redis://127.0.0.1:6379/0"),
        ("MOTIONAUG_REDIS_PREFIX", db_name.as_str()),
        ("MOTIONAUG_LISTEN", "127.0.0.1:0"),
        ("MOTIONAUG_WORKER_TOKEN", WORKER_TOKEN),
        ("MOTIONAUG_MAX_UPLOAD_BYTES", "1048576"),
        ("MOTIONAUG_MAX_FILES", "5"),
        ("MOTIONAUG_MAX_FRAMES", "500"),
        ("MOTIONAUG_LEASE_MS", "10000"),
        ("MOTIONAUG_RETRY_BASE_MS", "10"),
        ("MOTIONAUG_REAP_INTERVAL_MS", "50"),
        ("MOTIONAUG_POLL_INTERVAL_MS", "50"),
        ("MOTIONAUG_MAX_ATTEMPTS", "3"),
        ("MOTIONAUG_DB_POOL_SIZE", "5"),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v.to_string()))
    .collect();
    for (k, v) in overrides {
        env.insert(k.to_string(), v.to_string());
    }
    let config = Config::from_lookup(|k| env.get(k).cloned()).unwrap();
    let app = Application::build(config).await.unwrap();
    let port = app.port();
    let state = app.state().clone();
    let db = state.db.clone();
    let server = tokio::spawn(app.run_until_stopped(std::future::pending()));
    let key = motionaug_coordinator::auth::create_key(&db, "alpha")
        .await
        .unwrap();
    TestApp {
        base: format!("http://127.0.0.1:{port}"),
        db,
        state,
        db_name,
        http: reqwest::Client::new(),
        key,
        server,
        cleaned: false,
    }
}

impl TestApp {
    fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    fn get(&self, path: &str) -> reqwest::RequestBuilder {
        self.http.get(self.url(path)).bearer_auth(&self.key)
    }

    fn worker(&self, method: reqwest::Method, path: &str) -> reqwest::RequestBuilder {
        self.http
            .request(method, self.url(&format!("/internal/v1{path}")))
            .bearer_auth(WORKER_TOKEN)
    }

    async fn upload(&self, key: &str, files: &[(&str, Vec<u8>)]) -> reqwest::Response {
        let mut form = Form::new().text("name", "test set");
        for (name, bytes) in files {
            form = form.part(
                "file",
                Part::bytes(bytes.clone()).file_name(name.to_string()),
            );
        }
        self.http
            .post(self.url("/v1/datasets"))
            .bearer_auth(key)
            .multipart(form)
            .send()
            .await
            .unwrap()
    }

    async fn dataset_count(&self) -> i64 {
        sqlx::query_scalar("SELECT count(*) FROM datasets")
            .fetch_one(&self.db)
            .await
            .unwrap()
    }

    async fn augment(&self, dataset: &str, recipe: &Value) -> reqwest::Response {
        self.http
            .post(self.url(&format!("/v1/datasets/{dataset}/augmentations")))
            .bearer_auth(&self.key)
            .json(recipe)
            .send()
            .await
            .unwrap()
    }

    async fn claim(&self) -> Option<Value> {
        let r = self
            .worker(reqwest::Method::POST, "/jobs/claim")
            .json(&json!({"worker_id": "test-worker", "kinds": ["synthesize"], "wait_ms": 0}))
            .send()
            .await
            .unwrap();
        match r.status() {
            StatusCode::NO_CONTENT => None,
            StatusCode::OK => Some(r.json().await.unwrap()),
            s => panic!("claim answered {s}"),
        }
    }

    async fn report(&self, job: &Value, what: &str, body: Value) -> StatusCode {
        self.worker(
            reqwest::Method::POST,
            &format!("/jobs/{}/{what}", job["id"].as_str().unwrap()),
        )
        .json(&body)
        .send()
        .await
        .unwrap()
        .status()
    }

    async fn status(&self, aug: &str) -> Value {
        self.get(&format!("/v1/augmentations/{aug}"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap()
    }

    async fn cleanup(mut self) {
        self.server.abort();
        self.db.close().await;
        drop_database(&self.db_name);
        self.cleaned = true;
    }
}

/// A small valid BVH: a root with 6 channels, two 3-channel joints, an end site.
fn bvh(frames: usize) -> Vec<u8> {
    let mut s = String::from(
        "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n\
         JOINT Spine\n  {\n    OFFSET 0 10 0\n    CHANNELS 3 Zrotation Xrotation Yrotation\n\
         JOINT Head\n    {\n      OFFSET 0 10 0\n      CHANNELS 3 Zrotation Xrotation Yrotation\n\
         End Site\n      {\n        OFFSET 0 5 0\n      }\n    }\n  }\n}\nMOTION\n",
    );
    s.push_str(&format!("Frames: {frames}\nFrame Time: 0.033333\n"));
    for f in 0..frames {
        let a = f as f64;
        s.push_str(&format!(
            "{:.3} 90 0 {:.3} 0 0 {:.3} 0 0 0 {:.3} 0\n",
            a * 0.5,
            a.sin() * 5.0,
            a.cos() * 10.0,
            a * 0.1
        ));
    }
    s.into_bytes()
}

fn zip_of(files: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, bytes) in files {
        zip.start_file(*name, zip::write::SimpleFileOptions::default())
            .unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

/// A manifest entry as the synth crate writes it.
fn entry(file: &str, source: &str) -> Value {
    json!({"file": file, "source": source, "op": "noise", "op_index": 0, "copy": 0, "seed": 1,
           "params": {}, "frames": 40, "fps": 30.0})
}

fn empty_output() -> Value {
    json!({"manifest": [], "files": []})
}

fn noise_recipe() -> Value {
    json!({"seed": 3, "ops": [{"op": "noise", "copies": 2}]})
}

async fn problem(r: reqwest::Response) -> (StatusCode, Value) {
    let status = r.status();
    let ctype = r
        .headers()
        .get("content-type")
        .map(|v| v.to_str().unwrap().to_string())
        .unwrap_or_default();
    assert_eq!(ctype, "application/problem+json", "status {status}");
    (status, r.json().await.unwrap())
}

async fn upload_one(app: &TestApp) -> (String, Value) {
    let r = app.upload(&app.key, &[("walk.bvh", bvh(40))]).await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    (body["id"].as_str().unwrap().to_string(), body)
}

#[tokio::test]
async fn operational_endpoints_work_without_a_key() {
    let app = spawn_app(&[]).await;
    let r = app.http.get(app.url("/healthz")).send().await.unwrap();
    assert_eq!(r.status(), StatusCode::OK);
    let ready: Value = app
        .http
        .get(app.url("/readyz"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
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
    let openapi: Value = app
        .http
        .get(app.url("/openapi.json"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
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
async fn upload_list_show_delete() {
    let app = spawn_app(&[]).await;
    let r = app
        .upload(
            &app.key,
            &[
                ("walk.bvh", bvh(40)),
                ("set.zip", zip_of(&[("dir/jump.bvh", bvh(12))])),
            ],
        )
        .await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    let clips = body["clips"].as_array().unwrap();
    assert_eq!(clips.len(), 2);
    assert_eq!(clips[0]["name"], "walk");
    assert_eq!(clips[0]["frames"], 40);
    assert_eq!(clips[0]["joints"], 3);
    assert!((clips[0]["fps"].as_f64().unwrap() - 30.0).abs() < 0.01);
    assert_eq!(clips[1]["name"], "jump");
    assert_eq!(clips[1]["frames"], 12);
    let id = body["id"].as_str().unwrap();

    let list: Value = app
        .get("/v1/datasets")
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(list["datasets"].as_array().unwrap().len(), 1);
    assert_eq!(list["datasets"][0]["clip_count"], 2);
    let shown: Value = app
        .get(&format!("/v1/datasets/{id}"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(shown["clips"], body["clips"]);
    assert_eq!(shown["name"], "test set");

    let r = app
        .http
        .delete(app.url(&format!("/v1/datasets/{id}")))
        .bearer_auth(&app.key)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), StatusCode::NO_CONTENT);
    let r = app.get(&format!("/v1/datasets/{id}")).send().await.unwrap();
    assert_eq!(r.status(), StatusCode::NOT_FOUND);
    assert_eq!(app.dataset_count().await, 0);
    let clips: i64 = sqlx::query_scalar("SELECT count(*) FROM clips")
        .fetch_one(&app.db)
        .await
        .unwrap();
    assert_eq!(clips, 0);
    app.cleanup().await;
}

#[tokio::test]
async fn bad_files_reject_the_whole_upload_and_name_the_problem() {
    let app = spawn_app(&[]).await;
    // A broken frame line in the second file: nothing is stored.
    let mut broken = bvh(10);
    let text = String::from_utf8(broken.clone())
        .unwrap()
        .replace("Frame Time: 0.033333\n0.000", "Frame Time: 0.033333\nabc");
    broken = text.into_bytes();
    let r = app
        .upload(&app.key, &[("good.bvh", bvh(10)), ("bad.bvh", broken)])
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "bad.bvh");
    assert!(body["line"].as_u64().is_some(), "{body}");
    assert!(body["detail"].as_str().unwrap().contains("bad.bvh"));
    assert_eq!(app.dataset_count().await, 0);

    let r = app
        .upload(&app.key, &[("notes.txt", b"hello".to_vec())])
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(body["detail"].as_str().unwrap().contains("notes.txt"));

    let r = app
        .upload(&app.key, &[("a.bvh", bvh(5)), ("x/a.bvh", bvh(5))])
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert!(
        body["detail"].as_str().unwrap().contains("unique"),
        "{body}"
    );

    let r = app
        .upload(
            &app.key,
            &[(
                "motion.amc",
                b":FULLY-SPECIFIED\n1\nroot 0 0 0 0 0 0\n".to_vec(),
            )],
        )
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "motion.amc");

    let r = app
        .upload(&app.key, &[("junk.zip", b"PK not a zip".to_vec())])
        .await;
    assert_eq!(problem(r).await.0, StatusCode::UNPROCESSABLE_ENTITY);

    let r = app
        .http
        .post(app.url("/v1/datasets"))
        .bearer_auth(&app.key)
        .multipart(Form::new().text("name", "empty"))
        .send()
        .await
        .unwrap();
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["field"], "file");
    assert_eq!(app.dataset_count().await, 0);
    app.cleanup().await;
}

#[tokio::test]
async fn limits_on_body_size_file_count_and_frames() {
    let app = spawn_app(&[]).await;
    // Body limit is 1 MiB in these tests.
    let big = vec![b' '; 2 << 20];
    let r = app.upload(&app.key, &[("big.bvh", big)]).await;
    assert_eq!(problem(r).await.0, StatusCode::PAYLOAD_TOO_LARGE);
    // At most 5 files, zip entries included.
    let entries: Vec<(String, Vec<u8>)> = (0..6).map(|i| (format!("c{i}.bvh"), bvh(3))).collect();
    let refs: Vec<(&str, Vec<u8>)> = entries
        .iter()
        .map(|(n, b)| (n.as_str(), b.clone()))
        .collect();
    let r = app.upload(&app.key, &[("many.zip", zip_of(&refs))]).await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
    assert!(body["detail"].as_str().unwrap().contains("at most 5"));
    // At most 500 frames per clip.
    let r = app.upload(&app.key, &[("long.bvh", bvh(501))]).await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::PAYLOAD_TOO_LARGE);
    assert_eq!(body["file"], "long.bvh");
    // Recipes are JSON bodies with their own limit.
    let (dataset, _) = upload_one(&app).await;
    let huge = json!({"ops": [{"op": "noise", "pad": "x".repeat(5 << 20)}]});
    let r = app.augment(&dataset, &huge).await;
    assert_eq!(r.status(), StatusCode::PAYLOAD_TOO_LARGE);
    assert_eq!(app.dataset_count().await, 1);
    app.cleanup().await;
}

fn example(name: &str) -> Vec<u8> {
    std::fs::read(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/data")
            .join(name),
    )
    .unwrap()
}

#[tokio::test]
async fn amc_clips_pair_with_the_asf_of_their_upload() {
    let app = spawn_app(&[]).await;
    let asf = example("HDM_bd.asf");
    let kick = example("HDM_bd_kickLFront1Reps_001_120.amc");
    // Two skeletons: the AMC takes the one whose name prefixes its own.
    let r = app
        .upload(
            &app.key,
            &[
                ("HDM_xx.asf", asf.clone()),
                ("HDM_bd.asf", asf.clone()),
                ("HDM_bd_kickLFront1Reps_001_120.amc", kick.clone()),
            ],
        )
        .await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    assert_eq!(body["clips"].as_array().unwrap().len(), 1);
    assert_eq!(body["clips"][0]["name"], "HDM_bd_kickLFront1Reps_001_120");
    assert_eq!(body["clips"][0]["fps"], 120.0);
    assert_eq!(body["clips"][0]["joints"], 31);
    let skeleton: String = sqlx::query_scalar("SELECT skeleton_name FROM clips")
        .fetch_one(&app.db)
        .await
        .unwrap();
    assert_eq!(skeleton, "HDM_bd.asf");
    // Several skeletons and none fits: refused, naming the AMC.
    let r = app
        .upload(
            &app.key,
            &[
                ("a.asf", asf.clone()),
                ("b.asf", asf.clone()),
                ("kick.amc", kick.clone()),
            ],
        )
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "kick.amc");
    // A broken ASF is named with its line.
    let r = app
        .upload(
            &app.key,
            &[
                ("bad.asf", b":bonedata\n begin\n   id x\n".to_vec()),
                ("k.amc", kick),
            ],
        )
        .await;
    let (status, body) = problem(r).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY);
    assert_eq!(body["file"], "bad.asf");
    assert_eq!(app.dataset_count().await, 1);
    app.cleanup().await;
}

/// The upload limit, not the 4 MiB limit of JSON bodies, applies to uploads.
#[tokio::test]
async fn uploads_larger_than_json_bodies_are_accepted() {
    let app = spawn_app(&[
        ("MOTIONAUG_MAX_UPLOAD_BYTES", "16777216"),
        ("MOTIONAUG_MAX_FRAMES", "1000000"),
    ])
    .await;
    let big = bvh(150_000);
    assert!(big.len() > 5 << 20, "{} bytes", big.len());
    let r = app.upload(&app.key, &[("long.bvh", big)]).await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    assert_eq!(body["clips"][0]["frames"], 150_000);
    app.cleanup().await;
}

#[tokio::test]
async fn tenants_never_see_each_other() {
    let app = spawn_app(&[]).await;
    let other = motionaug_coordinator::auth::create_key(&app.db, "beta")
        .await
        .unwrap();
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app
        .augment(&dataset, &noise_recipe())
        .await
        .json()
        .await
        .unwrap();
    let aug = aug["id"].as_str().unwrap();
    let as_other =
        |m: reqwest::Method, p: String| app.http.request(m, app.url(&p)).bearer_auth(&other);
    let list: Value = as_other(reqwest::Method::GET, "/v1/datasets".into())
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(list["datasets"].as_array().unwrap().len(), 0);
    for (method, path) in [
        (reqwest::Method::GET, format!("/v1/datasets/{dataset}")),
        (reqwest::Method::DELETE, format!("/v1/datasets/{dataset}")),
        (
            reqwest::Method::GET,
            format!("/v1/datasets/{dataset}/augmentations"),
        ),
        (reqwest::Method::GET, format!("/v1/augmentations/{aug}")),
        (
            reqwest::Method::GET,
            format!("/v1/augmentations/{aug}/events"),
        ),
        (
            reqwest::Method::GET,
            format!("/v1/augmentations/{aug}/results"),
        ),
        (reqwest::Method::DELETE, format!("/v1/augmentations/{aug}")),
    ] {
        let r = as_other(method.clone(), path.clone()).send().await.unwrap();
        assert_eq!(r.status(), StatusCode::NOT_FOUND, "{method} {path}");
    }
    let r = as_other(
        reqwest::Method::POST,
        format!("/v1/datasets/{dataset}/augmentations"),
    )
    .json(&noise_recipe())
    .send()
    .await
    .unwrap();
    assert_eq!(r.status(), StatusCode::NOT_FOUND);
    // Still there and untouched for its owner.
    assert_eq!(app.status(aug).await["status"], "queued");
    assert_eq!(app.dataset_count().await, 1);
    app.cleanup().await;
}

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
async fn expired_leases_are_reclaimed_and_old_leases_cannot_report() {
    let app = spawn_app(&[("MOTIONAUG_LEASE_MS", "1000")]).await;
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app
        .augment(&dataset, &noise_recipe())
        .await
        .json()
        .await
        .unwrap();
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
    let aug: Value = app
        .augment(&dataset, &noise_recipe())
        .await
        .json()
        .await
        .unwrap();
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
    let aug2: Value = app
        .augment(&dataset, &noise_recipe())
        .await
        .json()
        .await
        .unwrap();
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

#[tokio::test]
async fn cancellation_reaches_running_jobs_and_events_stream() {
    let app = spawn_app(&[]).await;
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app
        .augment(&dataset, &noise_recipe())
        .await
        .json()
        .await
        .unwrap();
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

#[tokio::test]
async fn works_without_redis() {
    // Nothing listens on port 1: events stay in-process and listeners poll.
    let app = spawn_app(&[("REDIS_URL", "redis://127.0.0.1:1/0")]).await;
    let ready: Value = app
        .http
        .get(app.url("/readyz"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(ready["redis"], "unreachable");
    let (dataset, _) = upload_one(&app).await;
    let aug: Value = app
        .augment(&dataset, &noise_recipe())
        .await
        .json()
        .await
        .unwrap();
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
    let aug: Value = app
        .augment(&dataset, &noise_recipe())
        .await
        .json()
        .await
        .unwrap();
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
        .augment(dataset["id"].as_str().unwrap(), &noise_recipe())
        .await
        .json()
        .await
        .unwrap();
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

/// The methods a router may answer; HEAD and OPTIONS follow from these.
const METHODS: [reqwest::Method; 5] = [
    reqwest::Method::GET,
    reqwest::Method::POST,
    reqwest::Method::PUT,
    reqwest::Method::DELETE,
    reqwest::Method::PATCH,
];

/// The path of every route of `router`, read from its `Debug` text, where
/// axum's path router lists them as `RouteId(n): "/path"` (the fallback
/// router that follows is left out).
fn routed_paths(router: &impl std::fmt::Debug) -> BTreeSet<String> {
    let text = format!("{router:?}");
    let (paths, _fallback) = text
        .split_once(", fallback_router:")
        .expect("axum's Router lists its path router first");
    paths
        .split("RouteId(")
        .skip(1)
        .filter_map(|rest| {
            let (id, after) = rest.split_once(')')?;
            let quoted = after.strip_prefix(": \"")?;
            id.parse::<u32>().ok()?;
            Some(quoted.split('"').next()?.to_string())
        })
        .collect()
}

/// A concrete URL path that the route `path` matches.
fn concrete(path: &str) -> String {
    path.split('/')
        .map(|segment| match segment {
            "{id}" => "00000000-0000-0000-0000-000000000000",
            s if s.starts_with("{*") => "probe/file.bin",
            s if s.starts_with('{') => "probe",
            s => s,
        })
        .collect::<Vec<_>>()
        .join("/")
}

/// Every path the router serves, with every method it answers, is an operation
/// of the served OpenAPI document, and the document has no other operation.
/// Paths come from the router itself, methods from asking the running app
/// (without credentials: an answered method is anything but 405, and never the
/// router's "route not found").
#[tokio::test]
async fn every_route_and_method_is_in_the_openapi_document() {
    let app = spawn_app(&[]).await;
    let spec: Value = app
        .http
        .get(app.url("/openapi.json"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let documented: BTreeMap<String, BTreeSet<String>> = spec["paths"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(path, item)| {
            let methods = METHODS
                .iter()
                .map(|m| m.as_str().to_lowercase())
                .filter(|m| item.get(m).is_some())
                .collect();
            (path.clone(), methods)
        })
        .collect();

    let paths = routed_paths(&startup::router(app.state.clone()));
    assert!(
        paths.len() >= documented.len() && paths.contains("/internal/v1/jobs/{id}/inputs/{*name}"),
        "cannot read the routes from the router: {paths:?}"
    );
    let mut routed: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for path in &paths {
        let mut methods = BTreeSet::new();
        for method in METHODS {
            let url = app.url(&concrete(path));
            let r = app.http.request(method.clone(), url).send().await.unwrap();
            let status = r.status();
            if status == StatusCode::METHOD_NOT_ALLOWED {
                continue;
            }
            let body = r.text().await.unwrap();
            assert!(
                !(status == StatusCode::NOT_FOUND && body.contains("route not found")),
                "{method} {path}: the probe missed its route"
            );
            methods.insert(method.as_str().to_lowercase());
        }
        routed.insert(spec_path(path), methods);
    }
    assert_eq!(routed, documented);
    app.cleanup().await;
}

/// What the document says beyond its paths: every operation has a unique id,
/// the worker API needs the worker token, every client error is a problem, and
/// every reference resolves.
#[tokio::test]
async fn the_openapi_document_is_complete() {
    let app = spawn_app(&[]).await;
    let spec: Value = app
        .http
        .get(app.url("/openapi.json"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(spec["openapi"], "3.1.0");
    assert_eq!(spec["security"], serde_json::json!([{"apiKey": []}]));
    let schemes = &spec["components"]["securitySchemes"];
    for scheme in ["apiKey", "workerToken"] {
        assert_eq!(schemes[scheme]["scheme"], "bearer", "{scheme}");
    }
    let mut ids = BTreeSet::new();
    for (path, item) in spec["paths"].as_object().unwrap() {
        for (method, op) in item.as_object().unwrap() {
            let at = format!("{method} {path}");
            let id = op["operationId"]
                .as_str()
                .unwrap_or_else(|| panic!("{at}: no id"));
            assert!(ids.insert(id.to_string()), "{at}: operationId {id} twice");
            assert!(
                op["summary"].as_str().is_some_and(|s| !s.is_empty()),
                "{at}"
            );
            if path.starts_with("/internal/") {
                assert_eq!(
                    op["security"],
                    serde_json::json!([{"workerToken": []}]),
                    "{at}"
                );
                assert!(op["responses"].get("401").is_some(), "{at}");
            } else if path.starts_with("/v1/") {
                assert!(
                    op.get("security").is_none(),
                    "{at}: the API key is the default"
                );
                assert!(op["responses"].get("401").is_some(), "{at}");
            } else {
                assert_eq!(op["security"], serde_json::json!([]), "{at}");
            }
            for (status, response) in op["responses"].as_object().unwrap() {
                if status.starts_with('4') {
                    assert_eq!(
                        response["$ref"], "#/components/responses/Problem",
                        "{at}: {status}"
                    );
                }
            }
        }
    }
    // Every `$ref` names a component that exists.
    let text = spec.to_string();
    for reference in text.split("\"$ref\":\"").skip(1) {
        let reference = reference.split('"').next().unwrap();
        let pointer = reference.trim_start_matches('#');
        assert!(spec.pointer(pointer).is_some(), "{reference} is missing");
    }
    assert_eq!(
        spec["components"]["responses"]["Problem"]["content"]["application/problem+json"]["schema"]
            ["$ref"],
        "#/components/schemas/Problem"
    );
    app.cleanup().await;
}
