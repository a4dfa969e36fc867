//! How position channels of a non-root joint are read, one rule shared by the
//! reader and the writer so that what the writer writes reads back the same.
//!
//! Exporters write a non-root joint's position channels in one of two ways:
//! *absolute*, the joint's local translation itself (the value repeats the
//! `OFFSET` when the joint holds still; Blender, three.js and MotionBuilder
//! read them so), or *relative*, a displacement added to the `OFFSET` (all
//! zeros when it holds still). A file does not say which, so the values
//! decide: they are absolute when they lie closer to the `OFFSET` than to zero
//! over the clip (sum of absolute differences on the joint's position axes,
//! ties absolute), else relative. When the `OFFSET` is zero both readings agree.

use glam::DVec3;

/// Whether position values `values` (one per frame, file units, on the axes
/// in `axes`) read as absolute translations against `offset`.
pub(super) fn reads_absolute(values: &[DVec3], offset: DVec3, axes: &[usize]) -> bool {
    let (to_offset, to_zero) = distances(values, offset, axes);
    to_offset <= to_zero
}

/// Sums over frames and `axes` of `|v - offset|` and `|v|`.
fn distances(values: &[DVec3], offset: DVec3, axes: &[usize]) -> (f64, f64) {
    let mut to_offset = 0.0;
    let mut to_zero = 0.0;
    for v in values {
        for &a in axes {
            to_offset += (v[a] - offset[a]).abs();
            to_zero += v[a].abs();
        }
    }
    (to_offset, to_zero)
}

/// The `OFFSET` (metres) to write for a joint whose translation track is
/// `values` (metres, all three axes written), given its rest offset `rest`,
/// lengths written times `scale`: the rest offset when the values clearly read
/// as absolute against it (beyond the 6-decimal rounding of the text), else
/// the per-axis median of the values when they clearly do against that (the
/// median is the offset they lie closest to), else zero, where both readings
/// agree.
pub(super) fn written_offset(values: &[DVec3], rest: DVec3, scale: f64) -> DVec3 {
    const AXES: [usize; 3] = [0, 1, 2];
    let scaled: Vec<DVec3> = values.iter().map(|v| *v * scale).collect();
    // Rounding to 6 decimals moves each difference by at most 1e-6 units.
    let margin = 4e-6 * (scaled.len() * 3) as f64;
    let clear = |offset: DVec3| {
        let (to_offset, to_zero) = distances(&scaled, offset * scale, &AXES);
        to_zero - to_offset > margin
    };
    if clear(rest) {
        return rest;
    }
    let median = DVec3::from_array(AXES.map(|a| {
        let mut xs: Vec<f64> = values.iter().map(|v| v[a]).collect();
        xs.sort_by(f64::total_cmp);
        xs.get(xs.len() / 2).copied().unwrap_or(0.0)
    }));
    if clear(median) { median } else { DVec3::ZERO }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_near_the_offset_are_absolute() {
        let offset = DVec3::new(0.0, -40.0, 0.0);
        let near = [DVec3::new(0.0, -39.0, 1.0), DVec3::new(0.0, -41.0, 0.0)];
        assert!(reads_absolute(&near, offset, &[0, 1, 2]));
        let small = [DVec3::new(0.0, 1.0, 0.0), DVec3::new(0.0, -1.0, 0.0)];
        assert!(!reads_absolute(&small, offset, &[0, 1, 2]));
        // Only the joint's own position axes count.
        assert!(reads_absolute(&small, offset, &[0, 2]));
    }

    #[test]
    fn written_offsets_read_back_as_absolute() {
        // The rest offset when it works, else the median, else zero.
        let rest = DVec3::new(0.0, 0.9, 0.0);
        let walk: Vec<DVec3> = (0..50)
            .map(|f| DVec3::new(f as f64 * 0.1, 0.9, 0.0))
            .collect();
        assert_eq!(written_offset(&walk, rest, 100.0), rest);
        let far: Vec<DVec3> = (0..50).map(|f| DVec3::new(3.0, f as f64, 0.0)).collect();
        let o = written_offset(&far, DVec3::new(0.0, -20.0, 0.0), 100.0);
        assert_eq!(o, DVec3::new(3.0, 25.0, 0.0));
        assert!(reads_absolute(&far, o, &[0, 1, 2]));
        let around_zero = [DVec3::new(-1.0, 0.0, 0.0), DVec3::new(1.0, 0.0, 0.0)];
        assert_eq!(
            written_offset(&around_zero, DVec3::new(0.5, 0.0, 0.0), 100.0),
            DVec3::ZERO
        );
    }
}
