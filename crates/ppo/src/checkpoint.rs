//! Checkpoint files: one directory per checkpoint, `ckpt-<iteration>-<millis>/` holding
//! `tensors.safetensors` (networks, optimiser moments, normaliser statistics, all exact)
//! and `state.json` (configuration, counters, curve, RNG state). A checkpoint is written
//! into a temporary directory, its files fsynced, then renamed into place, and the file
//! `LATEST` (also replaced atomically) names it; a crash at any point leaves the previous
//! checkpoint intact. Older checkpoints beyond the few most recent are removed.

use std::collections::HashMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use crate::config::PpoConfig;
use crate::env::EnvRng;
use crate::error::{PpoError, Result};
use crate::trainer::Progress;

pub const TENSORS_FILE: &str = "tensors.safetensors";
pub const STATE_FILE: &str = "state.json";
pub const LATEST_FILE: &str = "LATEST";
const FORMAT: u32 = 1;

/// Exact state of a ChaCha generator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RngState {
    pub seed_hex: String,
    pub stream: u64,
    /// u128 as a decimal string (JSON numbers are not safe beyond 2^53).
    pub word_pos: String,
}

impl RngState {
    pub fn capture(rng: &EnvRng) -> Self {
        let seed_hex = rng.get_seed().iter().map(|b| format!("{b:02x}")).collect();
        RngState {
            seed_hex,
            stream: rng.get_stream(),
            word_pos: rng.get_word_pos().to_string(),
        }
    }

    pub fn restore(&self) -> std::result::Result<EnvRng, String> {
        let hex = self.seed_hex.as_bytes();
        if hex.len() != 64 {
            return Err(format!("rng seed must be 64 hex digits, got {}", hex.len()));
        }
        let mut seed = [0u8; 32];
        for (i, b) in seed.iter_mut().enumerate() {
            let s = std::str::from_utf8(&hex[2 * i..2 * i + 2]).map_err(|e| e.to_string())?;
            *b = u8::from_str_radix(s, 16).map_err(|e| format!("rng seed: {e}"))?;
        }
        let word_pos: u128 = self
            .word_pos
            .parse()
            .map_err(|e| format!("rng word_pos `{}`: {e}", self.word_pos))?;
        let mut rng = EnvRng::from_seed(seed);
        rng.set_stream(self.stream);
        rng.set_word_pos(word_pos);
        Ok(rng)
    }
}

/// Everything in `state.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CheckpointMeta {
    pub format: u32,
    pub obs_dim: usize,
    pub act_dim: usize,
    pub config: PpoConfig,
    pub progress: Progress,
    pub rng: RngState,
    pub policy_opt_steps: u64,
    pub value_opt_steps: u64,
}

impl CheckpointMeta {
    pub fn new(
        obs_dim: usize,
        act_dim: usize,
        config: PpoConfig,
        progress: Progress,
        rng: &EnvRng,
        policy_opt_steps: u64,
        value_opt_steps: u64,
    ) -> Self {
        CheckpointMeta {
            format: FORMAT,
            obs_dim,
            act_dim,
            config,
            progress,
            rng: RngState::capture(rng),
            policy_opt_steps,
            value_opt_steps,
        }
    }
}

fn sync_dir(dir: &Path) -> Result<()> {
    fs::File::open(dir)
        .and_then(|f| f.sync_all())
        .map_err(|e| PpoError::io(dir, e))
}

fn write_synced(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut f = fs::File::create(path).map_err(|e| PpoError::io(path, e))?;
    f.write_all(bytes).map_err(|e| PpoError::io(path, e))?;
    f.sync_all().map_err(|e| PpoError::io(path, e))
}

/// Write a checkpoint under `dir`, point `LATEST` at it and keep the `keep` newest.
pub fn save(
    dir: &Path,
    meta: &CheckpointMeta,
    tensors: &[(String, Tensor)],
    keep: usize,
) -> Result<PathBuf> {
    fs::create_dir_all(dir).map_err(|e| PpoError::io(dir, e))?;
    let millis = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis())
        .unwrap_or(0);
    let name = format!("ckpt-{:08}-{millis:013}", meta.progress.iterations);
    let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
    if tmp.exists() {
        fs::remove_dir_all(&tmp).map_err(|e| PpoError::io(&tmp, e))?;
    }
    fs::create_dir(&tmp).map_err(|e| PpoError::io(&tmp, e))?;
    let bytes = safetensors::serialize(tensors.iter().map(|(n, t)| (n.as_str(), t)), None)
        .map_err(|e| PpoError::checkpoint(&tmp, format!("serialising tensors: {e}")))?;
    write_synced(&tmp.join(TENSORS_FILE), &bytes)?;
    let json = serde_json::to_vec_pretty(meta)
        .map_err(|e| PpoError::checkpoint(&tmp, format!("serialising state: {e}")))?;
    write_synced(&tmp.join(STATE_FILE), &json)?;
    sync_dir(&tmp)?;
    let final_dir = dir.join(&name);
    fs::rename(&tmp, &final_dir).map_err(|e| PpoError::io(&final_dir, e))?;
    sync_dir(dir)?;
    let latest_tmp = dir.join(format!(".{LATEST_FILE}.tmp{}", std::process::id()));
    write_synced(&latest_tmp, name.as_bytes())?;
    fs::rename(&latest_tmp, dir.join(LATEST_FILE))
        .map_err(|e| PpoError::io(dir.join(LATEST_FILE), e))?;
    sync_dir(dir)?;
    prune(dir, &name, keep.max(1))?;
    tracing::debug!(checkpoint = %final_dir.display(), "checkpoint written");
    Ok(final_dir)
}

fn checkpoint_dirs(dir: &Path) -> Result<Vec<String>> {
    let mut names = Vec::new();
    for entry in fs::read_dir(dir).map_err(|e| PpoError::io(dir, e))? {
        let entry = entry.map_err(|e| PpoError::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with("ckpt-") && entry.path().is_dir() {
            names.push(name);
        }
    }
    names.sort();
    Ok(names)
}

fn prune(dir: &Path, current: &str, keep: usize) -> Result<()> {
    // Temporary directories left by a crash in the middle of a save.
    for entry in fs::read_dir(dir).map_err(|e| PpoError::io(dir, e))? {
        let entry = entry.map_err(|e| PpoError::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with(".ckpt-") && name.contains(".tmp") && entry.path().is_dir() {
            fs::remove_dir_all(entry.path()).map_err(|e| PpoError::io(entry.path(), e))?;
        }
    }
    let names = checkpoint_dirs(dir)?;
    let excess = names.len().saturating_sub(keep);
    for name in names.iter().take(excess).filter(|n| n.as_str() != current) {
        let p = dir.join(name);
        fs::remove_dir_all(&p).map_err(|e| PpoError::io(&p, e))?;
    }
    Ok(())
}

fn complete(path: &Path) -> bool {
    path.join(TENSORS_FILE).is_file() && path.join(STATE_FILE).is_file()
}

/// The checkpoint to resume from: the one `LATEST` names, or else the newest complete
/// `ckpt-*` directory. `None` when `dir` has none (or does not exist).
pub fn latest_checkpoint(dir: &Path) -> Result<Option<PathBuf>> {
    if !dir.exists() {
        return Ok(None);
    }
    if let Ok(name) = fs::read_to_string(dir.join(LATEST_FILE)) {
        let p = dir.join(name.trim());
        if complete(&p) {
            return Ok(Some(p));
        }
    }
    Ok(checkpoint_dirs(dir)?
        .into_iter()
        .rev()
        .map(|n| dir.join(n))
        .find(|p| complete(p)))
}

/// Read one checkpoint directory.
pub fn load(path: &Path) -> Result<(CheckpointMeta, HashMap<String, Tensor>)> {
    let state_path = path.join(STATE_FILE);
    let json = fs::read(&state_path).map_err(|e| PpoError::io(&state_path, e))?;
    let meta: CheckpointMeta = serde_json::from_slice(&json)
        .map_err(|e| PpoError::checkpoint(&state_path, format!("bad state: {e}")))?;
    if meta.format != FORMAT {
        return Err(PpoError::checkpoint(
            &state_path,
            format!(
                "format {} is not supported (expected {FORMAT})",
                meta.format
            ),
        ));
    }
    let tensors_path = path.join(TENSORS_FILE);
    let bytes = fs::read(&tensors_path).map_err(|e| PpoError::io(&tensors_path, e))?;
    let tensors = candle_core::safetensors::load_buffer(&bytes, &Device::Cpu)
        .map_err(|e| PpoError::checkpoint(&tensors_path, format!("bad tensors: {e}")))?;
    Ok((meta, tensors))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta(iterations: u64) -> CheckpointMeta {
        let progress = Progress {
            iterations,
            ..Progress::default()
        };
        let rng = EnvRng::seed_from_u64(9);
        CheckpointMeta::new(2, 1, PpoConfig::default(), progress, &rng, 0, 0)
    }

    #[test]
    fn rng_state_round_trips() {
        use rand::RngCore;
        let mut rng = EnvRng::seed_from_u64(42);
        for _ in 0..13 {
            rng.next_u32();
        }
        let mut back = RngState::capture(&rng).restore().unwrap();
        assert_eq!(rng.next_u64(), back.next_u64());
        let bad = RngState {
            seed_hex: "zz".into(),
            stream: 0,
            word_pos: "0".into(),
        };
        assert!(bad.restore().is_err());
    }

    #[test]
    fn latest_falls_back_to_newest_complete_checkpoint() {
        let dir = std::env::temp_dir().join(format!("ppo-ckpt-unit-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        assert_eq!(latest_checkpoint(&dir).unwrap(), None);
        let t = vec![(
            "x".to_string(),
            Tensor::from_slice(&[1.0f32, 2.0], 2, &Device::Cpu).unwrap(),
        )];
        let first = save(&dir, &meta(1), &t, 5).unwrap();
        let second = save(&dir, &meta(2), &t, 5).unwrap();
        assert_eq!(latest_checkpoint(&dir).unwrap(), Some(second.clone()));
        let (m, tensors) = load(&second).unwrap();
        assert_eq!(m.progress.iterations, 2);
        assert_eq!(tensors["x"].to_vec1::<f32>().unwrap(), vec![1.0, 2.0]);
        // A crash that left a half-written newer checkpoint and a stale LATEST.
        fs::create_dir(dir.join("ckpt-99999999-0000000000000")).unwrap();
        fs::write(dir.join(LATEST_FILE), "ckpt-missing").unwrap();
        fs::remove_dir_all(&second).unwrap();
        assert_eq!(latest_checkpoint(&dir).unwrap(), Some(first.clone()));
        // A corrupt state file is an error naming the file.
        fs::write(first.join(STATE_FILE), "{").unwrap();
        let err = load(&first).err().unwrap().to_string();
        assert!(err.contains(STATE_FILE), "{err}");
        fs::remove_dir_all(&dir).unwrap();
    }
}

#[cfg(test)]
mod float_tests {
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn json_floats_round_trip_exactly(x in proptest::num::f64::NORMAL) {
            let s = serde_json::to_string(&x).unwrap();
            let back: f64 = serde_json::from_str(&s).unwrap();
            prop_assert_eq!(back.to_bits(), x.to_bits());
        }
    }
}
