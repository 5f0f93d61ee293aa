//! `illuminants`: the user's illuminant definitions (JSON), shared by the replicas.

use super::error::StoreError;
use super::{Change, Store};

/// An `illuminants` row.
#[derive(Debug, Clone, PartialEq, sqlx::FromRow)]
pub struct IlluminantRow {
    pub name: String,
    pub definition_json: String,
}

impl Store {
    /// The user illuminants, in creation order.
    pub async fn illuminants(&self) -> Result<Vec<IlluminantRow>, StoreError> {
        Ok(on_pool!(self, p => sqlx::query_as::<_, IlluminantRow>(
            "SELECT name, definition_json FROM illuminants ORDER BY created_at, name",
        )
        .fetch_all(p)
        .await?))
    }

    /// Creates or replaces a user illuminant, and tells the other replicas.
    pub async fn upsert_illuminant(
        &self,
        name: &str,
        definition_json: &str,
        now: i64,
    ) -> Result<(), StoreError> {
        on_pool!(self, p => sqlx::query(
            "INSERT INTO illuminants (name, definition_json, created_at) VALUES ($1, $2, $3)
             ON CONFLICT (name) DO UPDATE SET definition_json = excluded.definition_json",
        )
        .bind(name)
        .bind(definition_json)
        .bind(now)
        .execute(p)
        .await?
        .rows_affected());
        self.notify(Change::Illuminants).await
    }

    /// Deletes a user illuminant, and tells the other replicas.
    pub async fn delete_illuminant(&self, name: &str) -> Result<(), StoreError> {
        on_pool!(self, p => sqlx::query("DELETE FROM illuminants WHERE name = $1")
            .bind(name)
            .execute(p)
            .await?
            .rows_affected());
        self.notify(Change::Illuminants).await
    }
}
