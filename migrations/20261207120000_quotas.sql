-- Quotas checked in the transaction that writes: an admission (a job, an upload) first takes its
-- tenant's row here, so one tenant's admissions run one after another and each sees what the
-- last one wrote. A job keeps the storage quota it was admitted under, which its results are
-- held to when they are recorded.

CREATE TABLE tenant_admissions (
    tenant_id    TEXT    PRIMARY KEY NOT NULL,
    admitted_at  INTEGER NOT NULL
);

ALTER TABLE jobs ADD COLUMN storage_quota_bytes INTEGER;
