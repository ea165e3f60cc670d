//! Rigid moves of one object, as an edit asks for them: a rotation about a pivot (the object's
//! centre unless given), then a translation.

use super::check_translation;
use glam::{DAffine3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

/// A rigid move of one object: `rotate` about `pivot` (default: the centre of the object's
/// bounding box where it is), then `translate` (scene units).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Motion {
    /// The translation, scene units.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub translate: [f64; 3],
    /// The rotation, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate: Option<Rotation>,
    /// The point the rotation turns about (scene units); the object's centre when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pivot: Option<[f64; 3]>,
}

/// A rotation by `degrees` about `axis` (any length but zero), counter-clockwise looking down
/// the axis towards its origin (the right-hand rule).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rotation {
    /// The axis direction.
    pub axis: [f64; 3],
    /// The angle, degrees.
    pub degrees: f64,
}

fn is_zero(v: &[f64; 3]) -> bool {
    *v == [0.0; 3]
}

impl From<DVec3> for Motion {
    fn from(offset: DVec3) -> Motion {
        Motion {
            translate: offset.to_array(),
            ..Motion::default()
        }
    }
}

impl std::fmt::Display for Motion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(Rotation { axis, degrees }) = self.rotate {
            write!(f, "rotate {degrees} degrees about {axis:?}")?;
            if let Some(pivot) = self.pivot {
                write!(f, " through {pivot:?}")?;
            }
            write!(f, ", then ")?;
        }
        write!(f, "translate {:?}", self.translate)
    }
}

/// The largest rotation angle accepted, degrees: many turns, and still exact enough in f64.
pub const MAX_DEGREES: f64 = 1e6;

impl Motion {
    /// Checks every value: a finite translation within [`super::MAX_COORDINATE`], an axis finite and
    /// not zero, an angle finite within [`MAX_DEGREES`], a pivot like a translation, and a
    /// pivot only with a rotation.
    pub fn check(&self) -> Result<(), String> {
        check_translation(self.translate).map_err(|rule| format!("translate {rule}"))?;
        if let Some(pivot) = self.pivot {
            check_translation(pivot).map_err(|rule| format!("pivot {rule}"))?;
        }
        match self.rotate {
            Some(Rotation { axis, degrees }) => {
                let length = DVec3::from(axis).length();
                if !(length.is_finite() && length > 0.0) {
                    return Err(format!("rotate axis {axis:?} must be finite and not zero"));
                }
                if !(degrees.is_finite() && degrees.abs() <= MAX_DEGREES) {
                    return Err(format!(
                        "rotate degrees {degrees} must be finite and within ±{MAX_DEGREES:e}"
                    ));
                }
                Ok(())
            }
            None if self.pivot.is_some() => Err("a pivot needs a rotation".into()),
            None => Ok(()),
        }
    }

    /// The move as an affine map, with `centre` as the pivot when none was given: `x ->
    /// R (x - p) + p + t`.
    pub fn affine(&self, centre: DVec3) -> DAffine3 {
        let translate = DAffine3::from_translation(DVec3::from(self.translate));
        match self.rotate {
            Some(Rotation { axis, degrees }) => {
                let pivot = self.pivot.map_or(centre, DVec3::from);
                let turn =
                    DQuat::from_axis_angle(DVec3::from(axis).normalize(), degrees.to_radians());
                translate
                    * DAffine3::from_translation(pivot)
                    * DAffine3::from_quat(turn)
                    * DAffine3::from_translation(-pivot)
            }
            None => translate,
        }
    }

    /// Whether this is a translation alone (translations compose by adding).
    pub fn is_translation(&self) -> bool {
        self.rotate.is_none() && self.pivot.is_none()
    }
}

/// The farthest any of `points` lies from the origin along an axis, after `motion`: a move
/// that would take it past [`MAX_COORDINATE`] is refused.
pub fn reach_after(motion: &DAffine3, points: impl Iterator<Item = DVec3>) -> f64 {
    points
        .map(|p| motion.transform_point3(p).abs().max_element())
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_quarter_turns_about_the_centre_come_back_and_one_moves_a_corner_as_the_right_hand_rule_says()
     {
        let quarter = Motion {
            rotate: Some(Rotation {
                axis: [0.0, 0.0, 2.0],
                degrees: 90.0,
            }),
            ..Motion::default()
        };
        let centre = DVec3::new(1.0, 1.0, 0.0);
        let turn = quarter.affine(centre);
        // About +z, counter-clockwise: (2, 1) around (1, 1) goes to (1, 2).
        let moved = turn.transform_point3(DVec3::new(2.0, 1.0, 5.0));
        assert!(
            (moved - DVec3::new(1.0, 2.0, 5.0)).length() < 1e-12,
            "{moved}"
        );
        let full = turn * turn * turn * turn;
        let back = full.transform_point3(DVec3::new(2.0, 1.0, 5.0));
        assert!(
            (back - DVec3::new(2.0, 1.0, 5.0)).length() < 1e-12,
            "{back}"
        );
        let with_pivot = Motion {
            pivot: Some([0.0; 3]),
            translate: [0.0, 0.0, 1.0],
            ..quarter
        };
        let moved = with_pivot
            .affine(centre)
            .transform_point3(DVec3::new(1.0, 0.0, 0.0));
        assert!(
            (moved - DVec3::new(0.0, 1.0, 1.0)).length() < 1e-12,
            "{moved}"
        );
    }

    #[test]
    fn a_motion_is_refused_with_the_value_that_broke_its_rule() {
        let rotate = |axis, degrees| Motion {
            rotate: Some(Rotation { axis, degrees }),
            ..Motion::default()
        };
        assert_eq!(
            rotate([0.0; 3], 90.0).check(),
            Err("rotate axis [0.0, 0.0, 0.0] must be finite and not zero".into())
        );
        assert_eq!(
            rotate([0.0, 1.0, 0.0], f64::NAN).check(),
            Err("rotate degrees NaN must be finite and within ±1e6".into())
        );
        assert_eq!(
            Motion {
                pivot: Some([1.0, 2.0, 3.0]),
                ..Motion::default()
            }
            .check(),
            Err("a pivot needs a rotation".into())
        );
        assert!(
            Motion::from(DVec3::new(f64::INFINITY, 0.0, 0.0))
                .check()
                .unwrap_err()
                .starts_with("translate [inf, 0.0, 0.0] must have every value finite")
        );
        assert_eq!(rotate([0.0, 1.0, 0.0], -720.0).check(), Ok(()));
    }
}
