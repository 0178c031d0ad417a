-- Uploaded rigs: skeletons (BVH or glb) that dances are retargeted onto (issue 26). The file is
-- an artifact named by the id (rigs/<id>.<format>); the row keeps the skeleton as read from it.

CREATE TABLE rigs (
    id          TEXT    PRIMARY KEY NOT NULL,
    filename    TEXT    NOT NULL,                 -- the upload's own name, display only
    format      TEXT    NOT NULL,                 -- found from the bytes: bvh|glb
    units       TEXT    NOT NULL,                 -- what the rest pose was read in: m|cm|mm
    sha256      TEXT    NOT NULL,                 -- not unique: one file, several mappings
    size_bytes  INTEGER NOT NULL,
    skeleton    TEXT    NOT NULL,                 -- JSON {names, parents, offsets (metres), humanoid}
    created_at  INTEGER NOT NULL
);
