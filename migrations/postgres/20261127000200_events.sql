-- Job events pushed to clients (issue 28); the SQLite migration of the same name explains the
-- tables and triggers, which are the same here.

-- A progress line has no from_status/to_status (NULL), so what counts status lines is unchanged.
ALTER TABLE job_events
    ALTER COLUMN to_status DROP NOT NULL,
    ADD COLUMN kind TEXT NOT NULL DEFAULT 'status',
    ADD COLUMN stage TEXT,
    ADD COLUMN progress DOUBLE PRECISION;

CREATE FUNCTION choreo_job_progressed() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    INSERT INTO job_events (job_id, kind, from_status, to_status, attempt, worker, error, at, stage, progress)
    VALUES (NEW.id, 'progress', NULL, NULL, NEW.attempts, NEW.lease_owner, NULL,
            (extract(epoch FROM clock_timestamp()) * 1000)::BIGINT, NEW.stage, NEW.progress);
    RETURN NULL;
END;
$$;

CREATE TRIGGER job_progressed AFTER UPDATE OF stage, progress ON jobs
FOR EACH ROW WHEN (OLD.status = 'running' AND NEW.status = 'running' AND NEW.stage IS NOT NULL
                   AND (OLD.stage IS DISTINCT FROM NEW.stage
                        OR floor(NEW.progress * 20) <> floor(OLD.progress * 20)))
EXECUTE FUNCTION choreo_job_progressed();

CREATE TABLE webhooks (
    job_id          UUID   PRIMARY KEY,
    tenant_id       UUID   NOT NULL,
    url             TEXT   NOT NULL,
    state           TEXT   NOT NULL DEFAULT 'pending' CHECK (state IN ('pending','delivered','failed')),
    attempts        BIGINT NOT NULL DEFAULT 0,
    next_attempt_at BIGINT NOT NULL,
    created_at      BIGINT NOT NULL,
    finished_at     BIGINT
);
CREATE INDEX webhooks_due ON webhooks (state, next_attempt_at);

CREATE FUNCTION choreo_job_ended_webhook() RETURNS trigger LANGUAGE plpgsql AS $$
DECLARE
    now_ms BIGINT := (extract(epoch FROM clock_timestamp()) * 1000)::BIGINT;
BEGIN
    INSERT INTO webhooks (job_id, tenant_id, url, next_attempt_at, created_at)
    VALUES (NEW.id, NEW.tenant_id, NEW.options::jsonb ->> 'webhook_url', now_ms, now_ms)
    ON CONFLICT (job_id) DO NOTHING;
    RETURN NULL;
END;
$$;

CREATE TRIGGER job_ended_webhook AFTER UPDATE OF status ON jobs
FOR EACH ROW WHEN (OLD.status IS DISTINCT FROM NEW.status
                   AND NEW.status IN ('succeeded','failed','cancelled')
                   AND (NEW.options::jsonb ->> 'webhook_url') IS NOT NULL)
EXECUTE FUNCTION choreo_job_ended_webhook();

CREATE TABLE webhook_deliveries (
    seq         BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    job_id      UUID   NOT NULL,
    attempt     BIGINT NOT NULL,
    status_code BIGINT,
    error       TEXT,
    at          BIGINT NOT NULL
);
CREATE INDEX webhook_deliveries_job ON webhook_deliveries (job_id, seq);
