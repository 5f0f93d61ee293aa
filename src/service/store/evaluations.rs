//! `evaluations`: ΔE2000 reports, with the request that made them.

use super::Store;
use super::columns::{EvaluationChart, EvaluationMethod, column};
use super::error::{RowKind, StoreError};

/// The table's name (in errors).
const TABLE: &str = "evaluations";

/// An `evaluations` row.
#[derive(Debug, Clone, PartialEq)]
pub struct EvaluationRow {
    pub id: String,
    pub table_id: Option<String>,
    pub method: EvaluationMethod,
    pub chart: EvaluationChart,
    pub acquisition_illuminant: String,
    pub mean_delta_e: f64,
    pub request_json: String,
    pub report_json: String,
    pub created_at: i64,
}

/// An `evaluations` row as stored.
#[derive(Debug, sqlx::FromRow)]
struct StoredEvaluationRow {
    id: String,
    table_id: Option<String>,
    method: String,
    chart: String,
    acquisition_illuminant: String,
    mean_delta_e: f64,
    request_json: String,
    report_json: String,
    created_at: i64,
}

impl TryFrom<StoredEvaluationRow> for EvaluationRow {
    type Error = StoreError;

    fn try_from(r: StoredEvaluationRow) -> Result<EvaluationRow, StoreError> {
        let method = column(TABLE, &r.id, &r.method, EvaluationMethod::parse)?;
        let chart = column(TABLE, &r.id, &r.chart, EvaluationChart::parse)?;
        Ok(EvaluationRow {
            id: r.id,
            table_id: r.table_id,
            method,
            chart,
            acquisition_illuminant: r.acquisition_illuminant,
            mean_delta_e: r.mean_delta_e,
            request_json: r.request_json,
            report_json: r.report_json,
            created_at: r.created_at,
        })
    }
}

impl Store {
    pub async fn insert_evaluation(&self, e: &EvaluationRow) -> Result<(), StoreError> {
        on_pool!(self, p => sqlx::query(
            "INSERT INTO evaluations (id, table_id, method, chart, acquisition_illuminant, mean_delta_e, request_json, report_json, created_at)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)",
        )
        .bind(&e.id)
        .bind(&e.table_id)
        .bind(e.method.as_str())
        .bind(e.chart.as_str())
        .bind(&e.acquisition_illuminant)
        .bind(e.mean_delta_e)
        .bind(&e.request_json)
        .bind(&e.report_json)
        .bind(e.created_at)
        .execute(p)
        .await?
        .rows_affected());
        Ok(())
    }

    /// The evaluation `id`; [`StoreError::NotFound`] when there is none.
    pub async fn evaluation(&self, id: &str) -> Result<EvaluationRow, StoreError> {
        let row = on_pool!(self, p => sqlx::query_as::<_, StoredEvaluationRow>(
            "SELECT * FROM evaluations WHERE id = $1",
        )
        .bind(id)
        .fetch_optional(p)
        .await?);
        row.ok_or_else(|| StoreError::NotFound {
            kind: RowKind::Evaluation,
            id: id.to_string(),
        })?
        .try_into()
    }

    /// The newest evaluations first (at most 1000).
    pub async fn evaluations(&self) -> Result<Vec<EvaluationRow>, StoreError> {
        let rows = on_pool!(self, p => sqlx::query_as::<_, StoredEvaluationRow>(
            "SELECT * FROM evaluations ORDER BY created_at DESC, id LIMIT 1000",
        )
        .fetch_all(p)
        .await?);
        rows.into_iter().map(EvaluationRow::try_from).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn evaluations_read_back_typed_and_a_bad_method_is_a_corrupt_row() {
        let dir = tempfile::tempdir().unwrap();
        let s = Store::connect("", dir.path()).await.unwrap();
        let e = EvaluationRow {
            id: "eval_1".into(),
            table_id: None,
            method: EvaluationMethod::Baseline,
            chart: EvaluationChart::Natural100,
            acquisition_illuminant: "Tungsten".into(),
            mean_delta_e: 2.5,
            request_json: "{}".into(),
            report_json: "{}".into(),
            created_at: 3,
        };
        s.insert_evaluation(&e).await.unwrap();
        assert_eq!(s.evaluation("eval_1").await.unwrap(), e);
        let missing = s.evaluation("eval_2").await.unwrap_err();
        assert_eq!(missing.to_string(), "no evaluation with id 'eval_2'");
        let Store::Sqlite(pool) = &s else {
            unreachable!()
        };
        sqlx::query("UPDATE evaluations SET method = 'matrix' WHERE id = 'eval_1'")
            .execute(pool)
            .await
            .unwrap();
        let bad = s.evaluations().await.unwrap_err();
        assert!(
            matches!(&bad, StoreError::CorruptRow { table: "evaluations", column: "method", value, .. } if value == "matrix"),
            "{bad:?}"
        );
        s.close().await;
    }
}
