//! Bounded memory for uploads: how many are read at once, and how many bytes
//! all of them may hold together.
//!
//! An upload is held in memory while it is checked (every file is parsed
//! before anything is stored). Without a bound, a few small zips that unpack to
//! gigabytes each (zip bombs) would take the process's memory with them. So:
//!
//! * at most `MOTIONAUG_MAX_CONCURRENT_UPLOADS` uploads are read at once (the
//!   others wait before their body is read, holding nothing);
//! * every byte an upload holds (its request body as it streams in, each zip
//!   entry as it is inflated) is first reserved from one budget of
//!   `MOTIONAUG_UPLOAD_MEMORY_BYTES` for the whole process, in the capacity the
//!   buffer really allocates. A zip entry is refused the moment its expanded
//!   bytes pass the upload's unpacked limit (413), before more is inflated; an
//!   upload that finds the budget taken by others is refused with 503 (try
//!   again), one that alone needs more than the whole budget with 413.
//!
//! The reservation is released when the upload's request ends (its files
//! stored or refused).

use std::sync::Arc;

use axum::http::StatusCode;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::error::ApiError;

/// Reservations are counted in KiB (semaphore permits are `u32`).
const UNIT: u64 = 1024;

/// The process's upload slots and memory budget (cloned into every handler).
#[derive(Clone, Debug)]
pub struct UploadMemory {
    slots: Arc<Semaphore>,
    budget: Arc<Semaphore>,
    budget_bytes: u64,
}

impl UploadMemory {
    pub fn new(concurrent_uploads: usize, budget_bytes: u64) -> Self {
        let units = (budget_bytes / UNIT).clamp(1, Semaphore::MAX_PERMITS as u64) as usize;
        UploadMemory {
            slots: Arc::new(Semaphore::new(concurrent_uploads.max(1))),
            budget: Arc::new(Semaphore::new(units)),
            budget_bytes,
        }
    }

    /// Waits for an upload slot; the upload's reservation starts empty.
    pub async fn start(&self) -> Reservation {
        // The semaphore is never closed.
        let slot = self.slots.clone().acquire_owned().await.ok();
        Reservation {
            memory: self.clone(),
            _slot: slot,
            held: None,
            units: 0,
        }
    }
}

/// What one upload holds: its slot and the memory it reserved.
#[derive(Debug)]
pub struct Reservation {
    memory: UploadMemory,
    _slot: Option<OwnedSemaphorePermit>,
    held: Option<OwnedSemaphorePermit>,
    units: u64,
}

impl Reservation {
    /// Reserves `bytes` more, without waiting.
    pub fn grow(&mut self, bytes: u64) -> Result<(), ApiError> {
        let units = bytes.div_ceil(UNIT);
        if units == 0 {
            return Ok(());
        }
        let total = (self.units + units) * UNIT;
        if total > self.memory.budget_bytes {
            return Err(ApiError::too_large(format!(
                "the upload needs more than the {} bytes of memory the coordinator gives \
                 uploads (MOTIONAUG_UPLOAD_MEMORY_BYTES); send it in smaller parts",
                self.memory.budget_bytes
            )));
        }
        let permit = u32::try_from(units)
            .ok()
            .and_then(|n| self.memory.budget.clone().try_acquire_many_owned(n).ok())
            .ok_or_else(|| {
                ApiError::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "Busy",
                    "other uploads hold the memory the coordinator gives uploads; try again \
                     in a few seconds",
                )
            })?;
        match &mut self.held {
            Some(held) => held.merge(permit),
            None => self.held = Some(permit),
        }
        self.units += units;
        Ok(())
    }

    /// Bytes reserved so far.
    pub fn bytes(&self) -> u64 {
        self.units * UNIT
    }
}

/// Appends `data` to `buf`, reserving what the buffer's growth allocates
/// first. `cap` is the most this buffer may ever hold (its limit plus one, so
/// passing the limit is seen): growth never allocates past it.
pub fn append(
    buf: &mut Vec<u8>,
    data: &[u8],
    cap: usize,
    reservation: &mut Reservation,
) -> Result<(), ApiError> {
    let needed = buf.len() + data.len();
    if needed > buf.capacity() {
        let target = needed.max(buf.capacity().saturating_mul(2)).max(64 << 10);
        let target = target.min(cap.max(needed));
        reservation.grow((target - buf.capacity()) as u64)?;
        buf.reserve_exact(target - buf.len());
    }
    buf.extend_from_slice(data);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn reservations_share_one_budget_and_are_released() {
        let memory = UploadMemory::new(2, 1 << 20);
        let mut a = memory.start().await;
        let mut b = memory.start().await;
        a.grow(700 << 10).unwrap();
        // Taken by the other upload: busy, try again.
        let busy = b.grow(400 << 10).unwrap_err();
        assert_eq!(busy.status(), StatusCode::SERVICE_UNAVAILABLE);
        // More than the whole budget: too large, whatever the others hold.
        let huge = b.grow(2 << 20).unwrap_err();
        assert_eq!(huge.status(), StatusCode::PAYLOAD_TOO_LARGE);
        drop(a);
        b.grow(1 << 20).unwrap();
        assert_eq!(b.bytes(), 1 << 20);
    }

    #[tokio::test]
    async fn appending_reserves_the_capacity_and_stops_at_the_cap() {
        let memory = UploadMemory::new(1, 4 << 20);
        let mut r = memory.start().await;
        let mut buf = Vec::new();
        let chunk = vec![7u8; 10_000];
        for _ in 0..100 {
            append(&mut buf, &chunk, 1_000_001, &mut r).unwrap();
        }
        assert_eq!(buf.len(), 1_000_000);
        assert!(buf.capacity() <= 1_000_001);
        assert!(r.bytes() >= buf.capacity() as u64);
        assert!(r.bytes() <= buf.capacity() as u64 + 5 * 1024);
    }
}
