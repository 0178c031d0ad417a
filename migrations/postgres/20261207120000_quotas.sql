-- Quotas checked in the transaction that writes, the PostgreSQL twin of
-- ../20261207120000_quotas.sql: the upsert of a tenant's row holds its lock until the commit.

CREATE TABLE tenant_admissions (
    tenant_id    UUID   PRIMARY KEY NOT NULL,
    admitted_at  BIGINT NOT NULL
);

ALTER TABLE jobs ADD COLUMN storage_quota_bytes BIGINT;
