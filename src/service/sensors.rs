//! `GET /v1/sensors` and `GET /v1/sensors/{name}`: the sensor catalogue
//! ([`crate::camera::catalogue`]), each sensor with whether a good stored table was trained
//! for it (the same listing as `l3 sensors`).

use axum::Json;
use axum::extract::{Path as UrlPath, State};
use serde_json::{Value, json};

use super::ServiceError;
use super::state::AppState;
use super::tables::stored_tables;
use crate::camera::catalogue;

/// `GET /v1/sensors`
pub async fn list(State(state): State<AppState>) -> Result<Json<Value>, ServiceError> {
    let stored = stored_tables(&state.store).await?;
    let items = catalogue::listing(|name| stored.newest_for(name));
    Ok(Json(json!({ "items": items })))
}

/// `GET /v1/sensors/{name}`: the summary and the design.
pub async fn get(
    State(state): State<AppState>,
    UrlPath(name): UrlPath<String>,
) -> Result<Json<Value>, ServiceError> {
    let entry = catalogue::find(&name).ok_or_else(|| {
        ServiceError::NotFound(format!(
            "no catalogue sensor '{name}' (GET /v1/sensors lists them)"
        ))
    })?;
    let design = entry
        .design()
        .map_err(|e| ServiceError::Internal(format!("sensor {}: {e}", entry.name)))?;
    let stored = stored_tables(&state.store).await?;
    let json = |e: serde_json::Error| ServiceError::Internal(format!("sensor JSON: {e}"));
    let mut v =
        serde_json::to_value(entry.summary(stored.newest_for(&entry.name))).map_err(json)?;
    v["curves"] = json!(entry.curves);
    v["design"] = serde_json::to_value(design).map_err(json)?;
    Ok(Json(v))
}
