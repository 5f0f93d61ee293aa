//! What the database can fail with. The store knows nothing of HTTP: the one mapping of these
//! errors to statuses is `ServiceError`'s (`src/service/error.rs`).

/// The kind of row a lookup by id did not find (it names the row in messages).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    Job,
    Table,
    Evaluation,
}

impl std::fmt::Display for RowKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            RowKind::Job => "training job",
            RowKind::Table => "table",
            RowKind::Evaluation => "evaluation",
        })
    }
}

/// An error of the service's database.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// No row of this kind has the id.
    #[error("no {kind} with id '{id}'")]
    NotFound { kind: RowKind, id: String },
    /// An idempotency key is taken by a job of another request.
    #[error("Idempotency-Key '{key}' was already used with a different request body")]
    KeyConflict { key: String },
    /// A value that is none of a column's values (a parse of an enum column).
    #[error("{column} '{value}': one of {expected}")]
    UnknownValue {
        column: &'static str,
        value: String,
        /// The column's values, comma-separated.
        expected: String,
    },
    /// A stored row with a value the service cannot read (none of its column's values).
    #[error("{table} row '{id}': {column} '{value}' is none of {expected}")]
    CorruptRow {
        table: &'static str,
        id: String,
        column: &'static str,
        value: String,
        expected: String,
    },
    /// A `database_url` that names no backend (or that the backend refuses).
    #[error("{0}")]
    Url(String),
    /// No connection to the database opened at start: where to, and why.
    #[error("database: cannot connect to {url}: {source}")]
    Connect {
        /// The URL without its password.
        url: String,
        source: sqlx::Error,
    },
    /// The migrations could not be applied.
    #[error("database: migration failed: {0}")]
    Migration(#[from] sqlx::migrate::MigrateError),
    /// The database failed (connection, query, constraint).
    #[error("database: {0}")]
    Database(#[from] sqlx::Error),
}

impl StoreError {
    /// An [`StoreError::UnknownValue`] read from row `id` of `table`: a corrupt row. Other
    /// errors are returned as they are.
    pub fn in_row(self, table: &'static str, id: &str) -> StoreError {
        match self {
            StoreError::UnknownValue {
                column,
                value,
                expected,
            } => StoreError::CorruptRow {
                table,
                id: id.to_string(),
                column,
                value,
                expected,
            },
            e => e,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_the_row_and_the_value() {
        let e = StoreError::NotFound {
            kind: RowKind::Job,
            id: "job_1".into(),
        };
        assert_eq!(e.to_string(), "no training job with id 'job_1'");
        let e = StoreError::UnknownValue {
            column: "method",
            value: "x".into(),
            expected: "l3, baseline".into(),
        };
        assert_eq!(e.to_string(), "method 'x': one of l3, baseline");
        let e = e.in_row("evaluations", "eval_1");
        assert_eq!(
            e.to_string(),
            "evaluations row 'eval_1': method 'x' is none of l3, baseline"
        );
        assert!(matches!(e, StoreError::CorruptRow { .. }));
        let e = StoreError::Url("u".into()).in_row("evaluations", "eval_1");
        assert!(matches!(e, StoreError::Url(_)));
    }
}
