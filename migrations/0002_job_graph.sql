-- The whole augmentation as a job graph (pipeline::plan): every job gets the key
-- it has in the plan, which names it in errors and in its dependents' inputs.
ALTER TABLE jobs ADD COLUMN key text;
UPDATE jobs SET key = kind || ':' || COALESCE(input->>'clip_name', id::text) WHERE key IS NULL;
ALTER TABLE jobs ALTER COLUMN key SET NOT NULL;
CREATE UNIQUE INDEX jobs_key ON jobs (augmentation_id, key);
