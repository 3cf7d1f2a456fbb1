//! The CPU operands of the custom ops: f32 slices of contiguous storage, and the (B, C, ...)
//! layout helpers the per-channel ops share.

use candle_core::{CpuStorage, Layout, Result};

/// The f32 values of a contiguous CPU operand of campro's ops (`what` names the op in errors).
pub(crate) fn slice<'a>(s: &'a CpuStorage, l: &Layout, what: &str) -> Result<&'a [f32]> {
    let CpuStorage::F32(v) = s else { candle_core::bail!("{what}: f32 only") };
    let Some((a, b)) = l.contiguous_offsets() else { candle_core::bail!("{what}: contiguous operands only") };
    Ok(&v[a..b])
}

/// Per-plane values of a (B, C, ...) tensor (plane p is channel p mod C) summed per channel,
/// in f64.
pub(crate) fn per_channel(per_plane: impl IntoIterator<Item = f64>, c: usize) -> Vec<f64> {
    let mut out = vec![0f64; c];
    for (p, v) in per_plane.into_iter().enumerate() {
        out[p % c] += v;
    }
    out
}

/// (channels, plane size) of a (B, C, ...) tensor whose slopes number `slopes`.
pub(crate) fn plane(dims: &[usize], slopes: usize) -> Result<(usize, usize)> {
    match dims {
        [_, c, rest @ ..] if *c == slopes && *c > 0 => Ok((*c, rest.iter().product::<usize>().max(1))),
        _ => candle_core::bail!("prelu: x {dims:?} needs one slope per channel, got {slopes}"),
    }
}
