//! The coordinator's `/viewer/` against the real app and database: a tenant's
//! dataset and a running augmentation whose progress the page follows while
//! the test, acting as the worker, reports it; then the augmentation's
//! outputs play; another tenant gets "not found" for all of it.

use std::collections::HashMap;
use std::time::Duration;

use motionaug_coordinator::configuration::Config;
use motionaug_coordinator::startup::Application;
use serde_json::{Value, json};
use sqlx::{Connection, PgConnection};

use crate::common::example;
use crate::pixels::{canvas_stats, save};
use crate::webdriver::Browser;

const ADMIN_URL: &str = "postgres://postgres@127.0.0.1:5432/test";
const WORKER_TOKEN: &str = "browser-test-worker-token-0123";

/// The app on a fresh database, dropped afterwards.
struct App {
    base: String,
    db_name: String,
    server: tokio::task::JoinHandle<anyhow::Result<()>>,
    alpha: String,
    beta: String,
    http: reqwest::Client,
}

impl App {
    async fn spawn() -> App {
        let db_name = format!("browser_{}", uuid::Uuid::new_v4().simple());
        let mut admin = PgConnection::connect(ADMIN_URL)
            .await
            .expect("postgres at 127.0.0.1:5432");
        sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {db_name}")))
            .execute(&mut admin)
            .await
            .unwrap();
        let url = format!("postgres://postgres@127.0.0.1:5432/{db_name}");
        let env: HashMap<&str, String> = [
            ("DATABASE_URL", url),
            ("REDIS_URL", "redis://127.0.0.1:6379/0".into()),
            ("MOTIONAUG_REDIS_PREFIX", db_name.clone()),
            ("MOTIONAUG_LISTEN", "127.0.0.1:0".into()),
            ("MOTIONAUG_WORKER_TOKEN", WORKER_TOKEN.into()),
            ("MOTIONAUG_POLL_INTERVAL_MS", "100".into()),
            ("MOTIONAUG_DB_POOL_SIZE", "5".into()),
        ]
        .into_iter()
        .collect();
        let config = Config::from_lookup(|k| env.get(k).cloned()).unwrap();
        let app = Application::build(config).await.unwrap();
        let base = format!("http://127.0.0.1:{}", app.port());
        let db = app.state().db.clone();
        let server = tokio::spawn(app.run_until_stopped(std::future::pending()));
        let alpha = motionaug_coordinator::auth::create_key(&db, "alpha")
            .await
            .unwrap();
        let beta = motionaug_coordinator::auth::create_key(&db, "beta")
            .await
            .unwrap();
        App {
            base,
            db_name,
            server,
            alpha,
            beta,
            http: reqwest::Client::new(),
        }
    }

    fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    async fn get(&self, key: &str, path: &str) -> reqwest::Response {
        self.http
            .get(self.url(path))
            .bearer_auth(key)
            .send()
            .await
            .unwrap()
    }

    async fn worker(&self, path: &str, body: Value) -> reqwest::Response {
        self.http
            .post(self.url(&format!("/internal/v1{path}")))
            .bearer_auth(WORKER_TOKEN)
            .json(&body)
            .send()
            .await
            .unwrap()
    }
}

impl Drop for App {
    fn drop(&mut self) {
        self.server.abort();
        let name = self.db_name.clone();
        let _ = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap();
            rt.block_on(async {
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
}

#[tokio::test(flavor = "multi_thread")]
async fn service_viewer_follows_an_augmentation_and_hides_it_from_other_tenants() {
    let _one = crate::serial().await;
    crate::bundled();
    let Some(browser) = Browser::start().await else {
        return;
    };
    let app = App::spawn().await;
    let walk = std::fs::read(example("16_11_walk_veer_left.bvh")).unwrap();
    let form = reqwest::multipart::Form::new().text("name", "walks").part(
        "file",
        reqwest::multipart::Part::bytes(walk.clone()).file_name("16_11_walk_veer_left.bvh"),
    );
    let dataset: Value = app
        .http
        .post(app.url("/v1/datasets"))
        .bearer_auth(&app.alpha)
        .multipart(form)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let dataset = dataset["id"].as_str().unwrap().to_string();
    let recipe = json!({"seed": 3, "ops": [{"op": "noise", "copies": 2}]});
    let aug: Value = app
        .http
        .post(app.url(&format!("/v1/datasets/{dataset}/augmentations")))
        .bearer_auth(&app.alpha)
        .json(&recipe)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let aug = aug["id"].as_str().unwrap().to_string();

    // The test is the worker: it claims the synthesis job and reports progress.
    let job: Value = app
        .worker(
            "/jobs/claim",
            json!({"worker_id": "browser-test", "kinds": ["synthesize"], "wait_ms": 0}),
        )
        .await
        .json()
        .await
        .unwrap();
    let (job_id, epoch) = (
        job["id"].as_str().unwrap().to_string(),
        job["epoch"].clone(),
    );
    let heartbeat = format!("/jobs/{job_id}/heartbeat");
    let beat =
        |progress: f64| app.worker(&heartbeat, json!({"epoch": epoch, "progress": progress}));
    assert!(beat(0.2).await.status().is_success());

    browser.goto(&app.url("/viewer")).await;
    browser
        .wait_for(
            "document.getElementById('login') && !document.getElementById('login').hidden",
            "the key form",
        )
        .await;
    browser
        .eval(
            "localStorage.setItem('motionaug.key', arguments[0]); return 0;",
            vec![json!(app.alpha)],
        )
        .await;
    browser
        .goto(&app.url(&format!("/viewer/?dataset={dataset}&augmentation={aug}")))
        .await;
    let item = format!("document.querySelector('li.augmentation[data-id=\"{aug}\"]')");
    let first = browser
        .wait_for(
            &format!(
                "{item} && Number({item}.dataset.progress) > 0 && Number({item}.dataset.progress)"
            ),
            "progress",
        )
        .await
        .as_f64()
        .unwrap();
    let listed = browser
        .eval(
            "return [...document.querySelectorAll('#dataset-list li')].map(li => li.dataset.id);",
            vec![],
        )
        .await;
    assert_eq!(listed, json!([dataset]));
    assert!(beat(0.7).await.status().is_success());
    let later = browser
        .wait_for(
            &format!(
                "Number({item}.dataset.progress) > {first} && Number({item}.dataset.progress)"
            ),
            "progress to advance",
        )
        .await
        .as_f64()
        .unwrap();
    assert!(later > first, "{first} -> {later}");
    save(&browser.screenshot().await, "viewer-service-progress");

    // The job's outputs, made by the pipeline as a worker would, then played.
    let motion =
        motion::io::parse_bvh(&walk, "16_11_walk_veer_left.bvh", motion::Unit::Auto).unwrap();
    let work = tempfile::tempdir().unwrap();
    let summary = pipeline::run(
        &pipeline::Recipe::from_value(recipe.clone()).unwrap(),
        &[pipeline::Clip {
            name: "16_11_walk_veer_left".into(),
            source: "16_11_walk_veer_left.bvh".into(),
            motion,
        }],
        &pipeline::Options {
            out: None,
            work: work.path(),
            seed: 3,
            on_event: &|_| {},
        },
    )
    .unwrap();
    let mut files = Vec::new();
    let mut manifest = Vec::new();
    for output in &summary.outputs {
        for (name, bytes) in
            pipeline::run::output_files(&output.name, &output.motion, output.mask.as_ref()).unwrap()
        {
            let r = app
                .http
                .put(app.url(&format!(
                    "/internal/v1/jobs/{job_id}/artifacts/{name}?epoch={epoch}"
                )))
                .bearer_auth(WORKER_TOKEN)
                .body(bytes)
                .send()
                .await
                .unwrap();
            assert!(r.status().is_success(), "{name}: {}", r.status());
            files.push(name);
        }
        manifest.push(serde_json::to_value(&output.entry).unwrap());
    }
    let done = app
        .worker(
            &format!("/jobs/{job_id}/complete"),
            json!({"epoch": epoch, "output": {"manifest": manifest, "files": files}}),
        )
        .await;
    assert!(done.status().is_success(), "{}", done.status());
    browser
        .wait_for(&format!("{item}.dataset.status === 'succeeded' && document.querySelectorAll('#clip-list li.clip').length === 3"), "the outputs")
        .await;
    browser
        .wait_for("document.querySelector('a.download')", "the download link")
        .await;
    let first_output = summary.outputs[0].name.clone();
    browser
        .eval(
            "document.querySelector(`li.clip[data-name='${arguments[0]}']`).click(); return 0;",
            vec![json!(first_output)],
        )
        .await;
    browser
        .wait_for(
            "window.__viewer.player.tracks.length === 2 && window.__viewer.player.tracks.every(t => t.loaded === t.frames && t.flags && t.shownFrame >= 0)",
            "the output to load",
        )
        .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let shot = browser.screenshot().await;
    let stats = canvas_stats(&browser, &shot).await;
    assert!(
        stats["saturated"].as_u64().unwrap() > 300,
        "no skeleton drawn: {stats}"
    );
    save(&shot, "viewer-service");
    let links = browser
        .eval(
            "return [...document.querySelectorAll('#panels a.file')].map(a => a.textContent);",
            vec![],
        )
        .await;
    assert_eq!(links, json!([first_output]), "the output can be downloaded");
    let errors = browser.console_errors().await;
    assert!(errors.is_empty(), "console errors: {errors:?}");

    // Another tenant: nothing of it exists.
    let file = format!("{first_output}.bvh");
    for path in [
        format!("/v1/augmentations/{aug}/library"),
        format!("/v1/augmentations/{aug}/results"),
        format!("/v1/augmentations/{aug}/files/{file}"),
        format!("/v1/augmentations/{aug}/view/meta/{file}"),
        format!("/v1/datasets/{dataset}/library"),
    ] {
        assert_eq!(app.get(&app.beta, &path).await.status(), 404, "{path}");
        assert_eq!(app.get(&app.alpha, &path).await.status(), 200, "{path}");
    }
    browser
        .eval(
            "localStorage.setItem('motionaug.key', arguments[0]); return 0;",
            vec![json!(app.beta)],
        )
        .await;
    browser
        .goto(&app.url(&format!("/viewer/?augmentation={aug}")))
        .await;
    browser
        .wait_for(
            "document.getElementById('status').textContent.includes('404')",
            "a 404",
        )
        .await;
    let clips = browser
        .eval(
            "return document.querySelectorAll('#clip-list li.clip').length;",
            vec![],
        )
        .await;
    assert_eq!(clips, json!(0));
    browser.close().await;
}
