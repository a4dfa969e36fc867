//! End-to-end tests with real processes: a coordinator process, several
//! `motionaug-worker` processes, a private `redis-server` and a fresh Postgres
//! database per scenario.
//!
//! Each scenario breaks something in the middle of an augmentation (SIGKILL a
//! worker, SIGTERM a worker, SIGKILL and restart the coordinator, flush and stop
//! Redis) and then checks that every job completed exactly once and that the
//! results are byte-identical to what the synth crate produces in this process.
//!
//! The test binary has its own `main` (`harness = false`): started with
//! `MOTIONAUG_E2E_ROLE=coordinator` it *is* the coordinator (the same entry point
//! as the `motionaug-coordinator` binary), which gives the test a real coordinator
//! process without depending on another package's binary. Run one scenario with
//! `cargo test -p motionaug-worker --test e2e -- NAME`.

use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, ensure};
use reqwest::multipart::{Form, Part};
use serde_json::{Value, json};
use sqlx::{Connection, PgConnection, PgPool};
use uuid::Uuid;

const ADMIN_URL: &str = "postgres://postgres@127.0.0.1:5432/test";
const TOKEN: &str = "e2e-worker-token-0123456789";
const LEASE_MS: u64 = 1500;

fn main() {
    if std::env::var("MOTIONAUG_E2E_ROLE").as_deref() == Ok("coordinator") {
        if let Err(e) = motionaug_coordinator::cli::main() {
            eprintln!("coordinator: {e:#}");
            std::process::exit(1);
        }
        return;
    }
    let filter = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    type Scenario = fn() -> anyhow::Result<()>;
    let scenarios: Vec<(&str, Scenario)> = vec![
        ("worker_help_and_version", worker_help_and_version),
        (
            "worker_killed_mid_job",
            || block_on(worker_killed_mid_job()),
        ),
        ("worker_sigterm_hands_job_back", || {
            block_on(worker_sigterm_hands_job_back())
        }),
        ("coordinator_restart", || block_on(coordinator_restart())),
        ("redis_flushed_and_restarted", || {
            block_on(redis_flushed_and_restarted())
        }),
        ("two_coordinators", || block_on(two_coordinators())),
        ("correction_graph_on_two_workers", || {
            block_on(correction_graph_on_two_workers())
        }),
        ("worker_killed_mid_correction", || {
            block_on(worker_killed_mid_correction())
        }),
        ("live_curve_reaches_the_viewer", || {
            block_on(live_curve_reaches_the_viewer())
        }),
        ("class_tracker_on_two_workers", || {
            block_on(class_tracker_on_two_workers())
        }),
        ("variant_tracker_on_two_workers", || {
            block_on(variant_tracker_on_two_workers())
        }),
        ("npz_and_static_root_clips", || {
            block_on(npz_and_static_root_clips())
        }),
    ];
    let started = Instant::now();
    let (mut passed, mut failed, mut filtered) = (0, 0, 0);
    for (name, scenario) in scenarios {
        if filter.as_deref().is_some_and(|f| !name.contains(f)) {
            filtered += 1;
            continue;
        }
        let t = Instant::now();
        match scenario() {
            Ok(()) => {
                passed += 1;
                println!("test {name} ... ok ({:.1}s)", t.elapsed().as_secs_f64());
            }
            Err(e) => {
                failed += 1;
                println!("test {name} ... FAILED\n{e:#}");
            }
        }
    }
    println!(
        "\ntest result: {}. {passed} passed; {failed} failed; 0 ignored; 0 measured; {filtered} filtered out; finished in {:.2}s\n",
        if failed == 0 { "ok" } else { "FAILED" },
        started.elapsed().as_secs_f64()
    );
    if failed > 0 {
        std::process::exit(1);
    }
}

/// `motionaug-worker --help` and `--version` print and exit at once, even with
/// a coordinator configured (they never start a worker).
fn worker_help_and_version() -> anyhow::Result<()> {
    let binary = env!("CARGO_BIN_EXE_motionaug-worker");
    for (arg, expected) in [
        ("--help", "MOTIONAUG_COORDINATOR_URL"),
        ("-h", "Usage: motionaug-worker"),
        (
            "--version",
            concat!("motionaug-worker ", env!("CARGO_PKG_VERSION")),
        ),
        ("-V", "motionaug-worker "),
    ] {
        let mut child = Command::new(binary)
            .arg(arg)
            .env(
                "MOTIONAUG_COORDINATOR_URL",
                format!("http://127.0.0.1:{}", free_port()),
            )
            .env("MOTIONAUG_WORKER_TOKEN", TOKEN)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()?;
        let deadline = Instant::now() + Duration::from_secs(10);
        let status = loop {
            if let Some(status) = child.try_wait()? {
                break status;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                anyhow::bail!("`motionaug-worker {arg}` started a worker instead of exiting");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut stdout = String::new();
        if let Some(mut out) = child.stdout.take() {
            out.read_to_string(&mut stdout)?;
        }
        ensure!(status.success(), "{arg}: exit {status}");
        ensure!(stdout.contains(expected), "{arg}: {stdout}");
    }
    Ok(())
}

fn block_on(f: impl std::future::Future<Output = anyhow::Result<()>>) -> anyhow::Result<()> {
    tokio::runtime::Runtime::new()?.block_on(f)
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/data")
}

/// The clips every scenario uploads: two HDM05 AMC clips with their ASF and a CMU BVH.
const CLIPS: &[&str] = &[
    "HDM_bd_kickLFront1Reps_001_120.amc",
    "HDM_bd_jogLeftCircle4StepsRstart_001_120.amc",
    "16_11_walk_veer_left.bvh",
];

fn recipe() -> Value {
    json!({
        "seed": 11,
        "ops": [
            {"op": "noise", "copies": 3},
            {"op": "time_warp", "copies": 2},
            {"op": "mirror"},
            {"op": "mask", "mode": "lower_body"},
        ]
    })
}

/// Kills a child process with SIGKILL (the default of `Child::kill`) and reaps it.
fn kill(child: &mut Child) {
    let _ = child.kill();
    let _ = child.wait();
}

fn sigterm(child: &Child) -> anyhow::Result<()> {
    let status = Command::new("kill")
        .arg("-TERM")
        .arg(child.id().to_string())
        .status()?;
    ensure!(status.success(), "kill -TERM failed");
    Ok(())
}

/// One scenario's processes and database.
struct Cluster {
    dir: PathBuf,
    db_name: String,
    db: PgPool,
    port: u16,
    redis_port: u16,
    redis: Option<Child>,
    coordinator: Option<Child>,
    coordinator_starts: usize,
    /// Further coordinators (ports and processes) sharing the database and Redis.
    extra_coordinators: Vec<(u16, Child)>,
    workers: BTreeMap<String, Child>,
    http: reqwest::Client,
    key: String,
}

impl Cluster {
    async fn start() -> anyhow::Result<Cluster> {
        let db_name = format!("test_{}", Uuid::new_v4().simple());
        let mut admin = PgConnection::connect(ADMIN_URL)
            .await
            .context("postgres at 127.0.0.1:5432")?;
        sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {db_name}")))
            .execute(&mut admin)
            .await?;
        let dir = std::env::temp_dir().join(format!("motionaug-e2e-{db_name}"));
        std::fs::create_dir_all(&dir)?;
        let mut cluster = Cluster {
            db: PgPool::connect_lazy(&format!("postgres://postgres@127.0.0.1:5432/{db_name}"))?,
            db_name,
            dir,
            port: free_port(),
            redis_port: free_port(),
            redis: None,
            coordinator: None,
            coordinator_starts: 0,
            extra_coordinators: Vec::new(),
            workers: BTreeMap::new(),
            http: reqwest::Client::new(),
            key: String::new(),
        };
        cluster.start_redis().await?;
        cluster.start_coordinator().await?;
        cluster.key = cluster.create_key("e2e")?;
        Ok(cluster)
    }

    fn database_url(&self) -> String {
        format!("postgres://postgres@127.0.0.1:5432/{}", self.db_name)
    }

    fn log(&self, name: &str) -> anyhow::Result<Stdio> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.dir.join(format!("{name}.log")))?;
        Ok(Stdio::from(file))
    }

    /// A private Redis on its own port, so stopping it disturbs nobody else.
    async fn start_redis(&mut self) -> anyhow::Result<()> {
        let child = Command::new("redis-server")
            .args([
                "--bind",
                "127.0.0.1",
                "--port",
                &self.redis_port.to_string(),
            ])
            .args(["--save", "", "--appendonly", "no"])
            .stdout(self.log("redis")?)
            .stderr(Stdio::null())
            .spawn()
            .context("redis-server must be installed")?;
        self.redis = Some(child);
        let deadline = Instant::now() + Duration::from_secs(10);
        while std::net::TcpStream::connect(("127.0.0.1", self.redis_port)).is_err() {
            ensure!(Instant::now() < deadline, "redis-server did not start");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        Ok(())
    }

    fn stop_redis(&mut self) {
        if let Some(mut r) = self.redis.take() {
            kill(&mut r);
        }
    }

    fn coordinator_command(&self) -> anyhow::Result<Command> {
        let mut cmd = Command::new(std::env::current_exe()?);
        cmd.env("MOTIONAUG_E2E_ROLE", "coordinator")
            .env("DATABASE_URL", self.database_url())
            .env(
                "REDIS_URL",
                format!("redis://127.0.0.1:{}/0", self.redis_port),
            )
            .env("MOTIONAUG_LISTEN", format!("127.0.0.1:{}", self.port))
            .env("MOTIONAUG_WORKER_TOKEN", TOKEN)
            .env("MOTIONAUG_LEASE_MS", LEASE_MS.to_string())
            .env("MOTIONAUG_REAP_INTERVAL_MS", "100")
            .env("MOTIONAUG_POLL_INTERVAL_MS", "200")
            .env("MOTIONAUG_RETRY_BASE_MS", "50")
            .env("MOTIONAUG_DB_POOL_SIZE", "8")
            .env("RUST_LOG", "info");
        Ok(cmd)
    }

    async fn start_coordinator(&mut self) -> anyhow::Result<()> {
        self.coordinator_starts += 1;
        let name = format!("coordinator-{}", self.coordinator_starts);
        let child = self
            .coordinator_command()?
            .stdout(self.log(&name)?)
            .stderr(self.log(&name)?)
            .spawn()?;
        self.coordinator = Some(child);
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Ok(r) = self.http.get(self.url("/readyz")).send().await
                && r.status().is_success()
            {
                return Ok(());
            }
            ensure!(
                Instant::now() < deadline,
                "coordinator not ready; see {}",
                self.dir.display()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Starts another coordinator on its own port; returns the port.
    async fn start_extra_coordinator(&mut self) -> anyhow::Result<u16> {
        let port = free_port();
        let name = format!("coordinator-extra-{port}");
        let child = self
            .coordinator_command()?
            .env("MOTIONAUG_LISTEN", format!("127.0.0.1:{port}"))
            .stdout(self.log(&name)?)
            .stderr(self.log(&name)?)
            .spawn()?;
        self.extra_coordinators.push((port, child));
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Ok(r) = self
                .http
                .get(format!("http://127.0.0.1:{port}/readyz"))
                .send()
                .await
                && r.status().is_success()
            {
                return Ok(port);
            }
            ensure!(Instant::now() < deadline, "extra coordinator not ready");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    fn create_key(&self, tenant: &str) -> anyhow::Result<String> {
        let out = self
            .coordinator_command()?
            .args(["create-key", "--tenant", tenant])
            .output()?;
        ensure!(
            out.status.success(),
            "create-key failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let key = String::from_utf8(out.stdout)?.trim().to_string();
        ensure!(key.starts_with("mak_"), "unexpected key output {key:?}");
        Ok(key)
    }

    fn start_worker(&mut self, id: &str, delay_ms: u64) -> anyhow::Result<()> {
        self.start_worker_on(id, delay_ms, self.port)
    }

    fn start_worker_on(&mut self, id: &str, delay_ms: u64, port: u16) -> anyhow::Result<()> {
        let child = Command::new(env!("CARGO_BIN_EXE_motionaug-worker"))
            .env(
                "MOTIONAUG_COORDINATOR_URL",
                format!("http://127.0.0.1:{port}"),
            )
            .env("MOTIONAUG_WORKER_TOKEN", TOKEN)
            .env("MOTIONAUG_WORKER_ID", id)
            .env("MOTIONAUG_WORKER_TEST_DELAY_MS", delay_ms.to_string())
            .env("MOTIONAUG_WORKER_CHECKPOINT_EVERY_S", "1")
            .env(
                "MOTIONAUG_WORKER_WORK_DIR",
                self.dir.join(format!("work-{id}")),
            )
            .env("RUST_LOG", "info")
            .stdout(self.log(id)?)
            .stderr(self.log(id)?)
            .spawn()?;
        self.workers.insert(id.to_string(), child);
        Ok(())
    }

    fn url(&self, path: &str) -> String {
        format!("http://127.0.0.1:{}{path}", self.port)
    }

    async fn upload_and_augment(&self) -> anyhow::Result<String> {
        self.upload_and_augment_with(CLIPS, &recipe()).await
    }

    async fn upload_and_augment_with(
        &self,
        clips: &[&str],
        recipe: &Value,
    ) -> anyhow::Result<String> {
        let mut files = vec![(
            "HDM_bd.asf".to_string(),
            std::fs::read(examples().join("HDM_bd.asf"))?,
        )];
        for name in clips {
            files.push((name.to_string(), std::fs::read(examples().join(name))?));
        }
        self.upload_files_and_augment(&files, clips.len(), recipe)
            .await
    }

    /// Uploads `files` (name, bytes), which hold `clips` clips, and starts `recipe` on them.
    async fn upload_files_and_augment(
        &self,
        files: &[(String, Vec<u8>)],
        clips: usize,
        recipe: &Value,
    ) -> anyhow::Result<String> {
        let mut form = Form::new().text("name", "e2e");
        for (name, bytes) in files {
            form = form.part("file", Part::bytes(bytes.clone()).file_name(name.clone()));
        }
        let r = self
            .http
            .post(self.url("/v1/datasets"))
            .bearer_auth(&self.key)
            .multipart(form)
            .send()
            .await?;
        ensure!(
            r.status() == 201,
            "upload: {} {}",
            r.status(),
            r.text().await?
        );
        let dataset: Value = r.json().await?;
        ensure!(
            dataset["clips"].as_array().map(Vec::len) == Some(clips),
            "clips: {dataset}"
        );
        let r = self
            .http
            .post(self.url(&format!(
                "/v1/datasets/{}/augmentations",
                dataset["id"].as_str().unwrap()
            )))
            .bearer_auth(&self.key)
            .json(recipe)
            .send()
            .await?;
        ensure!(
            r.status() == 202,
            "augment: {} {}",
            r.status(),
            r.text().await?
        );
        let aug: Value = r.json().await?;
        Ok(aug["id"].as_str().context("augmentation id")?.to_string())
    }

    async fn status(&self, aug: &str) -> anyhow::Result<Value> {
        self.get_json(&format!("/v1/augmentations/{aug}")).await
    }

    /// An authenticated GET of the public API, as JSON.
    async fn get_json(&self, path: &str) -> anyhow::Result<Value> {
        let r = self
            .http
            .get(self.url(path))
            .bearer_auth(&self.key)
            .send()
            .await?;
        ensure!(r.status().is_success(), "{path}: {}", r.status());
        Ok(r.json().await?)
    }

    /// Waits until some job is running with at least one but less than half of its
    /// outputs stored (7 outputs of 2 files each per clip); returns (job id, worker id).
    async fn job_in_progress(&self) -> anyhow::Result<(Uuid, String)> {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            let row: Option<(Uuid, String)> = sqlx::query_as(
                "SELECT j.id, j.worker_id FROM jobs j
                 WHERE j.state = 'running' AND j.checkpoint IS NOT NULL
                   AND (SELECT count(*) FROM artifacts a WHERE a.job_id = j.id) BETWEEN 1 AND 6
                 ORDER BY j.seq LIMIT 1",
            )
            .fetch_optional(&self.db)
            .await?;
            if let Some(row) = row {
                return Ok(row);
            }
            ensure!(
                Instant::now() < deadline,
                "no job made progress; see {}",
                self.dir.display()
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    async fn wait_for(&self, aug: &str, wanted: &str, timeout: Duration) -> anyhow::Result<Value> {
        let deadline = Instant::now() + timeout;
        loop {
            // The coordinator may be restarting: ignore connection errors for a while.
            if let Ok(status) = self.status(aug).await {
                if status["status"] == wanted {
                    return Ok(status);
                }
                ensure!(
                    Instant::now() < deadline
                        && !["failed", "cancelled"]
                            .contains(&status["status"].as_str().unwrap_or("")),
                    "augmentation did not reach {wanted}: {status}; logs in {}",
                    self.dir.display()
                );
            } else {
                ensure!(
                    Instant::now() < deadline,
                    "coordinator unreachable; logs in {}",
                    self.dir.display()
                );
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    /// Every job succeeded exactly once, no stray files, and the downloaded
    /// results equal a local run of the synth crate, byte for byte.
    async fn verify(&self, aug: &str) -> anyhow::Result<()> {
        let status = self
            .wait_for(aug, "succeeded", Duration::from_secs(120))
            .await?;
        ensure!(status["jobs"]["succeeded"] == CLIPS.len(), "{status}");
        let jobs: Vec<(String, i32, i32)> =
            sqlx::query_as("SELECT state, completions, attempts FROM jobs")
                .fetch_all(&self.db)
                .await?;
        ensure!(jobs.len() == CLIPS.len(), "jobs: {jobs:?}");
        for (state, completions, _) in &jobs {
            ensure!(
                state == "succeeded" && *completions == 1,
                "a job did not complete exactly once: {jobs:?}"
            );
        }
        let r = self
            .http
            .get(self.url(&format!("/v1/augmentations/{aug}/results")))
            .bearer_auth(&self.key)
            .send()
            .await?;
        ensure!(r.status().is_success(), "results: {}", r.status());
        let bytes = r.bytes().await?.to_vec();
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))?;
        let mut got: HashMap<String, Vec<u8>> = HashMap::new();
        for i in 0..zip.len() {
            let mut f = zip.by_index(i)?;
            let mut content = Vec::new();
            f.read_to_end(&mut content)?;
            got.insert(f.name()?.to_string(), content);
        }
        let (expected, manifest) = expected_outputs()?;
        let stored: i64 = sqlx::query_scalar("SELECT count(*) FROM artifacts")
            .fetch_one(&self.db)
            .await?;
        ensure!(
            stored as usize == expected.len(),
            "{stored} stored files, expected {}",
            expected.len()
        );
        ensure!(
            got.len() == expected.len() + 1,
            "zip holds {} files, expected {}",
            got.len(),
            expected.len() + 1
        );
        for (name, content) in &expected {
            let actual = got
                .get(name)
                .with_context(|| format!("{name} missing from the results"))?;
            ensure!(actual == content, "{name} differs from a local run");
        }
        let got_manifest = String::from_utf8(got["manifest.json"].clone())?;
        ensure!(
            got_manifest == manifest,
            "manifest.json differs from a local run"
        );
        Ok(())
    }

    /// Stops every process and drops the database; keeps the logs when asked.
    async fn cleanup(mut self, keep_logs: bool) {
        for (_, mut w) in std::mem::take(&mut self.workers) {
            kill(&mut w);
        }
        if let Some(mut c) = self.coordinator.take() {
            kill(&mut c);
        }
        for (_, mut c) in std::mem::take(&mut self.extra_coordinators) {
            kill(&mut c);
        }
        self.stop_redis();
        self.db.close().await;
        if let Ok(mut admin) = PgConnection::connect(ADMIN_URL).await {
            let _ = sqlx::query(sqlx::AssertSqlSafe(format!(
                "DROP DATABASE IF EXISTS {} WITH (FORCE)",
                self.db_name
            )))
            .execute(&mut admin)
            .await;
        }
        if keep_logs {
            eprintln!("logs kept in {}", self.dir.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for w in self.workers.values_mut() {
            kill(w);
        }
        if let Some(c) = self.coordinator.as_mut() {
            kill(c);
        }
        for (_, c) in self.extra_coordinators.iter_mut() {
            kill(c);
        }
        if let Some(r) = self.redis.as_mut() {
            kill(r);
        }
    }
}

/// The example clips as `motionaug augment` reads them (named by file stem,
/// `source` = the file name, as the service records uploads).
fn local_clips(names: &[&str]) -> anyhow::Result<Vec<pipeline::Clip>> {
    let mut files = Vec::new();
    for name in names {
        files.push((name.to_string(), std::fs::read(examples().join(name))?));
    }
    local_clips_of(&files)
}

/// The clips of `files` (name, bytes; AMC clips use the example ASF).
fn local_clips_of(files: &[(String, Vec<u8>)]) -> anyhow::Result<Vec<pipeline::Clip>> {
    let asf = std::fs::read(examples().join("HDM_bd.asf"))?;
    let mut clips = Vec::new();
    for (name, bytes) in files {
        let (format, skeleton) = if name.ends_with(".amc") {
            (
                motionaug_protocol::ClipFormat::Amc,
                Some(("HDM_bd.asf", asf.as_slice())),
            )
        } else if name.ends_with(".npz") {
            (motionaug_protocol::ClipFormat::Npz, None)
        } else {
            (motionaug_protocol::ClipFormat::Bvh, None)
        };
        let motion = motionaug_protocol::clip::load(format, name, bytes, skeleton)?;
        clips.push(pipeline::Clip {
            name: name.rsplit_once('.').unwrap().0.to_string(),
            source: name.to_string(),
            motion,
        });
    }
    Ok(clips)
}

/// Runs `recipe` on `clips` in this process with `pipeline::run`, the code of
/// `motionaug augment`, writing into `out`. Returns the wall time.
fn local_run(recipe: &Value, clips: &[&str], out: &Path) -> anyhow::Result<Duration> {
    local_run_of(recipe, local_clips(clips)?, out)
}

/// [`local_run`] on clips already read.
fn local_run_of(
    recipe: &Value,
    clips: Vec<pipeline::Clip>,
    out: &Path,
) -> anyhow::Result<Duration> {
    let recipe =
        motionaug_protocol::recipe::parse(recipe).map_err(|e| anyhow::anyhow!(e.message))?;
    let started = Instant::now();
    let summary = pipeline::run(
        &recipe,
        &clips,
        &pipeline::Options {
            out: Some(out),
            work: &out.join("work"),
            seed: recipe.effective_seed(None),
            on_event: &|_| {},
        },
    )?;
    ensure!(
        summary.failures.is_empty(),
        "local run: {:?}",
        summary.failures
    );
    Ok(started.elapsed())
}

/// What an uninterrupted run produces: every output file by name, and manifest.json.
fn expected_outputs() -> anyhow::Result<(BTreeMap<String, Vec<u8>>, String)> {
    let out = std::env::temp_dir().join(format!("motionaug-e2e-local-{}", Uuid::new_v4()));
    std::fs::create_dir_all(&out)?;
    let result = (|| {
        local_run(&recipe(), CLIPS, &out)?;
        let mut files = BTreeMap::new();
        for entry in std::fs::read_dir(&out)? {
            let path = entry?.path();
            let name = path.file_name().unwrap().to_string_lossy().to_string();
            if path.is_file() && name != "manifest.json" {
                files.insert(name, std::fs::read(&path)?);
            }
        }
        let manifest = std::fs::read_to_string(out.join("manifest.json"))?;
        Ok((files, manifest))
    })();
    let _ = std::fs::remove_dir_all(&out);
    result
}

async fn with_cluster<F, Fut>(f: F) -> anyhow::Result<()>
where
    F: FnOnce(Cluster) -> Fut,
    Fut: std::future::Future<Output = (Cluster, anyhow::Result<()>)>,
{
    let cluster = Cluster::start().await?;
    let (cluster, result) = f(cluster).await;
    cluster.cleanup(result.is_err()).await;
    result
}

/// SIGKILL the worker of a job that has stored some outputs: the lease expires,
/// another worker resumes from the checkpoint, every job completes exactly once.
async fn worker_killed_mid_job() -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            for i in 0..3 {
                c.start_worker(&format!("w{i}"), 250)?;
            }
            let aug = c.upload_and_augment().await?;
            let (job, worker) = c.job_in_progress().await?;
            let mut child = c.workers.remove(&worker).context("worker process")?;
            kill(&mut child);
            c.verify(&aug).await?;
            let (attempts, epochs): (i32, i64) = sqlx::query_as(
                "SELECT j.attempts, (SELECT count(DISTINCT a.epoch) FROM artifacts a WHERE a.job_id = j.id)
                 FROM jobs j WHERE j.id = $1",
            )
            .bind(job)
            .fetch_one(&c.db)
            .await?;
            ensure!(attempts >= 2, "the killed job ran {attempts} time(s)");
            // Files stored by the killed attempt were kept: the next attempt resumed
            // from the checkpoint instead of starting over.
            ensure!(epochs >= 2, "outputs of only {epochs} attempt(s) stored");
            Ok(())
        }
        .await;
        (c, result)
    })
    .await
}

/// SIGTERM: the worker stops at its next checkpoint and releases the job without
/// using up an attempt; another worker finishes it.
async fn worker_sigterm_hands_job_back() -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            c.start_worker("first", 300)?;
            let aug = c.upload_and_augment().await?;
            let (job, worker) = c.job_in_progress().await?;
            let mut child = c.workers.remove(&worker).context("worker process")?;
            sigterm(&child)?;
            let deadline = Instant::now() + Duration::from_secs(20);
            loop {
                if let Some(status) = child.try_wait()? {
                    ensure!(status.success(), "worker exited with {status}");
                    break;
                }
                ensure!(Instant::now() < deadline, "worker ignored SIGTERM");
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            let (state, attempts, has_checkpoint): (String, i32, bool) = sqlx::query_as(
                "SELECT state, attempts, checkpoint IS NOT NULL FROM jobs WHERE id = $1",
            )
            .bind(job)
            .fetch_one(&c.db)
            .await?;
            ensure!(
                state == "queued" && attempts == 0 && has_checkpoint,
                "after SIGTERM: {state}, {attempts} attempts"
            );
            c.start_worker("second", 0)?;
            c.verify(&aug).await
        }
        .await;
        (c, result)
    })
    .await
}

/// SIGKILL the coordinator while jobs run and start a new one: workers retry
/// their reports, and nothing is lost or done twice.
async fn coordinator_restart() -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            for i in 0..2 {
                c.start_worker(&format!("w{i}"), 200)?;
            }
            let aug = c.upload_and_augment().await?;
            c.job_in_progress().await?;
            let mut old = c.coordinator.take().context("coordinator process")?;
            kill(&mut old);
            tokio::time::sleep(Duration::from_millis(500)).await;
            c.start_coordinator().await?;
            c.verify(&aug).await
        }
        .await;
        (c, result)
    })
    .await
}

/// Flush Redis, then stop it while jobs run and an SSE client follows the
/// augmentation; start it again later. Redis is only a hint channel, so work
/// goes on, the SSE stream falls back to polling, and the results are complete.
async fn redis_flushed_and_restarted() -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            for i in 0..2 {
                c.start_worker(&format!("w{i}"), 200)?;
            }
            let aug = c.upload_and_augment().await?;
            let events = c
                .http
                .get(c.url(&format!("/v1/augmentations/{aug}/events")))
                .bearer_auth(&c.key)
                .send()
                .await?;
            ensure!(events.status().is_success(), "events: {}", events.status());
            let follower = tokio::spawn(async move {
                let mut text = String::new();
                let mut events = events;
                while let Ok(Some(chunk)) = events.chunk().await {
                    text.push_str(&String::from_utf8_lossy(&chunk));
                }
                text
            });
            c.job_in_progress().await?;
            let out = Command::new("redis-cli")
                .args(["-p", &c.redis_port.to_string(), "FLUSHALL"])
                .output()?;
            ensure!(out.status.success(), "FLUSHALL failed");
            c.stop_redis();
            let before = c.status(&aug).await?["progress"].as_f64().unwrap_or(0.0);
            let deadline = Instant::now() + Duration::from_secs(30);
            loop {
                let status = c.status(&aug).await?;
                if status["progress"].as_f64().unwrap_or(0.0) > before
                    || status["status"] == "succeeded"
                {
                    break;
                }
                ensure!(
                    Instant::now() < deadline,
                    "no progress while Redis is down: {status}"
                );
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            let ready: Value = c.http.get(c.url("/readyz")).send().await?.json().await?;
            ensure!(ready["redis"] == "unreachable", "readyz: {ready}");
            c.start_redis().await?;
            c.verify(&aug).await?;
            let text = tokio::time::timeout(Duration::from_secs(20), follower).await??;
            let last = text
                .lines()
                .rev()
                .find_map(|l| l.strip_prefix("data: "))
                .context("no SSE data")?;
            let last: Value = serde_json::from_str(last)?;
            ensure!(last["status"] == "succeeded", "last SSE event: {last}");
            Ok(())
        }
        .await;
        (c, result)
    })
    .await
}

/// Two coordinators share the database and Redis: the augmentation is started on
/// one, its worker talks to the other (woken through Redis), and an SSE client on
/// the second sees it finish.
async fn two_coordinators() -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            let other = c.start_extra_coordinator().await?;
            c.start_worker_on("w-other", 0, other)?;
            // Let the worker's long poll start on the other coordinator.
            tokio::time::sleep(Duration::from_millis(300)).await;
            let aug = c.upload_and_augment().await?;
            let events = c
                .http
                .get(format!(
                    "http://127.0.0.1:{other}/v1/augmentations/{aug}/events"
                ))
                .bearer_auth(&c.key)
                .send()
                .await?;
            ensure!(events.status().is_success(), "events: {}", events.status());
            c.verify(&aug).await?;
            let text = tokio::time::timeout(Duration::from_secs(20), events.text()).await??;
            ensure!(
                text.contains("\"status\":\"succeeded\""),
                "SSE on the other coordinator: {text}"
            );
            let workers: Vec<String> = sqlx::query_scalar(
                "SELECT DISTINCT worker_id FROM jobs WHERE worker_id IS NOT NULL",
            )
            .fetch_all(&c.db)
            .await?;
            ensure!(workers == ["w-other"], "jobs ran on {workers:?}");
            Ok(())
        }
        .await;
        (c, result)
    })
    .await
}

/// The clip the correction scenarios augment (the shortest example clip).
const CORRECT_CLIPS: &[&str] = &["HDM_bd_kickLFront1Reps_001_120.amc"];

/// A tiny correction recipe: stop at the first accepted evaluation
/// (`target_r_norm = 0`, every acceptance limit relaxed: this tests the
/// plumbing, not the physics), keep every corrected clip.
fn correct_recipe() -> Value {
    json!({
        "seed": 3,
        "ops": [{"op": "mirror"}],
        "correct": {"time_budget_s": 1, "envs": 2, "target_r_norm": 0,
                    "accept_threshold": 0, "max_residual_force_ratio": 100,
                    "max_foot_skating_m_s": 100, "skating_at_most_input": false,
                    "min_sole_flat_fraction": 0, "keep_rejected": true},
        "debias": {"iterations": 20}
    })
}

/// Every file of a results zip by name.
async fn download(c: &Cluster, aug: &str) -> anyhow::Result<BTreeMap<String, Vec<u8>>> {
    let r = c
        .http
        .get(c.url(&format!("/v1/augmentations/{aug}/results")))
        .bearer_auth(&c.key)
        .send()
        .await?;
    let status = r.status();
    ensure!(
        status.is_success(),
        "results: {status}: {}",
        r.text().await?
    );
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(r.bytes().await?.to_vec()))?;
    let mut files = BTreeMap::new();
    for i in 0..zip.len() {
        let mut f = zip.by_index(i)?;
        let mut content = Vec::new();
        f.read_to_end(&mut content)?;
        files.insert(f.name()?.to_string(), content);
    }
    Ok(files)
}

/// A manifest with the measured numbers of each correction blanked: what a
/// correction measures depends on wall-clock time (its budget), so two runs
/// agree on everything else but not on these. Acceptance criteria keep their
/// names; their values, and the reasons for a rejection, are blanked.
fn manifest_structure(text: &[u8]) -> anyhow::Result<Value> {
    let mut v: Value = serde_json::from_slice(text)?;
    for entry in v.as_array_mut().context("manifest is a list")? {
        if let Some(c) = entry.get_mut("correction").and_then(Value::as_object_mut) {
            for (key, value) in c.iter_mut() {
                if value.is_number() || value.is_boolean() {
                    *value = json!(format!("<{key}>"));
                } else if key == "criteria" {
                    let names: Vec<Value> = value
                        .as_array()
                        .context("criteria is a list")?
                        .iter()
                        .map(|c| c["name"].clone())
                        .collect();
                    *value = json!(names);
                } else if key == "rejected_because" {
                    *value = json!("<rejected_because>");
                }
            }
        }
    }
    Ok(v)
}

/// Every job completed exactly once, and the counts per kind are `kinds`.
async fn check_jobs(c: &Cluster, kinds: &[(&str, i64)]) -> anyhow::Result<()> {
    let jobs: Vec<(String, String, i32)> =
        sqlx::query_as("SELECT key, state, completions FROM jobs ORDER BY seq")
            .fetch_all(&c.db)
            .await?;
    for (key, state, completions) in &jobs {
        ensure!(
            state == "succeeded" && *completions == 1,
            "{key}: {state}, {completions} completions"
        );
    }
    for (kind, n) in kinds {
        let count: i64 = sqlx::query_scalar("SELECT count(*) FROM jobs WHERE kind = $1")
            .bind(kind)
            .fetch_one(&c.db)
            .await?;
        ensure!(count == *n, "{count} {kind} jobs, expected {n}");
    }
    Ok(())
}

/// Synthesis, correction of the original and of the new clip (warm-started
/// from the original's policy), debias training and application on two real
/// workers; the results hold the same files and the same manifest (but for
/// the correction's measured numbers) as `pipeline::run` in this process.
async fn correction_graph_on_two_workers() -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            c.start_worker("w0", 0)?;
            c.start_worker("w1", 0)?;
            let started = Instant::now();
            let aug = c
                .upload_and_augment_with(CORRECT_CLIPS, &correct_recipe())
                .await?;
            c.wait_for(&aug, "succeeded", Duration::from_secs(300))
                .await?;
            let service_s = started.elapsed().as_secs_f64();
            check_jobs(
                &c,
                &[
                    ("synthesize", 1),
                    ("correct_original", 1),
                    ("correct", 1),
                    ("debias_train", 1),
                    ("debias_apply", 1),
                ],
            )
            .await?;
            let got = download(&c, &aug).await?;
            let out = c.dir.join("local");
            std::fs::create_dir_all(&out)?;
            let local_s = local_run(&correct_recipe(), CORRECT_CLIPS, &out)?.as_secs_f64();
            let clip = "HDM_bd_kickLFront1Reps_001_120__00_mirror_000";
            let expected: Vec<String> = [
                format!("{clip}.bvh"),
                format!("{clip}.npz"),
                format!("work/correct/{clip}/report.json"),
                "manifest.json".to_string(),
            ]
            .into_iter()
            .collect();
            let names: Vec<String> = got.keys().cloned().collect();
            let mut expected_sorted = expected.clone();
            expected_sorted.sort();
            ensure!(names == expected_sorted, "results hold {names:?}");
            for name in &expected {
                ensure!(out.join(name).is_file(), "the local run has no {name}");
            }
            let ours = manifest_structure(&got["manifest.json"])?;
            let local = manifest_structure(&std::fs::read(out.join("manifest.json"))?)?;
            ensure!(
                ours == local,
                "manifests differ:\nservice {ours:#}\nlocal {local:#}"
            );
            ensure!(ours[0]["debiased"] == true, "{ours}");
            // The report the manifest names is the correction's own.
            let report: Value =
                serde_json::from_slice(&got[&format!("work/correct/{clip}/report.json")])?;
            let manifest: Value = serde_json::from_slice(&got["manifest.json"])?;
            ensure!(
                report["r_norm"] == manifest[0]["correction"]["r_norm"],
                "report {report} vs manifest {manifest}"
            );
            // Warm start: the variant's correction started from the original's policy.
            ensure!(
                report["warm_start"].is_string(),
                "the variant was not warm-started: {report}"
            );
            println!(
                "  correction graph: service (2 workers) {service_s:.1} s, \
                 pipeline::run in one process {local_s:.1} s"
            );
            Ok(())
        }
        .await;
        (c, result)
    })
    .await
}

/// `policy = "class"`: one worker trains the class tracker, and the
/// correction (on whichever worker claims it) starts from the tracker it
/// fetched through the coordinator; the manifest is the in-process run's.
async fn class_tracker_on_two_workers() -> anyhow::Result<()> {
    tracker_on_two_workers(false).await
}

/// `variant_tracker_iterations`: the class tracker fails the new clip (the
/// acceptance asks for a mean reward of 1, which nothing reaches), so a
/// second tracker is trained on it and its correction starts from that one,
/// fetched through the coordinator; the manifest is the in-process run's.
async fn variant_tracker_on_two_workers() -> anyhow::Result<()> {
    tracker_on_two_workers(true).await
}

/// The class tracker scenarios, without or with a second tracker.
async fn tracker_on_two_workers(second: bool) -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            c.start_worker("w0", 0)?;
            c.start_worker("w1", 0)?;
            let mut recipe = correct_recipe();
            recipe["correct"]["policy"] = json!("class");
            recipe["correct"]["tracker_budget_s"] = json!(1);
            let mut jobs = vec![("synthesize", 1), ("tracker", 1), ("correct", 1)];
            if second {
                recipe["correct"]["variant_tracker_iterations"] = json!(1);
                recipe["correct"]["accept_threshold"] = json!(1.0);
                jobs.push(("variant_tracker", 1));
            }
            recipe.as_object_mut().map(|r| r.remove("debias"));
            let aug = c.upload_and_augment_with(CORRECT_CLIPS, &recipe).await?;
            c.wait_for(&aug, "succeeded", Duration::from_secs(300))
                .await?;
            check_jobs(&c, &jobs).await?;
            let got = download(&c, &aug).await?;
            let clip = "HDM_bd_kickLFront1Reps_001_120__00_mirror_000";
            let report: Value =
                serde_json::from_slice(&got[&format!("work/correct/{clip}/report.json")])?;
            let from = report["warm_start"].as_str().unwrap_or_default();
            let expected = if second { "variant_tracker" } else { "tracker" };
            ensure!(
                from.contains(expected),
                "the correction did not start from the {expected}: {report}"
            );
            ensure!(!second || report["accepted"] == false, "{report}");
            let out = c.dir.join(format!("local-{expected}"));
            std::fs::create_dir_all(&out)?;
            local_run(&recipe, CORRECT_CLIPS, &out)?;
            let ours = manifest_structure(&got["manifest.json"])?;
            let local = manifest_structure(&std::fs::read(out.join("manifest.json"))?)?;
            ensure!(
                ours == local,
                "manifests differ:\nservice {ours:#}\nlocal {local:#}"
            );
            Ok(())
        }
        .await;
        (c, result)
    })
    .await
}

/// SIGKILL the worker of a correction once it uploaded a checkpoint: the lease
/// expires and the other worker resumes the training from that checkpoint.
/// (A PPO iteration of 4096 samples takes several seconds here and checkpoints
/// are written between iterations, so the budget allows a few iterations.)
async fn worker_killed_mid_correction() -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            c.start_worker("w0", 0)?;
            c.start_worker("w1", 0)?;
            let recipe = json!({
                "seed": 4,
                "ops": [{"op": "mirror"}],
                "correct": {"time_budget_s": 25, "envs": 2, "target_r_norm": 1,
                            "accept_threshold": 0, "keep_rejected": true,
                            "warm_start": false}
            });
            let aug = c.upload_and_augment_with(CORRECT_CLIPS, &recipe).await?;
            let deadline = Instant::now() + Duration::from_secs(120);
            let (job, worker) = loop {
                let row: Option<(Uuid, String)> = sqlx::query_as(
                    "SELECT id, worker_id FROM jobs
                     WHERE kind = 'correct' AND state = 'running' AND checkpoint IS NOT NULL",
                )
                .fetch_optional(&c.db)
                .await?;
                if let Some(row) = row {
                    break row;
                }
                ensure!(
                    Instant::now() < deadline,
                    "no correction checkpoint; logs in {}",
                    c.dir.display()
                );
                tokio::time::sleep(Duration::from_millis(50)).await;
            };
            let mut child = c.workers.remove(&worker).context("worker process")?;
            kill(&mut child);
            c.wait_for(&aug, "succeeded", Duration::from_secs(300))
                .await?;
            check_jobs(&c, &[("synthesize", 1), ("correct", 1)]).await?;
            let (attempts, survivor): (i32, String) =
                sqlx::query_as("SELECT attempts, worker_id FROM jobs WHERE id = $1")
                    .bind(job)
                    .fetch_one(&c.db)
                    .await?;
            ensure!(attempts == 2, "the correction ran {attempts} time(s)");
            ensure!(survivor != worker, "finished by the killed worker");
            let log = std::fs::read_to_string(c.dir.join(format!("{survivor}.log")))?;
            ensure!(
                log.contains("resuming the correction from its checkpoint"),
                "the second attempt did not resume; logs in {}",
                c.dir.display()
            );
            let got = download(&c, &aug).await?;
            ensure!(got.len() == 4, "results: {:?}", got.keys());
            Ok(())
        }
        .await;
        (c, result)
    })
    .await
}

/// Clips motionaug wrote as NPZ (its float32 output and the lossless form)
/// and a BVH with a static root above the travelling Hips go through the
/// service as through the CLI: one worker reads them with the same reader
/// and the results equal a local run byte for byte.
async fn npz_and_static_root_clips() -> anyhow::Result<()> {
    let layered = std::fs::read(examples().join("static_root_walk.bvh"))?;
    let walk = motion::io::parse_bvh(&layered, "walk.bvh", motion::Unit::Auto)?;
    let files = vec![
        ("static_root_walk.bvh".to_string(), layered),
        (
            "walk_f32.npz".to_string(),
            motion::npz::motion_to_bytes(&walk, &[])?,
        ),
        (
            "walk_exact.npz".to_string(),
            pipeline::encode_clip(&walk, None)?,
        ),
    ];
    with_cluster(|mut c| async move {
        let result = async {
            c.start_worker("w0", 0)?;
            let aug = c.upload_files_and_augment(&files, 3, &recipe()).await?;
            c.wait_for(&aug, "succeeded", Duration::from_secs(120))
                .await?;
            check_jobs(&c, &[("synthesize", 3)]).await?;
            let got = download(&c, &aug).await?;
            let out = c.dir.join("local");
            std::fs::create_dir_all(&out)?;
            local_run_of(&recipe(), local_clips_of(&files)?, &out)?;
            let mut expected = 0;
            for entry in std::fs::read_dir(&out)? {
                let path = entry?.path();
                if !path.is_file() {
                    continue;
                }
                let name = path.file_name().unwrap().to_string_lossy().to_string();
                let ours = got.get(&name).with_context(|| format!("{name} missing"))?;
                ensure!(
                    *ours == std::fs::read(&path)?,
                    "{name} differs from a local run"
                );
                expected += 1;
            }
            ensure!(
                got.len() == expected,
                "{} files, expected {expected}",
                got.len()
            );
            // The static root is written back above the Hips in every output.
            let mirrored = &got["static_root_walk__02_mirror_000.bvh"];
            ensure!(mirrored.starts_with(b"HIERARCHY\nROOT joint_Root\n"));
            Ok(())
        }
        .await;
        (c, result)
    })
    .await
}

/// The learning curve a running correction reports reaches the viewer's
/// library endpoint while it trains (the worker uploads `curve.json` as
/// points come), and once it finishes the library serves the report's curve,
/// of which the live points are the start: the same rollouts, not a stand-in.
async fn live_curve_reaches_the_viewer() -> anyhow::Result<()> {
    with_cluster(|mut c| async move {
        let result = async {
            c.start_worker("w0", 0)?;
            // R_norm 1 is never reached: the correction trains its whole budget,
            // a point per PPO iteration (several seconds each on a loaded
            // machine: the budget leaves room for two or more).
            let recipe = json!({
                "seed": 5,
                "ops": [{"op": "mirror"}],
                "correct": {"time_budget_s": 20, "envs": 2, "target_r_norm": 1,
                            "accept_threshold": 0, "keep_rejected": true,
                            "warm_start": false}
            });
            let aug = c.upload_and_augment_with(CORRECT_CLIPS, &recipe).await?;
            let library = format!("/v1/augmentations/{aug}/library");
            let clip = "HDM_bd_kickLFront1Reps_001_120__00_mirror_000";
            let key = format!("correct:{clip}");
            // The longest curve seen while the job was still running.
            let mut live: Vec<[f64; 3]> = Vec::new();
            let deadline = Instant::now() + Duration::from_secs(180);
            loop {
                let lib = c.get_json(&library).await?;
                let job = lib["corrections"]
                    .as_array()
                    .and_then(|cs| cs.iter().find(|j| j["key"] == key.as_str()))
                    .cloned();
                let state = job.as_ref().map(|j| j["state"].clone());
                if let Some(job) = job.as_ref().filter(|_| state == Some(json!("running"))) {
                    let curve: Vec<[f64; 3]> = serde_json::from_value(job["curve"].clone())?;
                    // Once the report is stored (the job ends soon after) the
                    // library serves its curve, which starts at 0 samples.
                    let from_report = curve.first().is_some_and(|p| p[1] == 0.0);
                    if !from_report && curve.len() > live.len() {
                        live = curve;
                    }
                }
                if matches!(
                    state.as_ref().and_then(Value::as_str),
                    Some("succeeded" | "failed")
                ) {
                    break;
                }
                ensure!(
                    Instant::now() < deadline,
                    "the correction did not finish; logs in {}",
                    c.dir.display()
                );
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            ensure!(
                !live.is_empty(),
                "no curve point reached the viewer while the correction ran; logs in {}",
                c.dir.display()
            );
            c.wait_for(&aug, "succeeded", Duration::from_secs(60))
                .await?;
            // Finished: the library's curve is the report's, which starts with
            // the untrained policy's rollout at (0 s, 0 samples).
            let got = download(&c, &aug).await?;
            let report: Value =
                serde_json::from_slice(&got[&format!("work/correct/{clip}/report.json")])?;
            let reported: Vec<[f64; 3]> = serde_json::from_value(report["curve"].clone())?;
            let lib = c.get_json(&library).await?;
            let job = lib["corrections"]
                .as_array()
                .and_then(|cs| cs.iter().find(|j| j["key"] == key.as_str()))
                .context("the correction in the library")?;
            let served: Vec<[f64; 3]> = serde_json::from_value(job["curve"].clone())?;
            ensure!(
                served == reported,
                "library {served:?} vs report {reported:?}"
            );
            ensure!(
                reported.len() > live.len() && reported[0][..2] == [0.0, 0.0],
                "report {reported:?}, live {live:?}"
            );
            for (i, (l, r)) in live.iter().zip(&reported[1..]).enumerate() {
                let close = l
                    .iter()
                    .zip(r)
                    .all(|(a, b)| (a - b).abs() <= 1e-9 * b.abs().max(1.0));
                ensure!(close, "live point {i} {l:?} is not the report's {r:?}");
            }
            // Real figures: time and samples grow, R_norm is a fraction.
            for w in reported[1..].windows(2) {
                ensure!(w[1][0] > w[0][0] && w[1][1] > w[0][1], "curve {reported:?}");
            }
            for [wall_s, samples, r_norm] in &reported[1..] {
                ensure!(
                    *wall_s > 0.0 && *samples >= 1.0 && *r_norm > 0.0 && *r_norm <= 1.0,
                    "curve {reported:?}"
                );
            }
            println!(
                "  live curve: {} point(s) while running, {} in the report",
                live.len(),
                reported.len()
            );
            Ok(())
        }
        .await;
        (c, result)
    })
    .await
}
