//! What the workspace's hand-written candle ops share (nn's bias add, the
//! VAE's LSTM recurrence and 3x3 products): reading an f32 CPU input through
//! its layout.

use candle_core::{CpuStorage, Layout};

/// The f32 values of a contiguous CPU op input; `what` names the input in
/// the error (`op: what must be contiguous`).
pub fn f32_slice<'a>(
    s: &'a CpuStorage,
    l: &Layout,
    op: &str,
    what: &str,
) -> candle_core::Result<&'a [f32]> {
    let data = s.as_slice::<f32>()?;
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&data[a..b]),
        None => candle_core::bail!("{op}: {what} must be contiguous"),
    }
}
