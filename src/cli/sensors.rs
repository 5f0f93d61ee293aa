//! `l3 sensors`: the sensor catalogue, each sensor with whether a good table trained for it is
//! stored in the service's data directory (the listing `GET /v1/sensors` serves).

use std::path::PathBuf;

use clap::Args;

use super::CliError;
use crate::camera::catalogue;
use crate::service::{ServiceConfig, ServiceError};

#[derive(Args, Debug)]
pub struct SensorsArgs {
    /// The service's data directory whose stored tables mark sensors as trained (default: the
    /// service's, `L3_DATA_DIR` or ./data; its database: `L3_DATABASE_URL`, else the
    /// directory's l3.sqlite).
    #[arg(long, value_name = "DIR")]
    pub data_dir: Option<PathBuf>,
    /// Print JSON (the body of `GET /v1/sensors`) instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Print this sensor's design (a TOML file or a catalogue name) as the JSON design object
    /// `POST /v1/training-jobs` takes as its `sensor`, its CSV curves given inline as samples,
    /// instead of the catalogue.
    #[arg(long, value_name = "SENSOR", conflicts_with = "json")]
    pub design: Option<PathBuf>,
}

/// The service's configuration with `data_dir` over its data directory.
pub(crate) fn data_config(data_dir: &Option<PathBuf>) -> Result<ServiceConfig, CliError> {
    let flags = crate::service::ConfigFlags {
        data_dir: data_dir.clone(),
        ..Default::default()
    };
    ServiceConfig::load_layers(None, &ServiceConfig::process_env(), &flags)
        .map_err(|e| CliError::Usage(e.to_string()))
}

/// Runs `f` to completion on a single-threaded runtime.
pub(crate) fn block_on<T>(f: impl std::future::Future<Output = T>) -> Result<T, CliError> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| ServiceError::Internal(format!("cannot start the async runtime: {e}")))?;
    Ok(rt.block_on(f))
}

pub fn run(cli: &super::Cli, a: &SensorsArgs) -> Result<(), CliError> {
    if let Some(sensor) = &a.design {
        let iset = super::iset(&cli.iset_dir)?;
        let design = super::load_sensor(&Some(sensor.clone()), iset.as_ref())?;
        let design = design.inlined(iset.as_ref())?;
        let v = serde_json::to_value(&design)
            .map_err(|e| CliError::Usage(format!("cannot write the design as JSON: {e}")))?;
        println!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
        return Ok(());
    }
    let cfg = data_config(&a.data_dir)?;
    let stored = block_on(crate::service::stored_tables_in(&cfg))??;
    let items = catalogue::listing(|name| stored.newest_for(name));
    if a.json {
        let v = serde_json::json!({ "items": items });
        println!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
        return Ok(());
    }
    let width = items.iter().map(|s| s.name.len()).max().unwrap_or(4);
    println!("{:width$}  {:6}  {:9}  TRAINED", "NAME", "CFA", "SOURCE");
    for s in &items {
        let source = match s.source {
            catalogue::SensorSource::Shipped => "shipped",
            catalogue::SensorSource::Rawtoaces => "rawtoaces",
        };
        let trained = s.table_id.as_deref().unwrap_or("-");
        println!("{:width$}  {:6}  {:9}  {trained}", s.name, s.cfa, source);
    }
    let n = items.iter().filter(|s| s.trained).count();
    println!(
        "{} sensors, {n} with a table in {}",
        items.len(),
        cfg.data.dir.display()
    );
    Ok(())
}
