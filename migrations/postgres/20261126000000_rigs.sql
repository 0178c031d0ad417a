-- Uploaded rigs, the PostgreSQL twin of ../20261126000000_rigs.sql.

CREATE TABLE rigs (
    id          UUID    PRIMARY KEY,
    filename    TEXT    NOT NULL,                 -- the upload's own name, display only
    format      TEXT    NOT NULL,                 -- found from the bytes: bvh|glb
    units       TEXT    NOT NULL,                 -- what the rest pose was read in: m|cm|mm
    sha256      TEXT    NOT NULL,                 -- not unique: one file, several mappings
    size_bytes  BIGINT  NOT NULL,
    skeleton    TEXT    NOT NULL,                 -- JSON {names, parents, offsets (metres), humanoid}
    created_at  BIGINT  NOT NULL
);
