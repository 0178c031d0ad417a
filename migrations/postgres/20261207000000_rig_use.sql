-- Rig retention and listing, the PostgreSQL twin of ../20261207000000_rig_use.sql: the last use
-- of a rig is COALESCE(last_used_at, created_at), and the tenant index gains the id.

ALTER TABLE rigs ADD COLUMN last_used_at BIGINT;
DROP INDEX rigs_tenant;
CREATE INDEX rigs_tenant ON rigs (tenant_id, id);
