//! What the coordinator and the workers must agree on.
//!
//! * The wire types of the internal worker API (`/internal/v1/...`), here in the
//!   crate root: keeping request and response bodies in one small crate makes the
//!   contract explicit and keeps the worker free of any database or HTTP-server
//!   dependency.
//! * [`clip`]: how a stored clip (BVH, or AMC with its ASF) becomes a `Motion`,
//!   so that an upload accepted by the coordinator is read identically by workers.
//! * [`recipe`]: reading a recipe and writing `manifest.json`, the same way the CLI does.

pub mod clip;
pub mod recipe;

use serde::{Deserialize, Serialize};
use uuid::Uuid;

/// Path prefix of the worker API on the coordinator.
pub const WORKER_API_PREFIX: &str = "/internal/v1";

/// Job kinds the coordinator schedules and workers run: the names of
/// `pipeline::JobKind` (`JobKind::name`).
pub mod kinds {
    /// Kinematic synthesis of one clip with the augmentation's recipe.
    pub const SYNTHESIZE: &str = "synthesize";
    /// Train the motion VAE on a class's clips, then sample.
    pub const VAE: &str = "vae";
    /// Body-size variations of a two-person pair.
    pub const INTERACTION: &str = "interaction";
    /// Train a class's tracker policy (`[correct] policy = "class"`).
    pub const TRACKER: &str = "tracker";
    /// Judge a class's new clips with its tracker and train a second tracker
    /// on those it fails (`[correct] variant_tracker_iterations`).
    pub const VARIANT_TRACKER: &str = "variant_tracker";
    /// Physical correction of a source clip (warm start and debiasing data).
    pub const CORRECT_ORIGINAL: &str = "correct_original";
    /// Physical correction of a new clip.
    pub const CORRECT: &str = "correct";
    /// Train the debiasing network on (corrected original, original) pairs.
    pub const DEBIAS_TRAIN: &str = "debias_train";
    /// Remove the learned bias from one corrected clip.
    pub const DEBIAS_APPLY: &str = "debias_apply";
    /// Every kind, for metrics and documentation.
    pub const ALL: &[&str] = &[
        SYNTHESIZE,
        VAE,
        INTERACTION,
        TRACKER,
        VARIANT_TRACKER,
        CORRECT_ORIGINAL,
        CORRECT,
        DEBIAS_TRAIN,
        DEBIAS_APPLY,
    ];
}

/// `POST /internal/v1/jobs/claim`: ask for one runnable job.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ClaimRequest {
    /// Stable id of the worker process (shown in job listings and logs).
    pub worker_id: String,
    /// Job kinds this worker can run.
    pub kinds: Vec<String>,
    /// How long the coordinator may hold the request open waiting for work
    /// (long poll). The coordinator caps it.
    #[serde(default)]
    pub wait_ms: u64,
}

/// Answer to a claim: the job and the lease the worker now holds on it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ClaimedJob {
    pub id: Uuid,
    /// Lease token. Every claim of a job gets a new, larger epoch; every report
    /// about the job must carry it, and reports with an older epoch are rejected.
    pub epoch: i64,
    pub kind: String,
    /// 1 for the first run, 2 for the first retry, ...
    pub attempt: i32,
    /// The job's [`PipelineInput`].
    pub input: serde_json::Value,
    /// The lease expires this long after the last heartbeat.
    pub lease_ms: u64,
    /// How often the worker should heartbeat.
    pub heartbeat_ms: u64,
    /// Whether a previous attempt stored a checkpoint (fetch it with
    /// `GET /internal/v1/jobs/{id}/checkpoint?epoch=N`).
    pub has_checkpoint: bool,
    /// The outputs of the jobs this one depends on (all succeeded).
    #[serde(default)]
    pub deps: Vec<DepOutput>,
}

/// A finished input of a claimed job.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DepOutput {
    /// The dependency's key in the plan (`correct_original:walk`, `synthesize:walk`, ...).
    pub key: String,
    pub kind: String,
    /// Its [`JobOutput`].
    pub output: serde_json::Value,
}

/// `POST /internal/v1/jobs/{id}/heartbeat`: extend the lease, report progress.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HeartbeatRequest {
    pub epoch: i64,
    /// Fraction done, 0..=1.
    pub progress: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct HeartbeatReply {
    /// The job was cancelled: stop working on it and report nothing more.
    pub cancelled: bool,
}

/// `POST /internal/v1/jobs/{id}/complete`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CompleteRequest {
    pub epoch: i64,
    /// The job's [`JobOutput`].
    pub output: serde_json::Value,
}

/// `POST /internal/v1/jobs/{id}/fail`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FailRequest {
    pub epoch: i64,
    /// What went wrong, for the user (kept on the job).
    pub error: String,
    /// `false` when running the job again cannot help (bad input).
    pub retryable: bool,
}

/// `POST /internal/v1/jobs/{id}/release`: give a job back without using up an
/// attempt (graceful worker shutdown). Its checkpoint is kept.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ReleaseRequest {
    pub epoch: i64,
}

/// Source format of an uploaded clip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClipFormat {
    /// A BVH file (skeleton and motion in one).
    Bvh,
    /// An AMC motion with the ASF skeleton it was uploaded with.
    Amc,
    /// A clip motionaug wrote as NPZ (lossless or float32), fed back in.
    Npz,
}

/// Input of every job: one job of `pipeline::plan`, as planned at submission
/// (it carries its settings), and the stored source clips it reads.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PipelineInput {
    /// The planned job (key, `pipeline::JobKind` with its settings, deps and outputs by key).
    pub job: pipeline::PlannedJob,
    /// The clip the job is about, when there is one (shown with errors).
    pub clip_name: Option<String>,
    /// The stored source clips the job reads.
    pub clips: Vec<ClipRef>,
}

/// A stored source clip (read with `GET /internal/v1/clips/{id}/source` and `/skeleton`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ClipRef {
    pub clip_id: Uuid,
    pub clip_name: String,
    pub source_name: String,
    pub skeleton_name: Option<String>,
    pub format: ClipFormat,
}

/// A clip a job made for a later job (its correction, debiasing), stored
/// losslessly (`pipeline::encode_clip`) as the artifact `file`, which is not
/// part of the results.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WorkClip {
    pub name: String,
    pub file: String,
    /// Its manifest entry so far (`pipeline::ManifestEntry`).
    pub entry: serde_json::Value,
}

/// Output of every job kind.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct JobOutput {
    /// Manifest entries (`pipeline::ManifestEntry`) of the final outputs it made.
    pub manifest: Vec<serde_json::Value>,
    /// Artifacts that go into the results zip.
    pub files: Vec<String>,
    /// Clips made for later jobs.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clips: Vec<WorkClip>,
    /// Other artifacts for later jobs (correction checkpoints, the debiasing model).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub work: Vec<String>,
    /// Clips whose correction was not accepted: left out of the outputs (a
    /// rejected original still warm-starts its variants but gives no debiasing pair).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rejected: Vec<String>,
}

impl JobOutput {
    /// Every artifact the output names (all must have been uploaded by the job).
    pub fn all_files(&self) -> Vec<String> {
        let mut all = self.files.clone();
        all.extend(self.clips.iter().map(|c| c.file.clone()));
        all.extend(self.work.iter().cloned());
        all
    }
}

/// Checkpoint of a `synthesize` job: outputs `0..done` are uploaded, with their
/// manifest entries and file names, so a resumed attempt continues at `done`.
/// (A correction's checkpoint is instead a zip of its latest PPO checkpoint.)
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct SynthesizeCheckpoint {
    pub done: usize,
    pub manifest: Vec<serde_json::Value>,
    pub files: Vec<String>,
    /// Outputs kept for their correction instead (recipes with `[correct]`).
    #[serde(default)]
    pub clips: Vec<WorkClip>,
}

/// Names of the artifacts jobs store for later jobs, in one place: the worker
/// that writes them and the worker that reads them agree by construction.
pub mod artifacts {
    /// A clip kept for its next job: `work/<folder>/<name>.npz`.
    pub fn work_clip(folder: &str, name: &str) -> String {
        format!("work/{folder}/{name}.npz")
    }
    /// A source clip's corrected motion (`correct_original`).
    pub fn original_corrected(clip: &str) -> String {
        format!("work/originals/{clip}/corrected.npz")
    }
    /// A source clip's latest correction checkpoint, zipped (a warm start).
    pub fn original_checkpoints(clip: &str) -> String {
        format!("work/originals/{clip}/checkpoints.zip")
    }
    /// A source clip's correction report (`correct::Report`).
    pub fn original_report(clip: &str) -> String {
        format!("work/originals/{clip}/report.json")
    }
    /// A new clip's correction report; part of the results (the manifest names it).
    pub fn correction_report(clip: &str) -> String {
        format!("work/correct/{clip}/report.json")
    }
    /// A source clip's learning curve so far, while its correction trains
    /// (JSON `[[wall_s, samples, r_norm], ...]`; the viewer draws it live).
    pub fn original_curve(clip: &str) -> String {
        format!("work/originals/{clip}/curve.json")
    }
    /// A new clip's learning curve so far, while its correction trains.
    pub fn correction_curve(clip: &str) -> String {
        format!("work/correct/{clip}/curve.json")
    }
    /// The debiasing network, zipped.
    pub const DEBIAS_MODEL: &str = "work/debias/model.zip";
    /// A class tracker's latest checkpoint, zipped (every correction of the
    /// class starts from it).
    pub fn tracker_checkpoints(group: &str) -> String {
        format!("work/trackers/{group}/checkpoints.zip")
    }
    /// A class tracker's report (`correct::ClassReport`, `class.json`).
    pub fn tracker_report(group: &str) -> String {
        format!("work/trackers/{group}/class.json")
    }
    /// The class tracker's verdict on the class's new clips as is
    /// (`variant_tracker`; a `correct::ClassReport`).
    pub fn variant_judged(group: &str) -> String {
        format!("work/variant_trackers/{group}/judged.json")
    }
    /// The second tracker's latest checkpoint, zipped (when it was trained).
    pub fn variant_tracker_checkpoints(group: &str) -> String {
        format!("work/variant_trackers/{group}/checkpoints.zip")
    }
    /// The second tracker's report (when it was trained).
    pub fn variant_tracker_report(group: &str) -> String {
        format!("work/variant_trackers/{group}/class.json")
    }
}

#[cfg(test)]
mod tests {
    use super::kinds;

    /// Workers claim only the kinds they list: every kind a plan can hold
    /// must be one of them.
    #[test]
    fn every_planned_kind_is_a_kind_workers_claim() {
        let names: Vec<String> = [
            "HDM_bd_kickLFront1Reps_001_120",
            "18_01_shake_A",
            "18_01_shake_B",
        ]
        .map(String::from)
        .to_vec();
        let mut seen = std::collections::BTreeSet::new();
        for correct in [
            "policy = \"clip\"",
            "policy = \"class\"",
            "policy = \"class\"\nvariant_tracker_iterations = 1",
        ] {
            let recipe = pipeline::Recipe::from_toml_str(&format!(
                "[[ops]]\nop = \"mirror\"\n[vae]\nmin_clips = 1\n[interaction]\n\
                 [correct]\n{correct}\n[debias]\n"
            ))
            .expect("recipe");
            for job in pipeline::plan(&recipe, &names, 0).jobs {
                seen.insert(job.kind.name());
            }
        }
        for kind in &seen {
            assert!(kinds::ALL.contains(kind), "workers do not claim `{kind}`");
        }
        assert_eq!(seen.len(), kinds::ALL.len(), "{seen:?}");
    }
}
