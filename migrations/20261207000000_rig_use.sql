-- Rigs expire like songs: `retention_days` after their last use. A use is the upload and each
-- download that names the rig (`?rig=<id>`). NULL means "not used since it was uploaded", so the
-- last use is COALESCE(last_used_at, created_at) and no backfill is needed.
--
-- `GET /v1/rigs` pages one tenant's rigs newest first (ids are time-ordered): the tenant index
-- gains the id, as `jobs_tenant` has it, so a page is read in index order; the usage sum reads
-- it as before.

ALTER TABLE rigs ADD COLUMN last_used_at INTEGER;
DROP INDEX rigs_tenant;
CREATE INDEX rigs_tenant ON rigs (tenant_id, id);
