-- Replicas sharing one database: job leases (owner, expiry, heartbeat), cancellation through
-- the row, a job kind (only 'train' today), a CHECK on the job status, and the table bytes in
-- the database (every replica reads them from here and caches them by id and SHA-256).

ALTER TABLE training_jobs ADD COLUMN kind TEXT NOT NULL DEFAULT 'train';
ALTER TABLE training_jobs ADD CONSTRAINT training_jobs_status_check
    CHECK (status IN ('queued', 'running', 'succeeded', 'failed', 'canceled'));
ALTER TABLE training_jobs ADD COLUMN lease_owner TEXT;
ALTER TABLE training_jobs ADD COLUMN lease_expires_at BIGINT;
ALTER TABLE training_jobs ADD COLUMN heartbeat_at BIGINT;
ALTER TABLE training_jobs ADD COLUMN cancel_requested BIGINT NOT NULL DEFAULT 0;
CREATE INDEX training_jobs_lease ON training_jobs (status, lease_expires_at);

ALTER TABLE l3_tables ADD COLUMN content BYTEA;
