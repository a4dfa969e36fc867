//! The states of a job and of an augmentation, as named types.
//!
//! A job's state is stored in `jobs.state`, a `text` column whose CHECK constraint
//! lists exactly the names of [`JobState`]; an augmentation's state is never stored,
//! it is derived when it is read from its jobs' counts per state (kept in its row
//! by triggers on `jobs`, migration 0003). Every comparison, bind and
//! API answer goes through these enums, so a misspelt state cannot compile.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use sqlx::encode::IsNull;
use sqlx::error::BoxDynError;
use sqlx::postgres::{PgArgumentBuffer, PgHasArrayType, PgTypeInfo, PgValueRef};
use sqlx::{Decode, Encode, Postgres, Type};

/// A state name that is not one of the enum's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown state `{0}`")]
pub struct UnknownState(pub String);

/// Where a job is in its life (`jobs.state`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    /// Waiting for a worker (new, retried, released or returned by the reaper).
    Queued,
    /// Claimed by a worker that holds its lease.
    Running,
    /// Completed; its output is stored.
    Succeeded,
    /// Failed for good (attempts used up, a permanent error, or an input failed).
    Failed,
    /// Its augmentation was cancelled or its dataset deleted.
    Cancelled,
}

impl JobState {
    /// Every state, in the order metrics report them.
    pub const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Succeeded,
        JobState::Failed,
        JobState::Cancelled,
    ];

    /// The name stored in the database.
    pub const fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }
}

impl fmt::Display for JobState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for JobState {
    type Err = UnknownState;

    fn from_str(s: &str) -> Result<Self, UnknownState> {
        JobState::ALL
            .into_iter()
            .find(|state| state.as_str() == s)
            .ok_or_else(|| UnknownState(s.to_string()))
    }
}

/// Stored as its name in a `text` column.
impl Type<Postgres> for JobState {
    fn type_info() -> PgTypeInfo {
        <str as Type<Postgres>>::type_info()
    }

    fn compatible(ty: &PgTypeInfo) -> bool {
        <str as Type<Postgres>>::compatible(ty)
    }
}

/// Lets a query take a list of states (`state = ANY($1)`).
impl PgHasArrayType for JobState {
    fn array_type_info() -> PgTypeInfo {
        <&str as PgHasArrayType>::array_type_info()
    }
}

impl Encode<'_, Postgres> for JobState {
    fn encode_by_ref(&self, buf: &mut PgArgumentBuffer) -> Result<IsNull, BoxDynError> {
        <&str as Encode<Postgres>>::encode(self.as_str(), buf)
    }
}

impl<'r> Decode<'r, Postgres> for JobState {
    fn decode(value: PgValueRef<'r>) -> Result<Self, BoxDynError> {
        Ok(<&str as Decode<Postgres>>::decode(value)?.parse()?)
    }
}

/// How many of an augmentation's jobs are in each state.
#[derive(Debug, Default, Serialize, Clone, PartialEq, utoipa::ToSchema)]
pub struct JobCounts {
    pub total: i64,
    pub queued: i64,
    pub running: i64,
    pub succeeded: i64,
    pub failed: i64,
    pub cancelled: i64,
}

impl JobCounts {
    /// Counts `n` more jobs in `state`.
    pub fn add(&mut self, state: JobState, n: i64) {
        self.total += n;
        let count = match state {
            JobState::Queued => &mut self.queued,
            JobState::Running => &mut self.running,
            JobState::Succeeded => &mut self.succeeded,
            JobState::Failed => &mut self.failed,
            JobState::Cancelled => &mut self.cancelled,
        };
        *count += n;
    }
}

/// Where an augmentation is, derived from its jobs' states: `queued` (no job has
/// started), `running` (some job has started or ended, some is still to run),
/// `succeeded` (every job did: the results can be downloaded), `failed` (nothing
/// is left to run and some job failed), `cancelled` (by its owner).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum AugmentationState {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl AugmentationState {
    /// The name the API shows.
    pub const fn as_str(self) -> &'static str {
        match self {
            AugmentationState::Queued => "queued",
            AugmentationState::Running => "running",
            AugmentationState::Succeeded => "succeeded",
            AugmentationState::Failed => "failed",
            AugmentationState::Cancelled => "cancelled",
        }
    }

    /// Nothing will change any more.
    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            AugmentationState::Succeeded | AugmentationState::Failed | AugmentationState::Cancelled
        )
    }

    /// The state of an augmentation from its cancellation mark and its jobs' states.
    pub fn of_jobs(cancelled: bool, jobs: &JobCounts) -> Self {
        if cancelled {
            AugmentationState::Cancelled
        } else if jobs.succeeded == jobs.total {
            AugmentationState::Succeeded
        } else if jobs.queued + jobs.running == 0 {
            // Only failed and cancelled jobs are left unfinished.
            if jobs.failed > 0 {
                AugmentationState::Failed
            } else {
                AugmentationState::Cancelled
            }
        } else if jobs.running > 0 || jobs.succeeded > 0 || jobs.failed > 0 {
            AugmentationState::Running
        } else {
            AugmentationState::Queued
        }
    }
}

impl fmt::Display for AugmentationState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn job_states_round_trip_through_their_names() {
        for state in JobState::ALL {
            assert_eq!(state.as_str().parse::<JobState>(), Ok(state));
            assert_eq!(
                serde_json::to_value(state).unwrap(),
                serde_json::Value::from(state.as_str())
            );
        }
        assert_eq!("done".parse::<JobState>(), Err(UnknownState("done".into())));
    }

    #[test]
    fn augmentation_states_follow_their_jobs() {
        use AugmentationState::*;
        use JobState as J;
        let cases: [(bool, &[JobState], AugmentationState); 8] = [
            (true, &[J::Queued, J::Queued], Cancelled),
            (false, &[J::Queued, J::Queued], Queued),
            (false, &[J::Queued, J::Running], Running),
            (false, &[J::Queued, J::Succeeded], Running),
            (false, &[J::Queued, J::Failed], Running),
            (false, &[J::Succeeded, J::Succeeded], Succeeded),
            (false, &[J::Succeeded, J::Failed], Failed),
            // Every job cancelled without the mark (a deleted dataset's jobs).
            (false, &[J::Cancelled, J::Cancelled], Cancelled),
        ];
        for (cancelled, jobs, expected) in cases {
            let mut counts = JobCounts::default();
            for state in jobs {
                counts.add(*state, 1);
            }
            assert_eq!(counts.total, 2);
            let state = AugmentationState::of_jobs(cancelled, &counts);
            assert_eq!(state, expected, "{cancelled} {jobs:?}");
            assert_eq!(
                serde_json::to_value(state).unwrap(),
                serde_json::Value::from(state.as_str())
            );
        }
        assert!(Failed.is_terminal() && Succeeded.is_terminal() && Cancelled.is_terminal());
        assert!(!Queued.is_terminal() && !Running.is_terminal());
    }
}
