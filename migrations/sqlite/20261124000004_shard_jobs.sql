-- Training sharded across replicas: a sharded job (kind 'train_sharded', never claimed itself)
-- becomes shard jobs ('survey_shard', then 'accumulate_shard'), rows of their own that any
-- replica claims under the same lease. A shard row names its parent job, its 0-based index
-- and the number of shards. `compute_ms` is a shard's own work (its step, without the merge);
-- `merge_ms` is a sharded job's merge (reading the parts, merging, solving, writing the
-- table). `finished_by` is the replica that ended a job.

ALTER TABLE training_jobs ADD COLUMN parent_id TEXT;
ALTER TABLE training_jobs ADD COLUMN shard_index BIGINT;
ALTER TABLE training_jobs ADD COLUMN shard_count BIGINT;
ALTER TABLE training_jobs ADD COLUMN compute_ms BIGINT;
ALTER TABLE training_jobs ADD COLUMN merge_ms BIGINT;
ALTER TABLE training_jobs ADD COLUMN finished_by TEXT;
CREATE INDEX training_jobs_parent ON training_jobs (parent_id, kind, shard_index);

-- The partial sums of a shard (the bytes of src/l3/partial_format.rs, which checksums its own
-- content), with the SHA-256 of the whole, checked when they are read back. Deleted when
-- their job ends.
CREATE TABLE training_partials (
    job_id TEXT NOT NULL,
    stage TEXT NOT NULL CHECK (stage IN ('survey', 'accumulate')),
    shard_index BIGINT NOT NULL,
    content BLOB NOT NULL,
    sha256 TEXT NOT NULL,
    size_bytes BIGINT NOT NULL,
    replica TEXT NOT NULL,
    created_at BIGINT NOT NULL,
    PRIMARY KEY (job_id, stage, shard_index)
);
