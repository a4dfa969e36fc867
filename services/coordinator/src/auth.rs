//! Authentication: tenant API keys for `/v1` and the shared worker token for
//! `/internal/v1`.
//!
//! An API key is `mak_` followed by 64 hex digits (32 random bytes). Only its
//! SHA-256 is stored; looking a key up is one indexed query on the hash, and
//! a key found is remembered for [`KEY_CACHE_TTL`] ([`KeyCache`]), so a client
//! polling a status costs one query per poll, not two.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::extract::FromRequestParts;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;
use rand::RngCore;
use sha2::{Digest, Sha256};
use sqlx::PgPool;
use uuid::Uuid;

use crate::error::ApiError;
use crate::startup::AppState;

/// The tenant whose key authenticated the request.
#[derive(Debug, Clone)]
pub struct Tenant {
    pub id: Uuid,
    pub name: String,
}

/// How long a looked-up key is trusted without asking the database again
/// (a revoked key works for at most this long on each coordinator).
pub const KEY_CACHE_TTL: Duration = Duration::from_secs(10);

/// Keys remembered at most (the cache is emptied when full).
const KEY_CACHE_SIZE: usize = 10_000;

/// Key hash -> the tenant and when it was looked up.
type KeyMap = HashMap<Vec<u8>, (Tenant, Instant)>;

/// Recently looked-up keys.
#[derive(Debug, Clone, Default)]
pub struct KeyCache(Arc<Mutex<KeyMap>>);

impl KeyCache {
    fn get(&self, hash: &[u8]) -> Option<Tenant> {
        let cache = self.0.lock().ok()?;
        let (tenant, at) = cache.get(hash)?;
        (at.elapsed() < KEY_CACHE_TTL).then(|| tenant.clone())
    }

    fn put(&self, hash: Vec<u8>, tenant: &Tenant) {
        if let Ok(mut cache) = self.0.lock() {
            if cache.len() >= KEY_CACHE_SIZE {
                cache.clear();
            }
            cache.insert(hash, (tenant.clone(), Instant::now()));
        }
    }
}

/// Marker: the request carried the worker token.
#[derive(Debug, Clone, Copy)]
pub struct Worker;

pub fn hash_key(key: &str) -> Vec<u8> {
    Sha256::digest(key.as_bytes()).to_vec()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A new random API key (shown to the user once).
pub fn generate_key() -> String {
    let mut bytes = [0u8; 32];
    rand::rng().fill_bytes(&mut bytes);
    format!("mak_{}", hex(&bytes))
}

/// Creates the tenant if needed and a new key for it; returns the key.
pub async fn create_key(db: &PgPool, tenant: &str) -> anyhow::Result<String> {
    let tenant = tenant.trim();
    anyhow::ensure!(
        !tenant.is_empty() && tenant.len() <= 200,
        "tenant name must be 1 to 200 characters"
    );
    let mut tx = db.begin().await?;
    let tenant_id: Uuid = sqlx::query_scalar(
        "INSERT INTO tenants (id, name) VALUES ($1, $2)
         ON CONFLICT (name) DO UPDATE SET name = EXCLUDED.name RETURNING id",
    )
    .bind(Uuid::new_v4())
    .bind(tenant)
    .fetch_one(&mut *tx)
    .await?;
    let key = generate_key();
    sqlx::query("INSERT INTO api_keys (id, tenant_id, key_hash, prefix) VALUES ($1, $2, $3, $4)")
        .bind(Uuid::new_v4())
        .bind(tenant_id)
        .bind(hash_key(&key))
        .bind(&key[..12])
        .execute(&mut *tx)
        .await?;
    tx.commit().await?;
    Ok(key)
}

fn bearer(parts: &Parts) -> Option<&str> {
    let value = parts.headers.get(AUTHORIZATION)?.to_str().ok()?;
    let (scheme, token) = value.split_once(' ')?;
    scheme.eq_ignore_ascii_case("bearer").then(|| token.trim())
}

/// Compares without an early exit so the time taken does not reveal a prefix.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

impl FromRequestParts<AppState> for Tenant {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let key = bearer(parts).ok_or_else(|| {
            ApiError::unauthorized("send your API key as `Authorization: Bearer <key>`")
        })?;
        let hash = hash_key(key);
        if let Some(tenant) = state.keys.get(&hash) {
            return Ok(tenant);
        }
        let row: Option<(Uuid, String)> = sqlx::query_as(
            "SELECT t.id, t.name FROM api_keys k JOIN tenants t ON t.id = k.tenant_id
             WHERE k.key_hash = $1 AND k.revoked_at IS NULL",
        )
        .bind(&hash)
        .fetch_optional(&state.db)
        .await?;
        let (id, name) = row.ok_or_else(|| ApiError::unauthorized("unknown or revoked API key"))?;
        let tenant = Tenant { id, name };
        state.keys.put(hash, &tenant);
        Ok(tenant)
    }
}

impl FromRequestParts<AppState> for Worker {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        match bearer(parts) {
            Some(token)
                if constant_time_eq(token.as_bytes(), state.config.worker_token.as_bytes()) =>
            {
                Ok(Worker)
            }
            _ => Err(ApiError::unauthorized("this route needs the worker token")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_are_random_and_hash_to_32_bytes() {
        let a = generate_key();
        let b = generate_key();
        assert_ne!(a, b);
        assert_eq!(a.len(), 4 + 64);
        assert_eq!(hash_key(&a).len(), 32);
        assert_ne!(hash_key(&a), hash_key(&b));
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"abc", b"ab"));
    }
}
