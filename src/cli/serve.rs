use std::path::PathBuf;

use clap::Args;

use super::{Cli, CliError};
use crate::service::{ConfigFlags, ServiceConfig, ServiceError, start_with};

#[derive(Args, Debug)]
pub struct ServeArgs {
    /// Configuration file (TOML) over config/default.toml; L3_* variables override both.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Address to listen on, over the config file's `bind` and `L3_BIND`.
    #[arg(long, value_name = "ADDR")]
    pub bind: Option<std::net::SocketAddr>,
    /// Data directory (database and tables), over the config file's `dir` and `L3_DATA_DIR`.
    #[arg(long, value_name = "DIR")]
    pub data_dir: Option<PathBuf>,
}

async fn shutdown_signal() {
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
        _ = ctrl_c => {}
        _ = term => {}
    }
    tracing::info!("shutting down: finishing in-flight requests");
}

pub fn run(cli: &Cli, a: &ServeArgs) -> Result<(), CliError> {
    let flags = ConfigFlags {
        bind: a.bind,
        data_dir: a.data_dir.clone(),
        iset_dir: cli.iset_dir.clone(),
    };
    let cfg =
        ServiceConfig::load_layers(a.config.as_deref(), &ServiceConfig::process_env(), &flags)
            .map_err(|e| CliError::Usage(e.to_string()))?;
    let filter = tracing_subscriber::EnvFilter::try_from_env("L3_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,sqlx=warn"));
    let builder = tracing_subscriber::fmt().with_env_filter(filter);
    if cfg.server.log_format == "json" {
        let _ = builder.json().try_init();
    } else {
        let _ = builder.try_init();
    }
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| ServiceError::Internal(format!("cannot start the async runtime: {e}")))?;
    // a start that fails (the address is taken, the database cannot be opened) is no usage
    // error: exit code 1 with the reason
    rt.block_on(async move {
        let server = start_with(cfg, shutdown_signal()).await?;
        Ok(server.wait().await?)
    })
}
