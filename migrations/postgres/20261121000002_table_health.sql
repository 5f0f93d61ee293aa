-- Table file health and activation history: a table whose file fails its checksum at start
-- (or on activation) is marked 'corrupt' (or 'missing') and never served; the service falls
-- back to the table activated most recently before it.

ALTER TABLE l3_tables ADD COLUMN status TEXT NOT NULL DEFAULT 'ok';
ALTER TABLE l3_tables ADD COLUMN status_detail TEXT;
ALTER TABLE l3_tables ADD COLUMN last_activated_at BIGINT;
