//! The values of the text columns the service reads as Rust enums, each with the exact text
//! stored (the schema and the stored values are those of every earlier version: a value is
//! written and read as the same string). Reading any other text is a
//! [`StoreError::UnknownValue`] (in a row, a [`StoreError::CorruptRow`]), never a panic.
//!
//! Boolean columns are `BIGINT` 0/1 in both backends; rows hold them as `bool` (any non-zero
//! value reads as true, as the SQL's `<> 0` does).

use std::fmt;
use std::str::FromStr;

use super::error::StoreError;

/// Declares an enum of a text column: its values and their stored text, `ALL`, `as_str`,
/// `parse` (a [`StoreError::UnknownValue`] for any other text), `Display` and `FromStr`.
macro_rules! text_column {
    (
        $(#[$meta:meta])*
        pub enum $name:ident in $column:literal {
            $( $(#[$vmeta:meta])* $variant:ident = $text:literal, )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum $name {
            $( $(#[$vmeta])* $variant, )+
        }

        impl $name {
            /// Every value, in declaration order.
            pub const ALL: [$name; [$($text),+].len()] = [$($name::$variant),+];

            /// The stored text.
            pub fn as_str(self) -> &'static str {
                match self {
                    $( $name::$variant => $text, )+
                }
            }

            /// The value stored as `s`.
            pub fn parse(s: &str) -> Result<$name, StoreError> {
                match s {
                    $( $text => Ok($name::$variant), )+
                    _ => Err(StoreError::UnknownValue {
                        column: $column,
                        value: s.to_string(),
                        expected: [$($text),+].join(", "),
                    }),
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.as_str())
            }
        }

        impl FromStr for $name {
            type Err = StoreError;
            fn from_str(s: &str) -> Result<$name, StoreError> {
                $name::parse(s)
            }
        }
    };
}

text_column! {
    /// A job's state (`training_jobs.status`, checked by the schema).
    pub enum JobStatus in "status" {
        Queued = "queued",
        Running = "running",
        Succeeded = "succeeded",
        Failed = "failed",
        Canceled = "canceled",
    }
}

text_column! {
    /// The kind of a job row (`training_jobs.kind`). Workers claim [`WORKER_KINDS`].
    pub enum JobKind in "kind" {
        /// A training job trained in one piece.
        Train = "train",
        /// A training job split into shards: its shard rows are claimed, never the job itself.
        Sharded = "train_sharded",
        /// The survey of one shard's batches (stage 1 of a sharded job).
        SurveyShard = "survey_shard",
        /// The normal equations of one shard's batches (stage 2); the last one to end merges.
        AccumulateShard = "accumulate_shard",
    }
}

text_column! {
    /// What a job is doing (`training_jobs.stage`): the stages the service records, and the
    /// training's own progress stages.
    pub enum JobStage in "stage" {
        Queued = "queued",
        /// Claimed by a replica, not yet reporting progress.
        Starting = "starting",
        /// Surveying the training data (a sharded job's first stage).
        Survey = "survey",
        /// Accumulating the normal equations (a sharded job's second stage).
        Accumulate = "accumulate",
        /// Solving for the kernels.
        Solve = "solve",
        /// The training is done; the table is being written.
        Done = "done",
        /// The last shard of a sharded job merges the parts.
        Merge = "merge",
        Succeeded = "succeeded",
        Failed = "failed",
        Canceled = "canceled",
        RequeuedAfterRestart = "requeued after restart",
        RequeuedAfterLeaseExpiry = "requeued after lease expiry",
        InterruptedByShutdown = "interrupted by shutdown",
    }
}

text_column! {
    /// The stage of a shard's partial sums (`training_partials.stage`, checked by the schema).
    pub enum ShardStage in "stage" {
        Survey = "survey",
        Accumulate = "accumulate",
    }
}

text_column! {
    /// A stored table's file health (`l3_tables.status`).
    pub enum TableStatus in "status" {
        /// The file (or the database's copy) verifies against its recorded SHA-256.
        Ok = "ok",
        /// The bytes differ from the recorded checksum, or do not parse.
        Corrupt = "corrupt",
        /// The file is gone.
        Missing = "missing",
    }
}

text_column! {
    /// How an evaluation rendered the chart (`evaluations.method`).
    pub enum EvaluationMethod in "method" {
        /// An L3 table.
        L3 = "l3",
        /// Bilinear demosaic and a 3×3 matrix fitted under D65, then T.
        Baseline = "baseline",
    }
}

text_column! {
    /// The chart an evaluation used (`evaluations.chart`).
    pub enum EvaluationChart in "chart" {
        Natural100 = "natural100",
        /// A ColorChecker capture posted as a frame.
        ColorChecker = "colorchecker",
    }
}

/// The kinds a job worker claims.
pub const WORKER_KINDS: &[JobKind] = &[
    JobKind::Train,
    JobKind::SurveyShard,
    JobKind::AccumulateShard,
];

impl JobKind {
    /// The stage of a shard kind.
    pub fn shard_stage(self) -> Option<ShardStage> {
        match self {
            JobKind::SurveyShard => Some(ShardStage::Survey),
            JobKind::AccumulateShard => Some(ShardStage::Accumulate),
            JobKind::Train | JobKind::Sharded => None,
        }
    }
}

impl ShardStage {
    /// The kind of the shard rows of this stage.
    pub fn kind(self) -> JobKind {
        match self {
            ShardStage::Survey => JobKind::SurveyShard,
            ShardStage::Accumulate => JobKind::AccumulateShard,
        }
    }
}

/// A boolean column's value (`BIGINT`: zero is false).
pub(super) fn flag(v: i64) -> bool {
    v != 0
}

/// The value stored for `b` in a boolean column (0 or 1).
pub(super) fn flag_value(b: bool) -> i64 {
    i64::from(b)
}

/// Parses `value` of a column of row `id` of `table`: a [`StoreError::CorruptRow`] when it is
/// none of the column's values.
pub(super) fn column<T>(
    table: &'static str,
    id: &str,
    value: &str,
    parse: impl FnOnce(&str) -> Result<T, StoreError>,
) -> Result<T, StoreError> {
    parse(value).map_err(|e| e.in_row(table, id))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every value reads back from its text, and the texts are the ones earlier versions wrote
    /// (the schema's CHECKs and the stored rows depend on them).
    #[test]
    fn values_round_trip_with_the_stored_text() {
        fn texts<T: Copy + fmt::Display + PartialEq + fmt::Debug + FromStr>(all: &[T]) -> String
        where
            T::Err: fmt::Debug,
        {
            for v in all {
                assert_eq!(v.to_string().parse::<T>().unwrap(), *v);
            }
            all.iter().map(T::to_string).collect::<Vec<_>>().join("|")
        }
        assert_eq!(
            texts(&JobStatus::ALL),
            "queued|running|succeeded|failed|canceled"
        );
        assert_eq!(
            texts(&JobKind::ALL),
            "train|train_sharded|survey_shard|accumulate_shard"
        );
        assert_eq!(
            texts(&JobStage::ALL),
            "queued|starting|survey|accumulate|solve|done|merge|succeeded|failed|canceled|\
             requeued after restart|requeued after lease expiry|interrupted by shutdown"
        );
        assert_eq!(texts(&ShardStage::ALL), "survey|accumulate");
        assert_eq!(texts(&TableStatus::ALL), "ok|corrupt|missing");
        assert_eq!(texts(&EvaluationMethod::ALL), "l3|baseline");
        assert_eq!(texts(&EvaluationChart::ALL), "natural100|colorchecker");
        // a job queued or ended records its state's name as its stage (`stage = status`)
        for s in JobStatus::ALL {
            let stage = JobStage::parse(s.as_str());
            assert_eq!(stage.is_ok(), s != JobStatus::Running, "{s}");
        }
    }

    #[test]
    fn an_unknown_value_is_an_error_not_a_panic() {
        let e = JobStatus::parse("done").unwrap_err();
        assert_eq!(
            e.to_string(),
            "status 'done': one of queued, running, succeeded, failed, canceled"
        );
        assert!(JobKind::parse("").is_err());
        assert!(TableStatus::parse("OK").is_err());
        let e = column("l3_tables", "tbl_1", "broken", TableStatus::parse).unwrap_err();
        assert!(
            matches!(&e, StoreError::CorruptRow { table: "l3_tables", id, column: "status", value, .. }
                if id == "tbl_1" && value == "broken"),
            "{e:?}"
        );
    }

    #[test]
    fn shard_kinds_and_stages_correspond() {
        for s in ShardStage::ALL {
            assert_eq!(s.kind().shard_stage(), Some(s));
        }
        assert_eq!(JobKind::Train.shard_stage(), None);
        assert_eq!(JobKind::Sharded.shard_stage(), None);
        assert!(!WORKER_KINDS.contains(&JobKind::Sharded));
        assert_eq!((flag(0), flag(1), flag(-3)), (false, true, true));
        assert_eq!((flag_value(false), flag_value(true)), (0, 1));
    }
}
