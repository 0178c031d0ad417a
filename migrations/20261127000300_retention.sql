-- Retention (issue 27): songs and results expire `retention_days` after their last use. A use is
-- an upload (the first, or the same bytes again), a download of the song's audio, the creation
-- of a job, its finish, and a download of one of its results. NULL means "not used since it was
-- made", so the last use is COALESCE(last_used_at, created_at) for a song and
-- COALESCE(last_used_at, finished_at, created_at) for a job; no backfill is needed. A song lives
-- while any job made from it does, so a dance downloaded yesterday keeps its song.

ALTER TABLE songs ADD COLUMN last_used_at INTEGER;
ALTER TABLE jobs ADD COLUMN last_used_at INTEGER;
