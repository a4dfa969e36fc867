-- Clips may also be NPZ files motionaug wrote (outputs uploaded again).
ALTER TABLE clips DROP CONSTRAINT clips_format_check;
ALTER TABLE clips ADD CONSTRAINT clips_format_check CHECK (format IN ('bvh', 'amc', 'npz'));
