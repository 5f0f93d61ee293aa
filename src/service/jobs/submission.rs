//! What a client may ask of a training job over HTTP, checked when the job is submitted (a
//! refused job is never created): its lights are those of the service's registry or
//! `cct:K` (no files of the server), and a sensor design object reads no file of the server
//! and takes no catalogue sensor's name (the tables trained for a catalogue sensor are what
//! that camera's files render with).

use std::path::{Component, Path};

use serde_json::Value;

use super::request::{JobRequest, parse_job_request};
use crate::camera::{FilterSpec, SensorDesign};
use crate::service::ServiceError;
use crate::service::state::Inner;
use crate::spectral::WavelengthGrid;

/// Parses a submitted job's body ([`parse_job_request`]) after the checks above: registered
/// lights are replaced by the spectral spec they stand for, so the stored request trains
/// what the registry meant at submission.
pub fn parse_submission(state: &Inner, body: &[u8]) -> Result<(JobRequest, Value), ServiceError> {
    let mut value: Value = serde_json::from_slice(body)
        .map_err(|e| ServiceError::InvalidJson(format!("the body is not valid JSON: {e}")))?;
    if let Some(Value::Array(lights)) = value.get_mut("illuminants") {
        for light in lights.iter_mut() {
            if let Value::String(name) = light {
                *light = Value::String(crate::service::illuminants::spectral_spec(state, name)?);
            }
        }
    }
    let design_object = value.get("sensor").is_some_and(Value::is_object);
    let (req, value) = parse_job_request(value.to_string().as_bytes())?;
    if design_object {
        check_design(&req.sensor)?;
    }
    Ok((req, value))
}

/// A design object's curves resolve on the simulation grid (values in range, a response in
/// every channel, tables that exist), as the CLI checks a design when it loads it: a design
/// that can only fail is refused at submission, not queued. Resolving is CPU work (and may
/// read the spectral data), so it runs on the render pool.
pub async fn check_curves(state: &Inner, req: &JobRequest) -> Result<(), ServiceError> {
    let design = req.sensor.clone();
    let iset = state.iset.clone();
    crate::service::cpu::run(&state.pools.render, "the sensor's curves", move || {
        design
            .resolve_curves(&WavelengthGrid::default(), iset.as_ref())
            .map(|_| ())
            .map_err(|e| ServiceError::BadRequest(format!("sensor: {e}")))
    })
    .await?
}

/// A design object sent over HTTP: not named like a catalogue sensor unless it is that
/// sensor, and its curves are parametric or tables of the spectral data.
fn check_design(d: &SensorDesign) -> Result<(), ServiceError> {
    if let Some(entry) = crate::camera::catalogue::find(&d.name) {
        let as_json = |d: &SensorDesign| serde_json::to_value(d).ok();
        let same = match (entry.design().ok().as_ref().and_then(as_json), as_json(d)) {
            (Some(c), Some(d)) => crate::service::tables::same_design(&c, &d),
            _ => false,
        };
        if !same {
            return Err(ServiceError::BadRequest(format!(
                "sensor: the design object is named '{}', a catalogue sensor's name, but is not that sensor; give it another name, or send \"sensor\": \"{}\" to train the catalogue sensor",
                d.name, entry.name
            )));
        }
    }
    let curves = d
        .filters
        .iter()
        .map(|(n, f)| (format!("filter '{n}'"), f))
        .chain([("ir_cut".to_string(), &d.ir_cut), ("qe".to_string(), &d.qe)]);
    for (what, f) in curves {
        if let FilterSpec::Csv { path, .. } = f
            && !is_data_table(path)
        {
            return Err(ServiceError::BadRequest(format!(
                "sensor: {what}: csv \"{path}\" is not accepted over HTTP: a curve's csv must be a relative path of the spectral data (as the catalogue's designs use, e.g. GET /v1/sensors/{{name}}), without '..'; give other curves inline as samples (`l3 sensors --design FILE.toml` prints a design with its CSV curves inline), gaussian, constant or short_pass"
            )));
        }
    }
    Ok(())
}

/// Whether a curve's csv path names a table inside the spectral data (the operator's ISET
/// data directory, else the built-in copy): relative, with plain components only.
fn is_data_table(path: &str) -> bool {
    let p = Path::new(path);
    !path.trim().is_empty()
        && !path.contains('\\')
        && p.components().all(|c| matches!(c, Component::Normal(_)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_tables_are_relative_plain_paths() {
        assert!(is_data_table("cameras/rawtoaces/sony_ilce-9.csv"));
        assert!(is_data_table("sensor/colorfilters/auto/ar0132atRGBW.csv"));
        for bad in [
            "/tmp/secret.csv",
            "../secret.csv",
            "cameras/../../etc/passwd",
            "./x.csv",
            "a\\..\\b.csv",
            "",
        ] {
            assert!(!is_data_table(bad), "{bad}");
        }
    }
}
