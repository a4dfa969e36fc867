//! Command line of `motionaug-coordinator`: `serve` (the default) and `create-key`.

use clap::{Parser, Subcommand};

use crate::configuration::Config;
use crate::startup::{Application, connect_and_migrate};
use crate::{auth, telemetry};

#[derive(Debug, Parser)]
#[command(
    name = "motionaug-coordinator",
    version,
    about = "motionaug coordinator: REST API and job queue"
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Serve the API (default). Configured by environment variables, see docs/SERVICE.md.
    Serve,
    /// Create an API key for a tenant (created if new) and print it. Needs DATABASE_URL.
    CreateKey {
        #[arg(long)]
        tenant: String,
    },
}

/// Resolves when the process gets SIGTERM or Ctrl-C.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
    tracing::info!("shutdown signal received");
}

/// Entry point of the binary (also used by the end-to-end tests).
pub fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let runtime = tokio::runtime::Runtime::new()?;
    runtime.block_on(async move {
        match cli.command.unwrap_or(Command::Serve) {
            Command::Serve => {
                telemetry::init("info");
                let config = Config::from_env()?;
                let app = Application::build(config).await?;
                app.run_until_stopped(shutdown_signal()).await
            }
            Command::CreateKey { tenant } => {
                let url = std::env::var("DATABASE_URL")
                    .map_err(|_| anyhow::anyhow!("DATABASE_URL is not set"))?;
                let db = connect_and_migrate(&url, 2).await?;
                let key = auth::create_key(&db, &tenant).await?;
                println!("{key}");
                Ok(())
            }
        }
    })
}
