-- A song's cache counted in its tenant's storage, the PostgreSQL twin of
-- ../20261207130000_song_cache.sql.

ALTER TABLE songs ADD COLUMN cache_bytes BIGINT NOT NULL DEFAULT 0;
