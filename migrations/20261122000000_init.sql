-- Songs and the job queue. Times are integer milliseconds since the Unix epoch (UTC), so
-- lease arithmetic stays in SQL. Ids are hyphenated UUID v7 text, which sorts by creation time.

CREATE TABLE songs (
    id          TEXT    PRIMARY KEY NOT NULL,
    filename    TEXT    NOT NULL,                 -- the upload's own name, display only
    format      TEXT    NOT NULL,                 -- found by decoding: mp3|wav|flac|ogg|m4a
    duration_s  REAL    NOT NULL,
    sample_rate INTEGER NOT NULL,
    channels    INTEGER NOT NULL,
    sha256      TEXT    NOT NULL UNIQUE,          -- the same bytes are one song
    size_bytes  INTEGER NOT NULL,
    analysis    TEXT,                             -- JSON {tempo_bpm, beat_times, downbeat_times}
    created_at  INTEGER NOT NULL
);

CREATE TABLE jobs (
    id               TEXT    PRIMARY KEY NOT NULL,
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
    idempotency_key  TEXT    UNIQUE,
    request_hash     TEXT,
    result           TEXT,                        -- JSON {files: [...]} of a succeeded generate job
    error            TEXT,
    created_at       INTEGER NOT NULL,
    started_at       INTEGER,
    finished_at      INTEGER
);

-- The claim query's scan: runnable jobs by priority, then age.
CREATE INDEX jobs_claim ON jobs (status, priority DESC, run_after, id);
CREATE INDEX jobs_lease ON jobs (status, lease_expires_at);
CREATE INDEX jobs_song ON jobs (song_id, kind);
CREATE INDEX jobs_model ON jobs (model, id);

-- Append-only history of every status change, written by triggers so it cannot drift.
CREATE TABLE job_events (
    seq         INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id      TEXT    NOT NULL REFERENCES jobs(id),
    from_status TEXT,
    to_status   TEXT    NOT NULL,
    attempt     INTEGER NOT NULL,
    worker      TEXT,
    error       TEXT,
    at          INTEGER NOT NULL
);
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
