-- A song's cache (its beats and feature sets, computed by its first generate job and stored with
-- it: src/song_cache) is counted in its tenant's storage, with the song.

ALTER TABLE songs ADD COLUMN cache_bytes INTEGER NOT NULL DEFAULT 0;
