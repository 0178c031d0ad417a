-- Songs and the job queue, the PostgreSQL twin of ../20261122000000_init.sql. Times are integer
-- milliseconds since the Unix epoch (UTC), as in SQLite, so the lease and backoff arithmetic is
-- the same SQL in both stores. Ids are UUID v7, which PostgreSQL orders by bytes: by creation time.

CREATE TABLE songs (
    id          UUID             PRIMARY KEY,
    filename    TEXT             NOT NULL,        -- the upload's own name, display only
    format      TEXT             NOT NULL,        -- found by decoding: mp3|wav|flac|ogg|m4a
    duration_s  DOUBLE PRECISION NOT NULL,
    sample_rate BIGINT           NOT NULL,
    channels    BIGINT           NOT NULL,
    sha256      TEXT             NOT NULL UNIQUE, -- the same bytes are one song
    size_bytes  BIGINT           NOT NULL,
    analysis    TEXT,                             -- JSON {tempo_bpm, beat_times, downbeat_times}
    created_at  BIGINT           NOT NULL
);

CREATE TABLE jobs (
    id               UUID             PRIMARY KEY,
    kind             TEXT             NOT NULL,   -- analyze|generate
    song_id          UUID             NOT NULL REFERENCES songs(id),
    model            TEXT,                        -- generate jobs only
    options          TEXT             NOT NULL,   -- JSON of the job kind and its options (serde)
    status           TEXT             NOT NULL CHECK (status IN ('queued','running','succeeded','failed','cancelled')),
    stage            TEXT,
    progress         DOUBLE PRECISION NOT NULL DEFAULT 0,
    priority         BIGINT           NOT NULL DEFAULT 0, -- higher runs first
    attempts         BIGINT           NOT NULL DEFAULT 0,
    max_attempts     BIGINT           NOT NULL,
    run_after        BIGINT           NOT NULL,   -- not claimable before this (retry backoff)
    lease_owner      TEXT,
    lease_expires_at BIGINT,
    heartbeat_at     BIGINT,
    cancel_requested BOOLEAN          NOT NULL DEFAULT FALSE,
    idempotency_key  TEXT             UNIQUE,
    request_hash     TEXT,
    result           TEXT,                        -- JSON {files: [...]} of a succeeded generate job
    error            TEXT,
    created_at       BIGINT           NOT NULL,
    started_at       BIGINT,
    finished_at      BIGINT
);

-- The claim's scan: runnable jobs by priority, then age; only queued rows are in it.
CREATE INDEX jobs_claim ON jobs (priority DESC, run_after, id) WHERE status = 'queued';
CREATE INDEX jobs_lease ON jobs (lease_expires_at) WHERE status = 'running';
CREATE INDEX jobs_song ON jobs (song_id, kind);
CREATE INDEX jobs_model ON jobs (model, id);
CREATE INDEX jobs_status ON jobs (status, id);

-- Append-only history of every status change, written by triggers so it cannot drift.
CREATE TABLE job_events (
    seq         BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    job_id      UUID   NOT NULL REFERENCES jobs(id),
    from_status TEXT,
    to_status   TEXT   NOT NULL,
    attempt     BIGINT NOT NULL,
    worker      TEXT,
    error       TEXT,
    at          BIGINT NOT NULL
);
CREATE INDEX job_events_job ON job_events (job_id, seq);

-- Workers LISTEN on this channel; a job that becomes claimable wakes them at once, in any
-- process on any host. A notification is sent at commit, so the job is visible when it arrives.
CREATE FUNCTION choreo_job_event() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    IF TG_OP = 'INSERT' THEN
        INSERT INTO job_events (job_id, from_status, to_status, attempt, worker, error, at)
        VALUES (NEW.id, NULL, NEW.status, NEW.attempts, NULL, NULL, NEW.created_at);
    ELSE
        INSERT INTO job_events (job_id, from_status, to_status, attempt, worker, error, at)
        VALUES (NEW.id, OLD.status, NEW.status, NEW.attempts, COALESCE(NEW.lease_owner, OLD.lease_owner), NEW.error,
                (extract(epoch FROM clock_timestamp()) * 1000)::BIGINT);
    END IF;
    IF NEW.status = 'queued' THEN
        PERFORM pg_notify('choreo_jobs', NEW.id::TEXT);
    END IF;
    RETURN NULL;
END;
$$;

CREATE TRIGGER job_registered AFTER INSERT ON jobs
FOR EACH ROW EXECUTE FUNCTION choreo_job_event();

CREATE TRIGGER job_status_changed AFTER UPDATE OF status ON jobs
FOR EACH ROW WHEN (OLD.status IS DISTINCT FROM NEW.status) EXECUTE FUNCTION choreo_job_event();
