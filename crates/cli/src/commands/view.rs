//! `motionaug view PATH... [--port N] [--no-open]`: the viewer page for an
//! `augment` output folder, any folder of clips or single clips, served on
//! 127.0.0.1 (the `viewer` crate has the page and the clip data; this is the
//! HTTP around it).
//!
//! Routes: the page's files at `/`; `/api/info`, `/api/clips` (the library:
//! every clip with the URLs of its parts) and per clip `/api/clips/{id}/meta`
//! (JSON), `frames?start=S&count=N` (float32 positions), `flags` (one byte per
//! frame and point), `report` (its correction's report.json) and `file` (the
//! clip file itself). Prepared clips are kept in a small cache, so paging
//! through a long clip runs forward kinematics once.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use axum::Json;
use axum::Router;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde::Deserialize;
use viewer::ClipView;
use viewer::library::{Library, ScanOptions, Urls};

use crate::input::ClipArgs;

#[derive(clap::Args)]
pub struct Args {
    /// An augment output folder (with manifest.json), folders of BVH / AMC /
    /// NPZ clips, or clip files.
    #[arg(required = true, value_name = "PATH")]
    paths: Vec<PathBuf>,
    #[command(flatten)]
    clip: ClipArgs,
    /// Port on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 7878)]
    port: u16,
    /// Only print the URL; do not open a browser.
    #[arg(long)]
    no_open: bool,
}

/// Clips prepared for the page, most recent last.
const CACHED_CLIPS: usize = 8;

struct Served {
    library: Library,
    options: ScanOptions,
    cache: Mutex<VecDeque<(String, Arc<ClipView>)>>,
}

type Shared = Arc<Served>;

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        viewer::assets::bundled(),
        "this motionaug was built without its viewer page: {}",
        viewer::assets::MISSING_BECAUSE
    );
    let options = ScanOptions {
        skeleton: args.clip.skeleton.clone(),
        unit: args.clip.unit,
        amc_fps: args.clip.amc_fps,
    };
    let library = viewer::library::scan(&args.paths, &options)?;
    anyhow::ensure!(
        !library.clips.is_empty(),
        "no clips (.bvh, .amc, .npz) in {}",
        library.title
    );
    let clips = library.clips.iter().filter(|c| c.listed).count();
    let state = Arc::new(Served {
        library,
        options,
        cache: Mutex::new(VecDeque::new()),
    });
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    runtime.block_on(async move {
        let listener = match tokio::net::TcpListener::bind(("127.0.0.1", args.port)).await {
            Ok(l) => l,
            Err(e) if args.port != 0 => {
                eprintln!("port {} is taken ({e}); using a free one", args.port);
                tokio::net::TcpListener::bind(("127.0.0.1", 0)).await?
            }
            Err(e) => return Err(e).context("cannot listen on 127.0.0.1"),
        };
        let url = format!("http://{}/", listener.local_addr()?);
        println!("viewer: {url}  ({clips} clips; Ctrl-C stops it)");
        if !args.no_open {
            open_browser(&url);
        }
        axum::serve(listener, router(state))
            .with_graceful_shutdown(async {
                let _ = tokio::signal::ctrl_c().await;
            })
            .await
            .context("the viewer's server failed")
    })
}

/// Opens `url` in the desktop's browser; says so when it cannot.
fn open_browser(url: &str) {
    let opener = if cfg!(target_os = "macos") {
        "open"
    } else if cfg!(windows) {
        "explorer"
    } else {
        "xdg-open"
    };
    let spawned = std::process::Command::new(opener)
        .arg(url)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn();
    if let Err(e) = spawned {
        eprintln!("cannot open a browser ({opener}: {e}); open {url} yourself");
    }
}

fn router(state: Shared) -> Router {
    Router::new()
        .route("/", get(|| async { asset("index.html") }))
        .route("/api/info", get(info))
        .route("/api/clips", get(clips))
        .route("/api/clips/{id}/{part}", get(part))
        .route(
            "/{file}",
            get(|Path(file): Path<String>| async move { asset(&file) }),
        )
        .with_state(state)
}

fn asset(path: &str) -> Response {
    match viewer::assets::get(path) {
        Some(a) => ([(header::CONTENT_TYPE, a.mime)], a.bytes).into_response(),
        None => (StatusCode::NOT_FOUND, format!("no file {path}")).into_response(),
    }
}

async fn info(State(state): State<Shared>) -> Response {
    Json(serde_json::json!({"mode": "local", "title": state.library.title})).into_response()
}

async fn clips(State(state): State<Shared>) -> Response {
    let clips: Vec<_> = state
        .library
        .clips
        .iter()
        .map(|c| {
            let base = format!("api/clips/{}", c.id);
            c.describe(Urls {
                meta: format!("{base}/meta"),
                frames: format!("{base}/frames"),
                flags: format!("{base}/flags"),
                report: c.report.as_ref().map(|_| format!("{base}/report")),
                download: Some(format!("{base}/file")),
            })
        })
        .collect();
    Json(serde_json::json!({"title": state.library.title, "clips": clips})).into_response()
}

#[derive(Deserialize)]
struct Page {
    start: Option<usize>,
    count: Option<usize>,
}

fn problem(status: StatusCode, message: impl Into<String>) -> Response {
    (status, message.into()).into_response()
}

/// The prepared clip `id` (from the cache, else read and put there).
async fn prepared(state: &Shared, id: &str) -> Result<Arc<ClipView>, Response> {
    if let Some(hit) = state
        .cache
        .lock()
        .map_err(|_| problem(StatusCode::INTERNAL_SERVER_ERROR, "cache poisoned"))?
        .iter()
        .find(|(k, _)| k == id)
    {
        return Ok(hit.1.clone());
    }
    let clip = state
        .library
        .clips
        .iter()
        .find(|c| c.id == id)
        .cloned()
        .ok_or_else(|| problem(StatusCode::NOT_FOUND, format!("no clip {id}")))?;
    let options = state.options.clone();
    let view = tokio::task::spawn_blocking(move || clip.load(&options))
        .await
        .map_err(|e| problem(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
        .map_err(|e| problem(StatusCode::UNPROCESSABLE_ENTITY, e.to_string()))?;
    let view = Arc::new(view);
    if let Ok(mut cache) = state.cache.lock() {
        cache.retain(|(k, _)| k != id);
        cache.push_back((id.to_string(), view.clone()));
        while cache.len() > CACHED_CLIPS {
            cache.pop_front();
        }
    }
    Ok(view)
}

async fn part(
    State(state): State<Shared>,
    Path((id, part)): Path<(String, String)>,
    Query(page): Query<Page>,
) -> Response {
    let result = async {
        let Some(clip) = state.library.clips.iter().find(|c| c.id == id) else {
            return Err(problem(StatusCode::NOT_FOUND, format!("no clip {id}")));
        };
        match part.as_str() {
            "report" => {
                let path = clip
                    .report
                    .as_ref()
                    .ok_or_else(|| problem(StatusCode::NOT_FOUND, "no correction report"))?;
                let bytes = tokio::fs::read(path).await.map_err(|e| {
                    problem(StatusCode::NOT_FOUND, format!("{}: {e}", path.display()))
                })?;
                Ok(([(header::CONTENT_TYPE, "application/json")], bytes).into_response())
            }
            "file" => {
                let bytes = tokio::fs::read(&clip.path).await.map_err(|e| {
                    problem(
                        StatusCode::NOT_FOUND,
                        format!("{}: {e}", clip.path.display()),
                    )
                })?;
                let name = clip
                    .path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned());
                Ok((
                    [
                        (header::CONTENT_TYPE, "application/octet-stream".to_string()),
                        (
                            header::CONTENT_DISPOSITION,
                            format!("attachment; filename=\"{}\"", name.unwrap_or_default()),
                        ),
                    ],
                    bytes,
                )
                    .into_response())
            }
            "meta" => Ok(Json(prepared(&state, &id).await?.meta().clone()).into_response()),
            "flags" => Ok(binary(prepared(&state, &id).await?.flags().to_vec())),
            "frames" => {
                let view = prepared(&state, &id).await?;
                let start = page.start.unwrap_or(0);
                let count = page.count.unwrap_or(view.meta().frames);
                let bytes = view
                    .frames_bytes(start, count)
                    .map_err(|e| problem(StatusCode::BAD_REQUEST, e.to_string()))?;
                Ok(binary(bytes))
            }
            other => Err(problem(StatusCode::NOT_FOUND, format!("no part {other}"))),
        }
    }
    .await;
    result.unwrap_or_else(|r| r)
}

fn binary(bytes: Vec<u8>) -> Response {
    ([(header::CONTENT_TYPE, "application/octet-stream")], bytes).into_response()
}
