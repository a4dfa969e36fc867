//! Length units of mocap files and the guess used when a BVH file does not say.
//!
//! BVH files carry no unit. Exporters write metres, centimetres, millimetres,
//! inches (the CMU BVH conversions) or feet, and nothing in the file tells them
//! apart, so the reader takes a [`Unit`] from the caller, or guesses it
//! ([`Unit::Auto`], see [`guess_unit`]).

use std::fmt;
use std::str::FromStr;

use glam::DVec3;

use crate::skeleton::Skeleton;

/// Length unit of a BVH file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Unit {
    Metres,
    Centimetres,
    Millimetres,
    Inches,
    Feet,
    /// 1/0.45 inch = 5.644 cm: the ASF length unit of CMU and HDM05 skeletons
    /// (`:units length 0.45`), which the widely used CMU BVH conversions keep.
    /// (Those files are sometimes said to be in inches, but their hips are
    /// 17 units high and the two subjects of the CMU pair clips stand 15 units
    /// apart where the capture notes say 0.83 m: only this unit fits.)
    CmuAsf,
    /// Guess from the body size of the rest pose, see [`guess_unit`].
    #[default]
    Auto,
}

/// The concrete units, in the order ties are broken.
pub const CONCRETE_UNITS: [Unit; 6] = [
    Unit::Metres,
    Unit::Centimetres,
    Unit::Millimetres,
    Unit::Inches,
    Unit::Feet,
    Unit::CmuAsf,
];

/// Body size the unit guess aims for, metres (an adult, standing).
pub const HUMAN_SIZE_M: f64 = 1.7;

impl Unit {
    /// Metres per file unit; `None` for [`Unit::Auto`].
    pub fn metres(self) -> Option<f64> {
        match self {
            Unit::Metres => Some(1.0),
            Unit::Centimetres => Some(0.01),
            Unit::Millimetres => Some(0.001),
            Unit::Inches => Some(0.0254),
            Unit::Feet => Some(0.3048),
            Unit::CmuAsf => Some(0.0254 / 0.45),
            Unit::Auto => None,
        }
    }

    /// The concrete unit whose scale is `metres_per_unit` (relative tolerance 1e-9).
    pub fn from_metres(metres_per_unit: f64) -> Option<Unit> {
        CONCRETE_UNITS.into_iter().find(|u| {
            u.metres()
                .is_some_and(|m| ((m - metres_per_unit) / m).abs() < 1e-9)
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Unit::Metres => "m",
            Unit::Centimetres => "cm",
            Unit::Millimetres => "mm",
            Unit::Inches => "in",
            Unit::Feet => "ft",
            Unit::CmuAsf => "cmu",
            Unit::Auto => "auto",
        }
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Unit {
    type Err = String;

    /// Accepts `m`, `cm`, `mm`, `in`, `ft`, `cmu` (1/0.45 inch), `auto` and the
    /// spelled-out names.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s.trim().to_ascii_lowercase().as_str() {
            "m" | "metre" | "metres" | "meter" | "meters" => Unit::Metres,
            "cm" | "centimetre" | "centimetres" | "centimeter" | "centimeters" => Unit::Centimetres,
            "mm" | "millimetre" | "millimetres" | "millimeter" | "millimeters" => Unit::Millimetres,
            "in" | "inch" | "inches" => Unit::Inches,
            "ft" | "foot" | "feet" => Unit::Feet,
            "cmu" | "asf" => Unit::CmuAsf,
            "auto" => Unit::Auto,
            other => {
                return Err(format!(
                    "unknown length unit `{other}` (expected m, cm, mm, in, ft, cmu or auto)"
                ));
            }
        })
    }
}

/// Body size of a rest pose in file units: the largest side of the bounding box
/// of every joint and end site. Standing upright this is the body height; in a
/// T-pose the arm span, which for people is about the height too; it does not
/// depend on which axis the file uses as up.
pub fn rest_size(skeleton: &Skeleton) -> f64 {
    rest_size_of(skeleton, |_| true)
}

/// [`rest_size`] of the joints `include` picks (a static root far from the
/// body it holds is not part of the body).
pub fn rest_size_of(skeleton: &Skeleton, include: impl Fn(usize) -> bool) -> f64 {
    let positions = skeleton.rest_positions();
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for (i, p) in positions.iter().enumerate().filter(|(i, _)| include(*i)) {
        lo = lo.min(*p);
        hi = hi.max(*p);
        if let Some(e) = skeleton.joint(i).end_site {
            lo = lo.min(*p + e);
            hi = hi.max(*p + e);
        }
    }
    let size = (hi - lo).max_element();
    if size.is_finite() { size } else { 0.0 }
}

/// Guess the unit of a file from the body size of its rest pose (in file units):
/// the concrete unit that puts the size nearest [`HUMAN_SIZE_M`] on a log scale
/// (ratios, not differences: 0.85 m and 3.4 m are equally far from 1.7 m).
/// Neighbouring candidates are at least a factor 2.2 apart (inch and
/// [`Unit::CmuAsf`]), so any body between about 1.2 m and 2.5 m tall is
/// recognised in every unit; smaller or larger bodies (or rest poses that are
/// not upright or T-shaped) can be mistaken, and callers who know the unit
/// should say so. A skeleton of zero size (one joint) is taken as metres.
pub fn guess_unit(size_in_file_units: f64) -> Unit {
    if !(size_in_file_units.is_finite() && size_in_file_units > 0.0) {
        return Unit::Metres;
    }
    let distance = |u: &Unit| {
        let m = u.metres().unwrap_or(1.0);
        (size_in_file_units * m / HUMAN_SIZE_M).ln().abs()
    };
    CONCRETE_UNITS
        .into_iter()
        .min_by(|a, b| distance(a).total_cmp(&distance(b)))
        .unwrap_or(Unit::Metres)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guesses_common_units() {
        assert_eq!(guess_unit(1.75), Unit::Metres);
        assert_eq!(guess_unit(172.0), Unit::Centimetres);
        assert_eq!(guess_unit(1690.0), Unit::Millimetres);
        assert_eq!(guess_unit(68.0), Unit::Inches);
        // CMU BVH conversions: ~30 units for an adult.
        assert_eq!(guess_unit(30.5), Unit::CmuAsf);
        assert_eq!(guess_unit(5.7), Unit::Feet);
        assert_eq!(guess_unit(0.0), Unit::Metres);
    }

    #[test]
    fn parses_names() {
        assert_eq!("CM".parse::<Unit>(), Ok(Unit::Centimetres));
        assert_eq!("inches".parse::<Unit>(), Ok(Unit::Inches));
        assert!("furlong".parse::<Unit>().is_err());
        assert_eq!(Unit::from_metres(0.0254), Some(Unit::Inches));
        assert_eq!(Unit::from_metres(0.0254 / 0.45), Some(Unit::CmuAsf));
        assert_eq!(Unit::from_metres(0.02), None);
    }
}
