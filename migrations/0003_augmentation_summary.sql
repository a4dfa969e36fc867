-- Each augmentation keeps a summary of its jobs, so reading its status is one
-- lookup by primary key instead of aggregating its jobs on every poll:
-- jobs per state and `done` (succeeded jobs count 1, the others their
-- progress), maintained by statement-level triggers on `jobs` inside the
-- transaction of every change (so the summary never disagrees with the jobs);
-- jobs per kind, the outputs and the correction seconds are fixed at planning
-- (the last two are what the tenant quotas count).
ALTER TABLE augmentations
    ADD COLUMN jobs_queued     integer NOT NULL DEFAULT 0,
    ADD COLUMN jobs_running    integer NOT NULL DEFAULT 0,
    ADD COLUMN jobs_succeeded  integer NOT NULL DEFAULT 0,
    ADD COLUMN jobs_failed     integer NOT NULL DEFAULT 0,
    ADD COLUMN jobs_cancelled  integer NOT NULL DEFAULT 0,
    ADD COLUMN done            double precision NOT NULL DEFAULT 0,
    ADD COLUMN kinds           jsonb NOT NULL DEFAULT '{}',
    ADD COLUMN outputs         bigint NOT NULL DEFAULT 0,
    ADD COLUMN correction_seconds double precision NOT NULL DEFAULT 0;

-- The quota of concurrent augmentations counts a tenant's unfinished ones.
CREATE INDEX augmentations_by_tenant ON augmentations (tenant_id);

-- Adds the changes of job rows to their augmentations' summaries: one row per
-- changed job side, `sign` 1 for a row's new version, -1 for its old one.
CREATE FUNCTION apply_job_changes(augs uuid[], states text[], signs integer[], dones double precision[])
RETURNS void LANGUAGE sql AS $$
    -- Lock the summaries in id order: two statements that change jobs of
    -- several augmentations (the reapers of two coordinators) never deadlock.
    SELECT 1 FROM augmentations WHERE id = ANY (augs) ORDER BY id FOR UPDATE;
    UPDATE augmentations a SET
        jobs_queued    = a.jobs_queued    + d.queued,
        jobs_running   = a.jobs_running   + d.running,
        jobs_succeeded = a.jobs_succeeded + d.succeeded,
        jobs_failed    = a.jobs_failed    + d.failed,
        jobs_cancelled = a.jobs_cancelled + d.cancelled,
        done           = a.done           + d.done
    FROM (
        SELECT aug,
               COALESCE(sum(sign) FILTER (WHERE state = 'queued'), 0)    AS queued,
               COALESCE(sum(sign) FILTER (WHERE state = 'running'), 0)   AS running,
               COALESCE(sum(sign) FILTER (WHERE state = 'succeeded'), 0) AS succeeded,
               COALESCE(sum(sign) FILTER (WHERE state = 'failed'), 0)    AS failed,
               COALESCE(sum(sign) FILTER (WHERE state = 'cancelled'), 0) AS cancelled,
               sum(sign * done) AS done
        FROM unnest(augs, states, signs, dones) AS c (aug, state, sign, done)
        GROUP BY aug
    ) d
    WHERE a.id = d.aug;
$$;

-- What a job adds to `done`.
CREATE FUNCTION job_done(state text, progress double precision)
RETURNS double precision LANGUAGE sql IMMUTABLE AS $$
    SELECT CASE WHEN state = 'succeeded' THEN 1 ELSE progress END;
$$;

CREATE FUNCTION jobs_summarise() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    IF TG_OP = 'INSERT' THEN
        PERFORM apply_job_changes(array_agg(augmentation_id), array_agg(state),
                                  array_agg(1), array_agg(job_done(state, progress)))
        FROM new_jobs;
    ELSIF TG_OP = 'DELETE' THEN
        PERFORM apply_job_changes(array_agg(augmentation_id), array_agg(state),
                                  array_agg(-1), array_agg(job_done(state, progress)))
        FROM old_jobs;
    ELSE
        -- Only rows whose state or progress changed (leases, checkpoints and
        -- outputs change nothing here).
        PERFORM apply_job_changes(array_agg(aug), array_agg(state), array_agg(sign), array_agg(done))
        FROM (
            SELECT n.augmentation_id AS aug, n.state, 1 AS sign, job_done(n.state, n.progress) AS done
            FROM new_jobs n JOIN old_jobs o ON o.id = n.id
            WHERE (n.state, n.progress) IS DISTINCT FROM (o.state, o.progress)
            UNION ALL
            SELECT o.augmentation_id, o.state, -1, job_done(o.state, o.progress)
            FROM new_jobs n JOIN old_jobs o ON o.id = n.id
            WHERE (n.state, n.progress) IS DISTINCT FROM (o.state, o.progress)
        ) c;
    END IF;
    RETURN NULL;
END;
$$;

CREATE TRIGGER jobs_summary_insert AFTER INSERT ON jobs
    REFERENCING NEW TABLE AS new_jobs
    FOR EACH STATEMENT EXECUTE FUNCTION jobs_summarise();
CREATE TRIGGER jobs_summary_update AFTER UPDATE ON jobs
    REFERENCING OLD TABLE AS old_jobs NEW TABLE AS new_jobs
    FOR EACH STATEMENT EXECUTE FUNCTION jobs_summarise();
CREATE TRIGGER jobs_summary_delete AFTER DELETE ON jobs
    REFERENCING OLD TABLE AS old_jobs
    FOR EACH STATEMENT EXECUTE FUNCTION jobs_summarise();

-- The summaries of augmentations made before this migration.
UPDATE augmentations a SET
    jobs_queued    = s.queued,
    jobs_running   = s.running,
    jobs_succeeded = s.succeeded,
    jobs_failed    = s.failed,
    jobs_cancelled = s.cancelled,
    done           = s.done,
    kinds          = s.kinds
FROM (
    SELECT augmentation_id,
           count(*) FILTER (WHERE state = 'queued')    AS queued,
           count(*) FILTER (WHERE state = 'running')   AS running,
           count(*) FILTER (WHERE state = 'succeeded') AS succeeded,
           count(*) FILTER (WHERE state = 'failed')    AS failed,
           count(*) FILTER (WHERE state = 'cancelled') AS cancelled,
           sum(job_done(state, progress)) AS done,
           (SELECT jsonb_object_agg(kind, n)
            FROM (SELECT kind, count(*) AS n FROM jobs k
                  WHERE k.augmentation_id = j.augmentation_id GROUP BY kind) per_kind) AS kinds
    FROM jobs j
    GROUP BY augmentation_id
) s
WHERE a.id = s.augmentation_id;
