-- Tenants (issue 27): every song, job and rig belongs to one tenant, the API key that made it.
-- Rows stored before keys existed belong to the open tenant (the nil UUID), which is also the
-- tenant of an open service and of the single `auth_token`. The same bytes uploaded by two
-- tenants are two songs, and an Idempotency-Key is one tenant's: both uniques become per tenant.
-- `job_events` loses its foreign key to `jobs`: it is the audit log, and a line must outlive the
-- job a deletion or the retention sweep removes.

ALTER TABLE songs ADD COLUMN tenant_id UUID NOT NULL DEFAULT '00000000-0000-0000-0000-000000000000';
ALTER TABLE songs DROP CONSTRAINT songs_sha256_key;
ALTER TABLE songs ADD CONSTRAINT songs_tenant_sha256_key UNIQUE (tenant_id, sha256);

ALTER TABLE jobs ADD COLUMN tenant_id UUID NOT NULL DEFAULT '00000000-0000-0000-0000-000000000000';
ALTER TABLE jobs DROP CONSTRAINT jobs_idempotency_key_key;
ALTER TABLE jobs ADD CONSTRAINT jobs_tenant_idempotency_key_key UNIQUE (tenant_id, idempotency_key);
CREATE INDEX jobs_tenant ON jobs (tenant_id, id);

ALTER TABLE job_events DROP CONSTRAINT job_events_job_id_fkey;

ALTER TABLE rigs ADD COLUMN tenant_id UUID NOT NULL DEFAULT '00000000-0000-0000-0000-000000000000';
