-- Tenants (issue 27): every song, job and rig belongs to one tenant, the API key that made it.
-- Rows stored before keys existed belong to the open tenant (the nil UUID), which is also the
-- tenant of an open service and of the single `auth_token`.
--
-- The same bytes uploaded by two tenants are two songs, and an Idempotency-Key is one tenant's:
-- both uniques become per tenant. SQLite cannot drop a column's UNIQUE, so `songs` and `jobs`
-- are rebuilt. sqlx runs a migration inside a transaction, where `PRAGMA foreign_keys` cannot
-- change; with deferred foreign keys, dropping a parent counts the children it orphans and
-- re-inserting the parent rows counts them back, so the check at COMMIT passes.
--
-- `job_events` loses its foreign key to `jobs`: it is the audit log, and a line must outlive the
-- job a deletion or the retention sweep removes.

PRAGMA defer_foreign_keys = ON;

CREATE TEMP TABLE songs_before AS SELECT * FROM songs;
CREATE TEMP TABLE jobs_before AS SELECT * FROM jobs;
CREATE TEMP TABLE job_events_before AS SELECT * FROM job_events;
DROP TABLE job_events;
DROP TABLE jobs;
DROP TABLE songs;

CREATE TABLE songs (
    id          TEXT    PRIMARY KEY NOT NULL,
    tenant_id   TEXT    NOT NULL DEFAULT '00000000-0000-0000-0000-000000000000',
    filename    TEXT    NOT NULL,                 -- the upload's own name, display only
    format      TEXT    NOT NULL,                 -- found by decoding: mp3|wav|flac|ogg|m4a
    duration_s  REAL    NOT NULL,
    sample_rate INTEGER NOT NULL,
    channels    INTEGER NOT NULL,
    sha256      TEXT    NOT NULL,                 -- the same bytes are one song, per tenant
    size_bytes  INTEGER NOT NULL,
    analysis    TEXT,                             -- JSON {tempo_bpm, beat_times, downbeat_times}
    created_at  INTEGER NOT NULL,
    UNIQUE (tenant_id, sha256)
);
INSERT INTO songs (id, filename, format, duration_s, sample_rate, channels, sha256, size_bytes, analysis, created_at)
SELECT id, filename, format, duration_s, sample_rate, channels, sha256, size_bytes, analysis, created_at FROM songs_before;

CREATE TABLE jobs (
    id               TEXT    PRIMARY KEY NOT NULL,
    tenant_id        TEXT    NOT NULL DEFAULT '00000000-0000-0000-0000-000000000000',
    kind             TEXT    NOT NULL,            -- analyze|generate
    song_id          TEXT    NOT NULL REFERENCES songs(id),
    model            TEXT,                        -- generate jobs only
    options          TEXT    NOT NULL,            -- JSON of the job kind and its options
    status           TEXT    NOT NULL CHECK (status IN ('queued','running','succeeded','failed','cancelled')),
    stage            TEXT,
    progress         REAL    NOT NULL DEFAULT 0,
    priority         INTEGER NOT NULL DEFAULT 0,  -- higher runs first
    attempts         INTEGER NOT NULL DEFAULT 0,
    max_attempts     INTEGER NOT NULL,
    run_after        INTEGER NOT NULL,            -- not claimable before this (retry backoff)
    lease_owner      TEXT,
    lease_expires_at INTEGER,
    heartbeat_at     INTEGER,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    idempotency_key  TEXT,                        -- unique per tenant
    request_hash     TEXT,
    result           TEXT,                        -- JSON {files: [...]} of a succeeded generate job
    error            TEXT,
    created_at       INTEGER NOT NULL,
    started_at       INTEGER,
    finished_at      INTEGER,
    UNIQUE (tenant_id, idempotency_key)
);
INSERT INTO jobs (id, kind, song_id, model, options, status, stage, progress, priority, attempts, max_attempts,
                  run_after, lease_owner, lease_expires_at, heartbeat_at, cancel_requested, idempotency_key,
                  request_hash, result, error, created_at, started_at, finished_at)
SELECT id, kind, song_id, model, options, status, stage, progress, priority, attempts, max_attempts,
       run_after, lease_owner, lease_expires_at, heartbeat_at, cancel_requested, idempotency_key,
       request_hash, result, error, created_at, started_at, finished_at FROM jobs_before;

CREATE INDEX jobs_claim ON jobs (status, priority DESC, run_after, id);
CREATE INDEX jobs_lease ON jobs (status, lease_expires_at);
CREATE INDEX jobs_song ON jobs (song_id, kind);
CREATE INDEX jobs_model ON jobs (model, id);
CREATE INDEX jobs_tenant ON jobs (tenant_id, id);

CREATE TABLE job_events (
    seq         INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id      TEXT    NOT NULL,                 -- no foreign key: the audit line outlives its job
    from_status TEXT,
    to_status   TEXT    NOT NULL,
    attempt     INTEGER NOT NULL,
    worker      TEXT,
    error       TEXT,
    at          INTEGER NOT NULL
);
INSERT INTO job_events SELECT * FROM job_events_before;
CREATE INDEX job_events_job ON job_events (job_id, seq);

CREATE TRIGGER job_registered AFTER INSERT ON jobs
BEGIN
    INSERT INTO job_events (job_id, from_status, to_status, attempt, worker, error, at)
    VALUES (NEW.id, NULL, NEW.status, NEW.attempts, NULL, NULL, NEW.created_at);
END;

CREATE TRIGGER job_status_changed AFTER UPDATE OF status ON jobs
WHEN OLD.status <> NEW.status
BEGIN
    INSERT INTO job_events (job_id, from_status, to_status, attempt, worker, error, at)
    VALUES (NEW.id, OLD.status, NEW.status, NEW.attempts, COALESCE(NEW.lease_owner, OLD.lease_owner), NEW.error,
            CAST((julianday('now') - 2440587.5) * 86400000 AS INTEGER));
END;

DROP TABLE job_events_before;
DROP TABLE jobs_before;
DROP TABLE songs_before;

ALTER TABLE rigs ADD COLUMN tenant_id TEXT NOT NULL DEFAULT '00000000-0000-0000-0000-000000000000';
