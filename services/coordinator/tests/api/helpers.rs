//! What every API test uses: the app spawned against a fresh database (dropped
//! afterwards, even when the test panics), requests with the tenant key or the
//! worker token, small clips, zips and recipes. The imports every module needs
//! are re-exported here, so a test module starts with `use crate::helpers::*;`.

pub use std::collections::{BTreeMap, BTreeSet, HashMap};
pub use std::io::{Read, Write};
pub use std::time::Duration;

pub use motionaug_coordinator::configuration::Config;
pub use motionaug_coordinator::openapi::spec_path;
pub use motionaug_coordinator::startup;
pub use motionaug_coordinator::startup::{AppState, Application};
pub use motionaug_coordinator::state::JobState;
pub use reqwest::StatusCode;
pub use reqwest::multipart::{Form, Part};
pub use serde_json::{Value, json};
pub use sqlx::{Connection, PgConnection, PgPool};
pub use uuid::Uuid;

pub const ADMIN_URL: &str = "postgres://postgres@127.0.0.1:5432/test";
pub const WORKER_TOKEN: &str = "test-worker-token-0123456789";

pub struct TestApp {
    base: String,
    pub db: PgPool,
    /// The state the served router was built with.
    pub state: AppState,
    db_name: String,
    pub http: reqwest::Client,
    pub key: String,
    server: tokio::task::JoinHandle<anyhow::Result<()>>,
    cleaned: bool,
}

/// Drops the test database from a separate thread.
pub fn drop_database(name: &str) {
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

/// A new empty database: its name and URL (drop it with [`drop_database`]).
pub async fn create_database() -> (String, String) {
    let db_name = format!("test_{}", Uuid::new_v4().simple());
    let mut admin = PgConnection::connect(ADMIN_URL)
        .await
        .expect("postgres at 127.0.0.1:5432");
    sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {db_name}")))
        .execute(&mut admin)
        .await
        .unwrap();
    let database_url = format!("postgres://postgres@127.0.0.1:5432/{db_name}");
    (db_name, database_url)
}

pub async fn spawn_app(overrides: &[(&str, &str)]) -> TestApp {
    let (db_name, database_url) = create_database().await;
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
    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    pub fn get(&self, path: &str) -> reqwest::RequestBuilder {
        self.http.get(self.url(path)).bearer_auth(&self.key)
    }

    pub fn worker(&self, method: reqwest::Method, path: &str) -> reqwest::RequestBuilder {
        self.http
            .request(method, self.url(&format!("/internal/v1{path}")))
            .bearer_auth(WORKER_TOKEN)
    }

    pub async fn upload(&self, key: &str, files: &[(&str, Vec<u8>)]) -> reqwest::Response {
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

    pub async fn dataset_count(&self) -> i64 {
        sqlx::query_scalar("SELECT count(*) FROM datasets")
            .fetch_one(&self.db)
            .await
            .unwrap()
    }

    pub async fn augment(&self, dataset: &str, recipe: &Value) -> reqwest::Response {
        self.http
            .post(self.url(&format!("/v1/datasets/{dataset}/augmentations")))
            .bearer_auth(&self.key)
            .json(recipe)
            .send()
            .await
            .unwrap()
    }

    /// `GET path` without credentials (operational endpoints), as JSON.
    pub async fn public_json(&self, path: &str) -> Value {
        self.http
            .get(self.url(path))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap()
    }

    /// `GET path` with the tenant's key, as JSON.
    pub async fn get_json(&self, path: &str) -> Value {
        self.get(path).send().await.unwrap().json().await.unwrap()
    }

    /// [`TestApp::augment`]'s answer as JSON.
    pub async fn augment_json(&self, dataset: &str, recipe: &Value) -> Value {
        self.augment(dataset, recipe).await.json().await.unwrap()
    }

    pub async fn claim(&self) -> Option<Value> {
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

    pub async fn report(&self, job: &Value, what: &str, body: Value) -> StatusCode {
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

    pub async fn status(&self, aug: &str) -> Value {
        self.get_json(&format!("/v1/augmentations/{aug}")).await
    }

    pub async fn cleanup(mut self) {
        self.server.abort();
        self.db.close().await;
        drop_database(&self.db_name);
        self.cleaned = true;
    }
}

/// A small valid BVH: a root with 6 channels, two 3-channel joints, an end site.
pub fn bvh(frames: usize) -> Vec<u8> {
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

pub fn zip_of(files: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, bytes) in files {
        zip.start_file(*name, zip::write::SimpleFileOptions::default())
            .unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

/// A manifest entry as the synth crate writes it.
pub fn entry(file: &str, source: &str) -> Value {
    json!({"file": file, "source": source, "op": "noise", "op_index": 0, "copy": 0, "seed": 1,
           "params": {}, "frames": 40, "fps": 30.0})
}

pub fn empty_output() -> Value {
    json!({"manifest": [], "files": []})
}

pub fn noise_recipe() -> Value {
    json!({"seed": 3, "ops": [{"op": "noise", "copies": 2}]})
}

pub async fn problem(r: reqwest::Response) -> (StatusCode, Value) {
    let status = r.status();
    let ctype = r
        .headers()
        .get("content-type")
        .map(|v| v.to_str().unwrap().to_string())
        .unwrap_or_default();
    assert_eq!(ctype, "application/problem+json", "status {status}");
    (status, r.json().await.unwrap())
}

pub async fn upload_one(app: &TestApp) -> (String, Value) {
    let r = app.upload(&app.key, &[("walk.bvh", bvh(40))]).await;
    assert_eq!(r.status(), StatusCode::CREATED);
    let body: Value = r.json().await.unwrap();
    (body["id"].as_str().unwrap().to_string(), body)
}

/// A real `motionaug-coordinator` process (the binary, not the library in this
/// process) on a fresh database and a free port, with a tenant key: for
/// measurements of the process itself (memory, latency under load).
pub struct RealCoordinator {
    child: std::process::Child,
    pub base: String,
    pub key: String,
    db_name: String,
}

impl RealCoordinator {
    /// Starts it with `env` on top of the required settings (the default
    /// limits otherwise) and waits until it answers.
    pub async fn start(env: &[(&str, &str)]) -> RealCoordinator {
        Self::start_binary(env!("CARGO_BIN_EXE_motionaug-coordinator"), env).await
    }

    /// [`RealCoordinator::start`] of another build of the coordinator (a
    /// benchmark's baseline).
    pub async fn start_binary(binary: &str, env: &[(&str, &str)]) -> RealCoordinator {
        let (db_name, database_url) = create_database().await;
        let key = std::process::Command::new(binary)
            .args(["create-key", "--tenant", "measured"])
            .env("DATABASE_URL", &database_url)
            .output()
            .unwrap();
        assert!(key.status.success(), "{key:?}");
        let key = String::from_utf8(key.stdout).unwrap().trim().to_string();
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let child = std::process::Command::new(binary)
            .env("DATABASE_URL", &database_url)
            .env("MOTIONAUG_LISTEN", format!("127.0.0.1:{port}"))
            .env("MOTIONAUG_WORKER_TOKEN", WORKER_TOKEN)
            .env("RUST_LOG", "warn")
            .envs(env.iter().copied())
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let server = RealCoordinator {
            child,
            base: format!("http://127.0.0.1:{port}"),
            key,
            db_name,
        };
        let http = reqwest::Client::new();
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        while http
            .get(format!("{}/healthz", server.base))
            .send()
            .await
            .is_err()
        {
            assert!(
                std::time::Instant::now() < deadline,
                "coordinator did not start"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        server
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// CPU seconds used so far by the process and by the Postgres backends of
    /// its database (Linux `/proc`; backends that exited are not counted).
    pub fn cpu_seconds(&self) -> (f64, f64) {
        let ticks = |pid: &str| -> f64 {
            let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
            let fields: Vec<&str> = stat
                .rsplit_once(')')
                .map_or(Vec::new(), |(_, rest)| rest.split_whitespace().collect());
            // utime and stime: fields 14 and 15 of stat(5), counted from the state (3).
            let at = |i: usize| {
                fields
                    .get(i)
                    .and_then(|v| v.parse::<f64>().ok())
                    .unwrap_or(0.0)
            };
            (at(11) + at(12)) / 100.0
        };
        let own = ticks(&self.pid().to_string());
        let mut postgres = 0.0;
        for entry in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
            let pid = entry.file_name().to_string_lossy().into_owned();
            if !pid.bytes().all(|b| b.is_ascii_digit()) {
                continue;
            }
            let title = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
            let title = String::from_utf8_lossy(&title);
            if title.starts_with("postgres: ") && title.contains(&format!(" {} ", self.db_name)) {
                postgres += ticks(&pid);
            }
        }
        (own, postgres)
    }

    /// Kills the process and drops its database.
    pub fn stop(self) {}
}

impl Drop for RealCoordinator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        drop_database(&self.db_name);
    }
}
