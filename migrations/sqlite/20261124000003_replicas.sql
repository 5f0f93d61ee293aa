-- Replicas sharing one database: job leases (owner, expiry, heartbeat), cancellation through
-- the row, a job kind (only 'train' today), a CHECK on the job status, and the table bytes in
-- the database (SQLite keeps them in the table files: `content` stays NULL here).
-- SQLite cannot add a CHECK to an existing table: training_jobs is rebuilt.

CREATE TABLE training_jobs_new (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL DEFAULT 'train',
    status TEXT NOT NULL
        CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'canceled')),
    request_json TEXT NOT NULL,
    idempotency_key TEXT UNIQUE,
    request_sha256 TEXT NOT NULL,
    activate BIGINT NOT NULL DEFAULT 0,
    progress DOUBLE PRECISION NOT NULL DEFAULT 0,
    stage TEXT,
    error TEXT,
    table_id TEXT,
    attempts BIGINT NOT NULL DEFAULT 0,
    created_at BIGINT NOT NULL,
    started_at BIGINT,
    finished_at BIGINT,
    lease_owner TEXT,
    lease_expires_at BIGINT,
    heartbeat_at BIGINT,
    cancel_requested BIGINT NOT NULL DEFAULT 0
);

INSERT INTO training_jobs_new (id, status, request_json, idempotency_key, request_sha256,
    activate, progress, stage, error, table_id, attempts, created_at, started_at, finished_at)
SELECT id, status, request_json, idempotency_key, request_sha256,
    activate, progress, stage, error, table_id, attempts, created_at, started_at, finished_at
FROM training_jobs;

DROP TABLE training_jobs;
ALTER TABLE training_jobs_new RENAME TO training_jobs;
CREATE INDEX training_jobs_status ON training_jobs (status, created_at);
CREATE INDEX training_jobs_lease ON training_jobs (status, lease_expires_at);

ALTER TABLE l3_tables ADD COLUMN content BLOB;
