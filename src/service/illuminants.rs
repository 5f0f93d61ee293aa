//! Illuminants: the registry of corrections T (built-ins plus the user's, persisted). A change
//! made through another replica is picked up by [`follow_stored`].

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path as UrlPath, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::ServiceError;
use super::state::{AppState, Inner, now_ms};
use super::store::IlluminantRow;
use crate::l3::correct::{CorrectionSource, IlluminantEntry, IlluminantRegistry, Mat3};
use crate::spectral::{IlluminantSpec, Samples};

/// A user illuminant's definition: exactly one of a matrix, an SPD or a CCT.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IlluminantDefinition {
    /// XYZ under the illuminant → XYZ under D65 (row-major 3×3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matrix: Option<Mat3>,
    /// A spectral power distribution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spd: Option<SpdSamples>,
    /// A correlated colour temperature, kelvin (blackbody below 4000 K, daylight above).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cct: Option<f64>,
}

/// SPD samples: wavelengths (nm, increasing) and relative power.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpdSamples {
    pub wavelengths_nm: Vec<f64>,
    pub values: Vec<f64>,
}

/// Applies a definition to a registry.
pub fn apply(
    reg: &mut IlluminantRegistry,
    name: &str,
    def: &IlluminantDefinition,
) -> Result<IlluminantEntry, ServiceError> {
    let bad = |e: String| ServiceError::BadRequest(format!("illuminant '{name}': {e}"));
    let given = usize::from(def.matrix.is_some())
        + usize::from(def.spd.is_some())
        + usize::from(def.cct.is_some());
    if given != 1 {
        return Err(bad(format!(
            "give exactly one of \"matrix\", \"spd\" or \"cct\" ({given} given)"
        )));
    }
    let r = if let Some(m) = def.matrix {
        reg.insert_matrix(name, m)
    } else if let Some(s) = &def.spd {
        if s.wavelengths_nm.len() != s.values.len() || s.values.len() < 2 {
            return Err(bad(format!(
                "spd has {} wavelengths and {} values; equal counts of at least 2 expected",
                s.wavelengths_nm.len(),
                s.values.len()
            )));
        }
        if s.values
            .iter()
            .chain(&s.wavelengths_nm)
            .any(|v| !v.is_finite())
        {
            return Err(bad("spd has non-finite numbers".into()));
        }
        // as many as a job or an evaluation takes of a light given by its samples
        let max = crate::spectral::MAX_INLINE_SPD_SAMPLES;
        if s.values.len() > max {
            return Err(bad(format!(
                "spd has {} samples; at most {max}",
                s.values.len()
            )));
        }
        let samples = Samples::new(s.wavelengths_nm.clone(), s.values.clone())
            .map_err(|e| bad(e.to_string()))?;
        reg.insert_spd(name, &samples, CorrectionSource::Spd)
    } else {
        let k = def.cct.unwrap_or(0.0);
        if !(k.is_finite() && (1000.0..=25_000.0).contains(&k)) {
            return Err(bad(format!("cct {k}: 1000 to 25000 K")));
        }
        reg.insert_cct(name, k)
    };
    r.cloned().map_err(|e| ServiceError::from_l3(e, bad))
}

/// The persisted user illuminants, in creation order.
pub async fn user_definitions(
    state: &Inner,
) -> Result<Vec<(String, IlluminantDefinition)>, ServiceError> {
    Ok(definitions(&state.store.illuminants().await?))
}

fn definitions(rows: &[IlluminantRow]) -> Vec<(String, IlluminantDefinition)> {
    let mut out = Vec::new();
    for r in rows {
        match serde_json::from_str(&r.definition_json) {
            Ok(d) => out.push((r.name.clone(), d)),
            Err(e) => tracing::warn!("stored illuminant {} is unreadable: {e}", r.name),
        }
    }
    out
}

/// The registry from the stored rows: built-ins, then the user's definitions. Fitting T from
/// an SPD is CPU work: it runs on the render pool, as a PUT's fit does.
async fn build_registry(
    state: &Inner,
    rows: &[IlluminantRow],
) -> Result<IlluminantRegistry, ServiceError> {
    let mut reg = state.default_registry.clone();
    let defs = definitions(rows);
    super::cpu::run(&state.pools.render, "the illuminant registry", move || {
        for (name, def) in defs {
            if let Err(e) = apply(&mut reg, &name, &def) {
                tracing::warn!("stored illuminant {name} skipped: {e}");
            }
        }
        reg
    })
    .await
}

/// Rebuilds the registry from the database and installs it (the caller holds
/// `registry_writes`).
async fn reload(state: &Inner, rows: Vec<IlluminantRow>) -> Result<(), ServiceError> {
    let reg = build_registry(state, &rows).await?;
    // the rows first: what a light names for training ([`spectral_spec`]) is read from them
    // once the registry has it
    let old = std::mem::replace(
        &mut *state
            .illuminant_rows
            .lock()
            .unwrap_or_else(|p| p.into_inner()),
        rows.clone(),
    );
    *state.registry() = reg;
    // kernels fused with an illuminant that changed or went are stale
    for r in old.iter().filter(|o| !rows.contains(o)) {
        state.forget_illuminant(&r.name);
    }
    Ok(())
}

/// Loads the registry from the database (at start).
pub async fn load_registry(state: &Inner) -> Result<(), ServiceError> {
    let _writing = state.registry_writes.lock().await;
    let rows = state.store.illuminants().await?;
    reload(state, rows).await
}

/// Follows illuminant changes made through other replicas: rebuilds the registry when the
/// stored definitions differ from those it was built from.
pub async fn follow_stored(state: &Inner) -> Result<(), ServiceError> {
    let rows = state.store.illuminants().await?;
    if *state
        .illuminant_rows
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        == rows
    {
        return Ok(());
    }
    let _writing = state.registry_writes.lock().await;
    // re-read under the lock: a change made here meanwhile is already installed
    let rows = state.store.illuminants().await?;
    reload(state, rows).await?;
    tracing::info!("illuminant registry reloaded (changed through another replica)");
    Ok(())
}

fn entry_json(e: &IlluminantEntry, user: bool) -> Value {
    json!({
        "name": e.name,
        "matrix": e.t,
        "white_xy": e.white_xy,
        "cct": e.cct,
        "source": e.source,
        "user_defined": user,
        "deletable": user,
    })
}

async fn user_names(state: &Inner) -> Result<Vec<String>, ServiceError> {
    Ok(user_definitions(state)
        .await?
        .into_iter()
        .map(|(n, _)| n.to_ascii_lowercase())
        .collect())
}

/// `GET /v1/illuminants`
pub async fn list(State(state): State<AppState>) -> Result<Json<Value>, ServiceError> {
    let users = user_names(&state).await?;
    let items: Vec<Value> = state
        .registry()
        .entries()
        .map(|e| entry_json(e, users.contains(&e.name.to_ascii_lowercase())))
        .collect();
    Ok(Json(json!({ "items": items })))
}

/// `GET /v1/illuminants/{name}`
pub async fn get(
    State(state): State<AppState>,
    UrlPath(name): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    checked_name(&name)?;
    let users = user_names(&state).await?;
    let e = state
        .registry()
        .get(&name)
        .cloned()
        .ok_or_else(|| ServiceError::NotFound(format!("no illuminant named '{name}'")))?;
    Ok(Json(entry_json(
        &e,
        users.contains(&e.name.to_ascii_lowercase()),
    )))
}

/// A path's illuminant name that no light could have is the request's mistake (400), as
/// `PUT` says of it, not a light that is missing (404).
fn checked_name(name: &str) -> Result<(), ServiceError> {
    IlluminantRegistry::check_name(name).map_err(|e| ServiceError::BadRequest(e.to_string()))
}

/// `PUT /v1/illuminants/{name}`: create or replace from a matrix, an SPD or a CCT.
pub async fn put(
    State(state): State<AppState>,
    UrlPath(name): UrlPath<String>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ServiceError> {
    super::render::require_json(&headers)?;
    let body = super::render::body_bytes(body, state.config.server.max_body_bytes)?;
    let def: IlluminantDefinition = serde_json::from_slice(&body).map_err(|e| {
        ServiceError::InvalidJson(format!(
            "illuminant definition: {e} (expected {{\"matrix\": [[..],[..],[..]]}}, {{\"spd\": {{\"wavelengths_nm\": [..], \"values\": [..]}}}} or {{\"cct\": K}})"
        ))
    })?;
    let lower = name.to_ascii_lowercase();
    if lower == "d65" {
        return Err(ServiceError::Conflict(
            "D65 is the rendering target and cannot be replaced".into(),
        ));
    }
    if ["cct:", "xy:", "csv:", "iset:", "spd:"]
        .iter()
        .any(|p| lower.starts_with(p))
    {
        return Err(ServiceError::BadRequest(format!(
            "illuminant name '{name}' uses a reserved prefix (cct:, xy:, csv:, iset:, spd:)"
        )));
    }
    // one registry change at a time, from reading the live registry to
    // swapping in the new one: concurrent PUTs and DELETEs cannot undo each
    // other
    let _writing = state.registry_writes.lock().await;
    // validate on a copy before persisting; fitting T from an SPD is CPU
    // work, done off the runtime: on the render pool (a few milliseconds, which
    // on the background pool would wait behind a running training job)
    let copy = state.registry().clone();
    let (name2, def2) = (name.clone(), def.clone());
    let (copy, entry) = super::cpu::run(&state.pools.render, "the illuminant fit", move || {
        let mut copy = copy;
        apply(&mut copy, &name2, &def2).map(|e| (copy, e))
    })
    .await??;
    let existed = user_names(&state).await?.contains(&lower);
    let text = serde_json::to_string(&def)
        .map_err(|e| ServiceError::Internal(format!("illuminant definition: {e}")))?;
    state
        .store
        .upsert_illuminant(&entry.name, &text, now_ms())
        .await?;
    let rows = state.store.illuminants().await?;
    // the rows before the registry, as in `reload`
    *state
        .illuminant_rows
        .lock()
        .unwrap_or_else(|p| p.into_inner()) = rows;
    *state.registry() = copy;
    state.forget_illuminant(&entry.name);
    let status = if existed {
        StatusCode::OK
    } else {
        StatusCode::CREATED
    };
    Ok((status, Json(entry_json(&entry, true))).into_response())
}

/// `DELETE /v1/illuminants/{name}`: user illuminants only (a built-in it replaced returns).
pub async fn delete(
    State(state): State<AppState>,
    UrlPath(name): UrlPath<String>,
) -> Result<StatusCode, ServiceError> {
    checked_name(&name)?;
    let lower = name.to_ascii_lowercase();
    if lower == "d65" {
        return Err(ServiceError::Conflict(
            "D65 is the rendering target and cannot be deleted".into(),
        ));
    }
    let _writing = state.registry_writes.lock().await;
    let stored = state
        .store
        .illuminants()
        .await?
        .into_iter()
        .map(|r| r.name)
        .find(|n| n.eq_ignore_ascii_case(&name));
    let Some(stored) = stored else {
        return Err(if state.registry().get(&name).is_some() {
            ServiceError::Conflict(format!(
                "'{name}' is a built-in illuminant and cannot be deleted"
            ))
        } else {
            ServiceError::NotFound(format!("no illuminant named '{name}'"))
        });
    };
    state.store.delete_illuminant(&stored).await?;
    let rows = state.store.illuminants().await?;
    reload(&state, rows).await?;
    state.forget_illuminant(&stored);
    Ok(StatusCode::NO_CONTENT)
}

/// What training and evaluations take as a light, for problem details.
const SPECTRAL_LIGHTS: &str =
    "a built-in light (GET /v1/illuminants), a registered light made from a cct or spd, or cct:K";

/// The light a client names for a training job or a simulated evaluation, as the spectral
/// spec the simulation reads, which names no registry entry (a job's stored request is
/// trained as it was submitted, on any replica): a built-in name or `cct:K` as given, a
/// registered light made from a colour temperature as its `cct:K`, one made from SPD samples
/// as those samples under its name (`spd:NAME:W=V,…`, which is also taken as given). Files
/// (`csv:`, `iset:`) are refused over HTTP and an unknown name is 400 `unknown_illuminant`
/// (naming what is accepted); a registered light the simulation cannot use (a matrix) is 422
/// saying why.
pub fn spectral_spec(state: &Inner, name: &str) -> Result<String, ServiceError> {
    let spec = name.trim();
    let lower = spec.to_ascii_lowercase();
    let unknown = |why: &str| {
        ServiceError::UnknownIlluminant(format!(
            "illuminant '{spec}': {why}; use {SPECTRAL_LIGHTS} (known: {})",
            spectral_names(state).join(", ")
        ))
    };
    if lower.starts_with("csv:") || lower.starts_with("iset:") {
        return Err(unknown(
            "file-based illuminant specs are not accepted over HTTP",
        ));
    }
    if lower.starts_with("xy:") {
        return Err(unknown(
            "a chromaticity has no spectrum to simulate a scene under",
        ));
    }
    let registered = state.registry().get(spec).cloned();
    if let Some(e) = registered {
        if let Some(def) = user_definition(state, &e.name) {
            return registered_spectral_spec(spec, &e.name, &def);
        }
        // an ISET light of the operator's data directory, by its registry name
        if e.source == CorrectionSource::Iset && IlluminantSpec::parse(&e.name).is_err() {
            return Ok(format!("iset:{}", e.name));
        }
    }
    match IlluminantSpec::parse(spec) {
        // as the stored request will hold it
        Ok(inline @ IlluminantSpec::Samples { .. }) => Ok(inline.to_string()),
        Ok(_) => Ok(spec.to_string()),
        Err(e) if lower.starts_with("spd:") => Err(ServiceError::BadRequest(e.to_string())),
        Err(_) => Err(unknown("no such light")),
    }
}

/// The spectral spec of the user's light `name` (as `spec` named it) defined by `def`.
fn registered_spectral_spec(
    spec: &str,
    name: &str,
    def: &IlluminantDefinition,
) -> Result<String, ServiceError> {
    if let Some(k) = def.cct {
        return Ok(format!("cct:{k}"));
    }
    if let Some(s) = &def.spd {
        return IlluminantSpec::samples(name, s.wavelengths_nm.clone(), s.values.clone())
            .map(|inline| inline.to_string())
            .map_err(|e| {
                ServiceError::Unprocessable(format!(
                    "illuminant '{spec}': its SPD samples cannot simulate a scene: {e}"
                ))
            });
    }
    Err(ServiceError::Unprocessable(format!(
        "illuminant '{spec}' is registered as a matrix only: it has no spectrum to simulate a scene under; register it with \"cct\" or \"spd\" to use it here"
    )))
}

/// The stored definition of the user's light `name` (compared without case), from the rows
/// the registry was built from.
fn user_definition(state: &Inner, name: &str) -> Option<IlluminantDefinition> {
    let rows = state
        .illuminant_rows
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    let row = rows.iter().find(|r| r.name.eq_ignore_ascii_case(name))?;
    serde_json::from_str(&row.definition_json).ok()
}

/// The names [`spectral_spec`] takes, for its problem details: the registry's lights that
/// have a usable spectrum, then `cct:K`.
fn spectral_names(state: &Inner) -> Vec<String> {
    let mut names: Vec<String> = state
        .registry()
        .entries()
        .filter(|e| match e.source {
            CorrectionSource::Cct => e.cct.is_some(),
            CorrectionSource::Spd | CorrectionSource::Iset => true,
            CorrectionSource::Matrix => false,
            CorrectionSource::Builtin => IlluminantSpec::parse(&e.name).is_ok(),
        })
        .map(|e| e.name.clone())
        .collect();
    names.push("cct:K".into());
    names
}
