-- Job events pushed to clients (issue 28): `job_events` gains stage and progress lines beside its
-- status lines, which `GET /v1/jobs/{id}/events` streams (its `seq` is the SSE event id, so a
-- reconnect resumes from the table without loss); and the webhook outbox with its attempt log.
--
-- A line's `kind` is `status` (the lines the status triggers already write, so old rows read
-- as status lines) or `progress`. Progress lines are written by a trigger on the job row, like
-- status lines, so they are in the same transaction as the change and cannot drift from it.
-- Only while the job stays running: the claim (queued → running, stage `claimed`) and the end
-- (running → succeeded, stage `done`) are status lines already, and one UPDATE firing two
-- triggers would leave their order to the database.
--
-- Not every heartbeat is a line: a heartbeat writes stage and progress every `heartbeat_s` (1 s)
-- for every running job, so a ten-minute job would log ~600 lines of which a progress bar needs
-- ~20. A line is written when the stage changes, or when progress crosses a 5 % step
-- (⌊progress × 20⌋ changes): at most ~20 progress lines per attempt plus one per stage.

-- A progress line has no `from_status`/`to_status` (NULL), so whatever counts status lines (attempts
-- as `to_status = 'running'`, successes) counts them as before. SQLite cannot drop a NOT NULL, so
-- the table is made again, its lines and their `seq` kept (so AUTOINCREMENT goes on from the
-- highest): the triggers on `jobs` that write it name it, and fire on no statement in between.
CREATE TEMP TABLE job_events_before AS SELECT * FROM job_events;
DROP TABLE job_events;
CREATE TABLE job_events (
    seq         INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id      TEXT    NOT NULL,                 -- no foreign key: the audit line outlives its job
    from_status TEXT,
    to_status   TEXT,                             -- NULL on a progress line
    attempt     INTEGER NOT NULL,
    worker      TEXT,
    error       TEXT,
    at          INTEGER NOT NULL,
    kind        TEXT    NOT NULL DEFAULT 'status',  -- status | progress
    stage       TEXT,                             -- progress lines
    progress    REAL                              -- progress lines
);
INSERT INTO job_events (seq, job_id, from_status, to_status, attempt, worker, error, at)
SELECT seq, job_id, from_status, to_status, attempt, worker, error, at FROM job_events_before;
DROP TABLE job_events_before;
CREATE INDEX job_events_job ON job_events (job_id, seq);

CREATE TRIGGER job_progressed AFTER UPDATE OF stage, progress ON jobs
WHEN OLD.status = 'running' AND NEW.status = 'running' AND NEW.stage IS NOT NULL
     AND (OLD.stage IS NOT NEW.stage
          OR CAST(NEW.progress * 20 AS INTEGER) <> CAST(OLD.progress * 20 AS INTEGER))
BEGIN
    INSERT INTO job_events (job_id, kind, from_status, to_status, attempt, worker, error, at, stage, progress)
    VALUES (NEW.id, 'progress', NULL, NULL, NEW.attempts, NEW.lease_owner, NULL,
            CAST((julianday('now') - 2440587.5) * 86400000 AS INTEGER), NEW.stage, NEW.progress);
END;

-- One row per job that ended with a `webhook_url` (in its options JSON): the outbox the workers'
-- delivery loop drains. Written by a trigger when the job turns terminal, in the same
-- transaction, so a delivery is never lost between the job's end and a crash; a restart finds
-- the pending rows. `next_attempt_at` is also the delivery's lease: a worker that takes a row
-- pushes it past its request timeout first, so a worker that dies mid-attempt hands the row on.
-- No foreign keys: a delivery and its log outlive a deleted job, as `job_events` does.
CREATE TABLE webhooks (
    job_id          TEXT    PRIMARY KEY NOT NULL,
    tenant_id       TEXT    NOT NULL,
    url             TEXT    NOT NULL,
    state           TEXT    NOT NULL DEFAULT 'pending' CHECK (state IN ('pending','delivered','failed')),
    attempts        INTEGER NOT NULL DEFAULT 0,
    next_attempt_at INTEGER NOT NULL,
    created_at      INTEGER NOT NULL,
    finished_at     INTEGER
);
CREATE INDEX webhooks_due ON webhooks (state, next_attempt_at);

CREATE TRIGGER job_ended_webhook AFTER UPDATE OF status ON jobs
WHEN OLD.status <> NEW.status AND NEW.status IN ('succeeded','failed','cancelled')
     AND json_extract(NEW.options, '$.webhook_url') IS NOT NULL
BEGIN
    INSERT OR IGNORE INTO webhooks (job_id, tenant_id, url, next_attempt_at, created_at)
    VALUES (NEW.id, NEW.tenant_id, json_extract(NEW.options, '$.webhook_url'),
            CAST((julianday('now') - 2440587.5) * 86400000 AS INTEGER),
            CAST((julianday('now') - 2440587.5) * 86400000 AS INTEGER));
END;

-- Every delivery attempt: the receiver's HTTP status, or why no answer came.
CREATE TABLE webhook_deliveries (
    seq         INTEGER PRIMARY KEY AUTOINCREMENT,
    job_id      TEXT    NOT NULL,
    attempt     INTEGER NOT NULL,
    status_code INTEGER,
    error       TEXT,
    at          INTEGER NOT NULL
);
CREATE INDEX webhook_deliveries_job ON webhook_deliveries (job_id, seq);
