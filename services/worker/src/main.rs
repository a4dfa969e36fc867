//! `motionaug-worker`: see the library crate. Configured by environment variables
//! (docs/SERVICE.md); logs JSON lines; stops gracefully on SIGTERM or Ctrl-C.

use clap::Parser;

/// The worker takes no arguments: everything is configured by environment
/// variables, so the same image runs anywhere. `--help` lists them.
#[derive(Debug, Parser)]
#[command(
    name = "motionaug-worker",
    version,
    about = "motionaug worker: claims jobs from a coordinator over HTTP and runs them",
    after_help = "Configured by environment variables (docs/SERVICE.md):\n  \
        MOTIONAUG_COORDINATOR_URL           coordinator URL, e.g. http://coordinator:8080 (required)\n  \
        MOTIONAUG_WORKER_TOKEN              the coordinator's worker token (required)\n  \
        MOTIONAUG_WORKER_ID                 name shown in jobs and logs (default: host-pid-random)\n  \
        MOTIONAUG_WORKER_CONCURRENCY        jobs run at once (default 1)\n  \
        MOTIONAUG_WORKER_SHUTDOWN_GRACE_MS  time to hand jobs back after SIGTERM (default 30000)\n  \
        MOTIONAUG_WORKER_CHECKPOINT_EVERY_S correction checkpoint interval (default 30)\n  \
        MOTIONAUG_WORKER_WORK_DIR           scratch space (default $TMPDIR/motionaug-worker)\n  \
        RUST_LOG                            log filter (default info)\n\n\
        Stops gracefully on SIGTERM or Ctrl-C."
)]
struct Cli {}

fn main() -> anyhow::Result<()> {
    nn::threads::init();
    Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .json()
        .with_current_span(true)
        .with_env_filter(filter)
        .init();
    let config = motionaug_worker::WorkerConfig::from_env()?;
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(motionaug_worker::run(config, shutdown_signal()))
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}
