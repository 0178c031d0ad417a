-- API keys (issue 27): each key is a tenant. The secret is shown once, at creation; only its
-- SHA-256 is kept (the secret is 256 random bits, so a fast hash is as safe as a slow KDF and
-- lets the lookup use an index). `tenant_id` is its own column, set to the key's id at creation,
-- so a rotated key could later be given the same tenant. A revoked key stays as a row: it is
-- refused with 401, and its existence keeps keys required (revoking the last key must not open
-- the service). The quota columns override the config's defaults when set.
CREATE TABLE api_keys (
    id                  TEXT    PRIMARY KEY NOT NULL,
    tenant_id           TEXT    NOT NULL,
    name                TEXT    NOT NULL,
    secret_sha256       TEXT    NOT NULL UNIQUE,   -- hex SHA-256 of the secret
    admin               INTEGER NOT NULL DEFAULT 0,
    rate_limit_rps      REAL,                      -- NULL: the config's rate_limit_rps
    max_queued_jobs     INTEGER,                   -- NULL: the config's max_queued_jobs
    storage_quota_bytes INTEGER,                   -- NULL: the config's storage_quota_bytes
    created_at          INTEGER NOT NULL,
    last_used_at        INTEGER,
    revoked_at          INTEGER
);

-- The bytes of a succeeded job's result files, counted against its tenant's storage quota.
ALTER TABLE jobs ADD COLUMN result_bytes INTEGER NOT NULL DEFAULT 0;

-- The fair claim asks, per tenant with runnable jobs, how many run and when it was last served.
CREATE INDEX jobs_tenant_status ON jobs (tenant_id, status);
CREATE INDEX jobs_tenant_started ON jobs (tenant_id, started_at);
CREATE INDEX rigs_tenant ON rigs (tenant_id);
