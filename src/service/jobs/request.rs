//! A training job's request: the training spec plus the sensor, whether to activate the table,
//! the shards and whether the table is written reproducibly, parsed and validated from JSON.

use serde_json::Value;

use crate::camera::{CameraError, SensorDesign};
use crate::service::ServiceError;

use crate::l3::learn::TrainingSpec;

/// The most shards a job may ask for (and at most one per batch, i.e. per training scene).
pub const MAX_SHARDS: usize = 64;

/// A parsed job request: the training spec plus the sensor, whether to activate, the shards
/// and whether the table is written reproducibly.
#[derive(Debug, Clone)]
pub struct JobRequest {
    pub spec: TrainingSpec,
    pub sensor: SensorDesign,
    pub activate: bool,
    /// Train in this many shards (shard jobs any replica claims); `None` trains in one piece.
    /// Any number gives the same table bytes.
    pub shards: Option<usize>,
    /// Zero the creation time and training duration in the table (as `l3 train
    /// --reproducible`), so that equal training gives equal table bytes (and id).
    pub reproducible: bool,
}

/// A boolean field of a job request (absent: false).
fn flag(map: &mut serde_json::Map<String, Value>, name: &str) -> Result<bool, ServiceError> {
    match map.remove(name) {
        None => Ok(false),
        Some(Value::Bool(b)) => Ok(b),
        Some(v) => Err(ServiceError::InvalidJson(format!(
            "{name} is {v}; true or false expected"
        ))),
    }
}

/// Parses and validates a job's JSON: the [`TrainingSpec`] fields, plus `sensor` (absent or
/// `"paper_default"`, a catalogue name, or a sensor design object), `activate` (bool), `shards` (1 to
/// [`MAX_SHARDS`], at most `scenes`) and `reproducible` (bool).
pub fn parse_job_request(body: &[u8]) -> Result<(JobRequest, Value), ServiceError> {
    let bad = |m: String| ServiceError::InvalidJson(m);
    let mut value: Value = serde_json::from_slice(body)
        .map_err(|e| bad(format!("the body is not valid JSON: {e}")))?;
    integral_floats_to_ints(&mut value);
    let Value::Object(mut map) = value.clone() else {
        return Err(bad(
            "the body must be a JSON object with the training spec".into()
        ));
    };
    let activate = flag(&mut map, "activate")?;
    let reproducible = flag(&mut map, "reproducible")?;
    let shards = match map.remove("shards") {
        None | Some(Value::Null) => None,
        Some(v) => Some(
            v.as_u64()
                .ok_or_else(|| bad(format!("shards is {v}; a whole number from 1 expected")))?,
        ),
    };
    let sensor = match map.remove("sensor") {
        None | Some(Value::Null) => SensorDesign::paper_default(),
        Some(Value::String(s)) if s == "paper_default" => SensorDesign::paper_default(),
        Some(Value::String(s)) => crate::camera::catalogue::find(&s)
            .ok_or_else(|| {
                ServiceError::BadRequest(format!(
                    "sensor '{s}': use \"paper_default\", a catalogue name (GET /v1/sensors) or a sensor design object"
                ))
            })?
            .design()
            .map_err(|e| ServiceError::Internal(format!("catalogue sensor '{s}': {e}")))?,
        Some(v) => SensorDesign::from_json(v).map_err(|e| match e {
            CameraError::Json(m) => bad(format!("sensor: {m}")),
            e => ServiceError::BadRequest(format!("sensor: {e}")),
        })?,
    };
    // a new table's defaults, not the stored records' (see `TrainingSpec::chroma_classes`)
    for (key, value) in crate::l3::learn::new_spec_defaults() {
        map.entry(key).or_insert(value);
    }
    // the error names the field (`scenes: invalid type: floating point 4.5, …`)
    let spec: TrainingSpec = serde_path_to_error::deserialize(Value::Object(map))
        .map_err(|e| bad(format!("training spec: {}: {}", e.path(), e.inner())))?;
    spec.validate()
        .map_err(|e| ServiceError::BadRequest(e.to_string()))?;
    let shards = shards
        .map(|n| {
            let max = spec.n_batches().min(MAX_SHARDS);
            usize::try_from(n)
                .ok()
                .filter(|n| (1..=max).contains(n))
                .ok_or_else(|| {
                    ServiceError::BadRequest(format!(
                        "shards {n}: 1 to {max} (at most one per training scene, of which the job has {}, and at most {MAX_SHARDS})",
                        spec.n_batches()
                    ))
                })
        })
        .transpose()?;
    Ok((
        JobRequest {
            spec,
            sensor,
            activate,
            shards,
            reproducible,
        },
        value,
    ))
}

/// Rewrites numbers like `4800.0` as the integer `4800`, everywhere in `v`. JSON Schema (and
/// many clients) treat them as integers; serde's integer fields would refuse them. Float
/// fields accept integers, so the rewrite changes no meaning.
pub(in crate::service) fn integral_floats_to_ints(v: &mut Value) {
    match v {
        Value::Number(n) if n.is_f64() => {
            if let Some(f) = n.as_f64()
                && f.fract() == 0.0
                && f.abs() < 9.0e15
            {
                *v = Value::from(f as i64);
            }
        }
        Value::Array(a) => a.iter_mut().for_each(integral_floats_to_ints),
        Value::Object(m) => m.values_mut().for_each(integral_floats_to_ints),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn job_request_parsing() {
        let (r, _) =
            parse_job_request(br#"{"illuminants":["D65"],"scenes":4,"activate":true}"#).unwrap();
        assert!(r.activate);
        assert_eq!(r.spec.scenes, 4);
        let (r, _) = parse_job_request(br#"{"scenes":48.0,"levels":1e1}"#).unwrap();
        assert_eq!((r.spec.scenes, r.spec.levels), (48, 10));
        assert_eq!((r.shards, r.reproducible), (None, false));
        let (r, _) =
            parse_job_request(br#"{"scenes":4,"shards":4.0,"reproducible":true}"#).unwrap();
        assert_eq!((r.shards, r.reproducible), (Some(4), true));
        for (body, needle) in [
            (&b"{"[..], "not valid JSON"),
            (b"[1]", "JSON object"),
            (br#"{"bogus":1}"#, "bogus"),
            (br#"{"levels":1}"#, "levels 1"),
            (br#"{"activate":"yes"}"#, "activate"),
            (br#"{"sensor":"nikon"}"#, "nikon"),
            (br#"{"scenes":4.5}"#, "scenes"),
            (br#"{"shards":0}"#, "shards 0: 1 to 48"),
            (br#"{"scenes":3,"shards":4}"#, "shards 4: 1 to 3"),
            (br#"{"scenes":100,"shards":65}"#, "at most 64"),
            (br#"{"shards":-1}"#, "shards"),
            (br#"{"shards":"2"}"#, "shards"),
            (br#"{"reproducible":1}"#, "reproducible"),
        ] {
            let e = parse_job_request(body).unwrap_err();
            assert!(e.to_string().contains(needle), "{e}");
            assert_eq!(e.status().as_u16(), 400);
        }
    }
}
