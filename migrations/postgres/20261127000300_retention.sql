-- Retention, the PostgreSQL twin of ../20261127000300_retention.sql: the last use of a song is
-- COALESCE(last_used_at, created_at), of a job COALESCE(last_used_at, finished_at, created_at).

ALTER TABLE songs ADD COLUMN last_used_at BIGINT;
ALTER TABLE jobs ADD COLUMN last_used_at BIGINT;
