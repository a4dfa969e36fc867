//! Per-tenant quotas: what a tenant uses, and the checks that keep it within
//! [`Quotas`].
//!
//! A check and the insert it guards run in one transaction that first locks
//! the tenant's row ([`lock_tenant`]): two requests of one tenant (two uploads,
//! two new augmentations, on one coordinator or several) are checked one after
//! the other, each seeing what the other stored, so no interleaving can take
//! a tenant past a quota. Requests of different tenants do not wait for each
//! other.

use serde::Serialize;
use sqlx::{Postgres, Transaction};
use utoipa::ToSchema;
use uuid::Uuid;

use crate::configuration::Quotas;
use crate::error::ApiError;

/// What a tenant uses now.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, ToSchema, sqlx::FromRow)]
pub struct Usage {
    /// Augmentations with jobs still queued or running (not cancelled).
    pub active_augmentations: i64,
    /// Correction budget of those augmentations, seconds.
    pub correction_seconds: f64,
    /// Uploaded files, results and checkpoints, bytes.
    pub stored_bytes: i64,
}

/// Takes the tenant's row lock until the transaction ends.
pub async fn lock_tenant(
    tx: &mut Transaction<'_, Postgres>,
    tenant_id: Uuid,
) -> Result<(), sqlx::Error> {
    sqlx::query("SELECT 1 FROM tenants WHERE id = $1 FOR UPDATE")
        .bind(tenant_id)
        .execute(&mut **tx)
        .await?;
    Ok(())
}

/// The tenant's usage, read with `db` (a transaction holding the tenant's lock
/// when it guards an insert).
pub async fn usage<'e>(
    db: impl sqlx::PgExecutor<'e>,
    tenant_id: Uuid,
) -> Result<Usage, sqlx::Error> {
    // `octet_length` of a stored bytea reads its size without fetching it.
    sqlx::query_as(
        "WITH active AS (
             SELECT correction_seconds FROM augmentations
             WHERE tenant_id = $1 AND cancelled_at IS NULL AND jobs_queued + jobs_running > 0)
         SELECT (SELECT count(*) FROM active) AS active_augmentations,
                (SELECT COALESCE(sum(correction_seconds), 0)::float8 FROM active)
                    AS correction_seconds,
                ((SELECT COALESCE(sum(octet_length(c.source) + COALESCE(octet_length(c.skeleton), 0)), 0)
                  FROM clips c JOIN datasets d ON d.id = c.dataset_id WHERE d.tenant_id = $1)
                 + (SELECT COALESCE(sum(octet_length(a.content)), 0)
                    FROM artifacts a JOIN augmentations g ON g.id = a.augmentation_id
                    WHERE g.tenant_id = $1)
                 + (SELECT COALESCE(sum(octet_length(j.checkpoint)), 0)
                    FROM jobs j JOIN augmentations g ON g.id = j.augmentation_id
                    WHERE g.tenant_id = $1 AND j.checkpoint IS NOT NULL))::int8 AS stored_bytes",
    )
    .bind(tenant_id)
    .fetch_one(db)
    .await
}

/// An augmentation that makes `outputs` clips and needs `correction_seconds`
/// of correction budget, on its own (before any database work): 422.
pub fn check_augmentation_size(
    quotas: &Quotas,
    outputs: u64,
    correction_seconds: f64,
) -> Result<(), ApiError> {
    if outputs > quotas.outputs_per_augmentation {
        return Err(ApiError::unprocessable(format!(
            "recipe: makes {outputs} clips from this dataset; an augmentation may make at most \
             {} (quota outputs_per_augmentation): use fewer copies or ops, or a smaller dataset",
            quotas.outputs_per_augmentation
        ))
        .with_file("recipe")
        .with_limit("outputs_per_augmentation", quotas.outputs_per_augmentation));
    }
    if correction_seconds > quotas.correction_seconds as f64 {
        return Err(ApiError::unprocessable(format!(
            "recipe: needs {correction_seconds} s of correction (its correction jobs x \
             [correct] time_budget_s); a tenant's unfinished augmentations may use at most {} s \
             together (quota correction_seconds): lower time_budget_s or make fewer clips",
            quotas.correction_seconds
        ))
        .with_file("recipe")
        .with_limit("correction_seconds", quotas.correction_seconds));
    }
    Ok(())
}

/// One more augmentation needing `correction_seconds`, against what the tenant
/// uses: 429 naming the quota it would pass.
pub fn check_new_augmentation(
    quotas: &Quotas,
    usage: &Usage,
    correction_seconds: f64,
) -> Result<(), ApiError> {
    if usage.active_augmentations as u64 >= quotas.active_augmentations {
        return Err(ApiError::too_many(format!(
            "{} augmentations are unfinished, the most a tenant may have at once (quota \
             active_augmentations); wait for one to end or cancel one",
            usage.active_augmentations
        ))
        .with_limit("active_augmentations", quotas.active_augmentations));
    }
    if usage.correction_seconds + correction_seconds > quotas.correction_seconds as f64 {
        return Err(ApiError::too_many(format!(
            "this augmentation needs {correction_seconds} s of correction and unfinished ones \
             hold {} s of the {} s a tenant may use at once (quota correction_seconds); wait \
             for one to end or cancel one",
            usage.correction_seconds, quotas.correction_seconds
        ))
        .with_limit("correction_seconds", quotas.correction_seconds));
    }
    check_stored(quotas, usage, 0)
}

/// Storing `new_bytes` more (0: anything at all), against what the tenant
/// stores: 429 naming the quota.
pub fn check_stored(quotas: &Quotas, usage: &Usage, new_bytes: u64) -> Result<(), ApiError> {
    let used = usage.stored_bytes.max(0) as u64;
    let over = if new_bytes == 0 {
        used >= quotas.stored_bytes
    } else {
        used.saturating_add(new_bytes) > quotas.stored_bytes
    };
    if over {
        return Err(ApiError::too_many(format!(
            "the tenant stores {used} bytes{}; at most {} may be stored (quota stored_bytes): \
             delete datasets you no longer need (their results go with them)",
            if new_bytes > 0 {
                format!(" and this upload adds {new_bytes}")
            } else {
                String::new()
            },
            quotas.stored_bytes
        ))
        .with_limit("stored_bytes", quotas.stored_bytes));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quotas_name_the_limit_they_refuse() {
        let quotas = Quotas {
            outputs_per_augmentation: 10,
            active_augmentations: 2,
            correction_seconds: 100,
            stored_bytes: 1000,
        };
        let limit = |r: Result<(), ApiError>| r.unwrap_err().0.limit;
        assert!(check_augmentation_size(&quotas, 10, 100.0).is_ok());
        assert_eq!(
            limit(check_augmentation_size(&quotas, 11, 0.0)),
            Some("outputs_per_augmentation")
        );
        assert_eq!(
            limit(check_augmentation_size(&quotas, 1, 101.0)),
            Some("correction_seconds")
        );
        let mut usage = Usage {
            active_augmentations: 1,
            correction_seconds: 40.0,
            stored_bytes: 999,
        };
        assert!(check_new_augmentation(&quotas, &usage, 60.0).is_ok());
        assert_eq!(
            limit(check_new_augmentation(&quotas, &usage, 61.0)),
            Some("correction_seconds")
        );
        usage.active_augmentations = 2;
        assert_eq!(
            limit(check_new_augmentation(&quotas, &usage, 0.0)),
            Some("active_augmentations")
        );
        assert!(check_stored(&quotas, &usage, 1).is_ok());
        assert_eq!(
            limit(check_stored(&quotas, &usage, 2)),
            Some("stored_bytes")
        );
        usage.stored_bytes = 1000;
        assert_eq!(
            limit(check_stored(&quotas, &usage, 0)),
            Some("stored_bytes")
        );
    }
}
