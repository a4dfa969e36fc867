-- motionaug service schema: Postgres is the system of record for tenants, data and jobs.

CREATE TABLE tenants (
    id          uuid PRIMARY KEY,
    name        text NOT NULL UNIQUE,
    created_at  timestamptz NOT NULL DEFAULT now()
);

-- API keys are stored as the SHA-256 of the key; the key itself is shown once.
CREATE TABLE api_keys (
    id          uuid PRIMARY KEY,
    tenant_id   uuid NOT NULL REFERENCES tenants (id) ON DELETE CASCADE,
    key_hash    bytea NOT NULL UNIQUE,
    prefix      text NOT NULL,
    created_at  timestamptz NOT NULL DEFAULT now(),
    revoked_at  timestamptz
);

CREATE TABLE datasets (
    id          uuid PRIMARY KEY,
    tenant_id   uuid NOT NULL REFERENCES tenants (id) ON DELETE CASCADE,
    name        text NOT NULL,
    created_at  timestamptz NOT NULL DEFAULT now()
);
CREATE INDEX datasets_by_tenant ON datasets (tenant_id, created_at);

-- One clip per BVH or AMC file, with the original bytes and a parsed summary.
CREATE TABLE clips (
    id             uuid PRIMARY KEY,
    dataset_id     uuid NOT NULL REFERENCES datasets (id) ON DELETE CASCADE,
    position       integer NOT NULL,
    name           text NOT NULL,
    format         text NOT NULL CHECK (format IN ('bvh', 'amc')),
    source_name    text NOT NULL,
    source         bytea NOT NULL,
    skeleton_name  text,
    skeleton       bytea,
    frames         integer NOT NULL,
    fps            double precision NOT NULL,
    joints         integer NOT NULL,
    joint_names    jsonb NOT NULL,
    UNIQUE (dataset_id, name)
);

CREATE TABLE augmentations (
    id            uuid PRIMARY KEY,
    tenant_id     uuid NOT NULL REFERENCES tenants (id) ON DELETE CASCADE,
    dataset_id    uuid NOT NULL REFERENCES datasets (id) ON DELETE CASCADE,
    recipe        jsonb NOT NULL,
    seed          bigint NOT NULL,
    cancelled_at  timestamptz,
    created_at    timestamptz NOT NULL DEFAULT now()
);
CREATE INDEX augmentations_by_dataset ON augmentations (dataset_id);

-- Jobs. `epoch` is the lease token: every claim increments it and every report from a
-- worker must carry the current one, so a late report from an expired lease is refused.
CREATE TABLE jobs (
    id                uuid PRIMARY KEY,
    -- Queue order (first in, first out).
    seq               bigint GENERATED ALWAYS AS IDENTITY,
    augmentation_id   uuid NOT NULL REFERENCES augmentations (id) ON DELETE CASCADE,
    kind              text NOT NULL,
    state             text NOT NULL CHECK (state IN ('queued', 'running', 'succeeded', 'failed', 'cancelled')),
    input             jsonb NOT NULL,
    output            jsonb,
    attempts          integer NOT NULL DEFAULT 0,
    max_attempts      integer NOT NULL,
    epoch             bigint NOT NULL DEFAULT 0,
    worker_id         text,
    claimed_at        timestamptz,
    lease_expires_at  timestamptz,
    run_after         timestamptz NOT NULL DEFAULT now(),
    progress          double precision NOT NULL DEFAULT 0,
    error             text,
    checkpoint        bytea,
    completions       integer NOT NULL DEFAULT 0,
    created_at        timestamptz NOT NULL DEFAULT now(),
    finished_at       timestamptz
);
CREATE INDEX jobs_queued ON jobs (seq) WHERE state = 'queued';
CREATE INDEX jobs_leases ON jobs (lease_expires_at) WHERE state = 'running';
CREATE INDEX jobs_by_augmentation ON jobs (augmentation_id);

-- A job is runnable when every job it depends on has succeeded.
CREATE TABLE job_dependencies (
    job_id      uuid NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    depends_on  uuid NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    PRIMARY KEY (job_id, depends_on)
);
CREATE INDEX job_dependencies_reverse ON job_dependencies (depends_on);

-- Result files. Unique per augmentation by name: a re-run of a job overwrites its own files.
CREATE TABLE artifacts (
    id               uuid PRIMARY KEY,
    job_id           uuid NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
    augmentation_id  uuid NOT NULL REFERENCES augmentations (id) ON DELETE CASCADE,
    name             text NOT NULL,
    content          bytea NOT NULL,
    sha256           bytea NOT NULL,
    epoch            bigint NOT NULL,
    created_at       timestamptz NOT NULL DEFAULT now(),
    UNIQUE (augmentation_id, name)
);
CREATE INDEX artifacts_by_job ON artifacts (job_id);

-- Workers seen recently (for the worker-count metric).
CREATE TABLE workers (
    id          text PRIMARY KEY,
    first_seen  timestamptz NOT NULL DEFAULT now(),
    last_seen   timestamptz NOT NULL DEFAULT now()
);
