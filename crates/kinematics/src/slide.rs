//! The slide of the rod in the support (MODEL.md 5): its sign, typed so that
//! "not known yet" can never pass for a number, and the tracker that follows it
//! from the joint positions. Pure kinematics, shared by the simulator, the
//! scenario checks, the runner and (through [`SlideSign`]) the estimator.
//!
//! Convention (binding, MODEL.md 5): sigma = +1 when A last moved towards B (the
//! rod slid along u, inserting), -1 when it moved away (retracting); before the
//! first slide sigma is unknown. A reversal counts only after a slide of
//! [`SLIDE_THRESHOLD_M`] the other way (the support's pre-sliding displacement).

use crate::{ActiveJoints, Calibration, Vec3};

/// The slide of the rod in the support, m, against the direction of its last
/// slide, after which the rod counts as sliding the other way.
///
/// A real support's friction does not reverse the instant the rod does: the
/// contact first deforms over a small pre-sliding displacement (micro-slip),
/// during which the friction keeps the sign of the last slide. The simulator
/// reverses the support's friction only after a slide of this size the other
/// way, and [`SlideTracker`] calls the slide reversed after the same (a few
/// encoder counts of the article's axes, so that quantisation does not flip it
/// either): identification's friction coefficient is then the sign of the
/// friction actually in the readings. One constant for both.
pub const SLIDE_THRESHOLD_M: f64 = 5e-6;

/// The direction of the last slide of the rod in the support (MODEL.md 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SlideSign {
    /// No slide seen yet: the sign of the support's friction is not known. A
    /// pose with this sign has no friction coefficient (see [`SlideSign::sigma`]).
    #[default]
    Unknown,
    /// A last moved towards B: the rod slid along u (sigma = +1).
    Inserting,
    /// A last moved away from B: the rod slid against u (sigma = -1).
    Retracting,
}

impl SlideSign {
    /// sigma, the coefficient of the support friction f in `F_A = ... + sigma f u`:
    /// `Some(1.0)` inserting, `Some(-1.0)` retracting, `None` when unknown
    /// (never 0: an unknown sign must be handled, not multiplied).
    pub const fn sigma(self) -> Option<f64> {
        match self {
            Self::Unknown => None,
            Self::Inserting => Some(1.0),
            Self::Retracting => Some(-1.0),
        }
    }

    /// Whether the sign is known.
    pub const fn is_known(self) -> bool {
        !matches!(self, Self::Unknown)
    }
}

/// The direction of the last slide from the distance between the U-joint and
/// the support along the rod: [`SlideSign::Inserting`] when it last shrank,
/// [`SlideSign::Retracting`] when it last grew, [`SlideSign::Unknown`] before
/// any slide. A slide counts once the distance has moved by more than
/// [`SLIDE_THRESHOLD_M`] from its extreme in the present direction (from the
/// first value before any slide).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SlideDirection {
    /// The extreme of the distance in the present direction, m (the first
    /// value before any slide; `None` before any value).
    reference_m: Option<f64>,
    sign: SlideSign,
}

impl SlideDirection {
    /// No distance seen yet; the sign is unknown.
    pub const fn new() -> Self {
        Self {
            reference_m: None,
            sign: SlideSign::Unknown,
        }
    }

    /// The sign of the last slide.
    pub const fn sign(&self) -> SlideSign {
        self.sign
    }

    /// Takes the next distance, m (non-finite values are ignored); returns
    /// true when the sign changed.
    pub fn update(&mut self, distance_m: f64) -> bool {
        if !distance_m.is_finite() {
            return false;
        }
        let Some(reference) = self.reference_m else {
            self.reference_m = Some(distance_m);
            return false;
        };
        let change = distance_m - reference;
        let continues = match self.sign {
            // Still shrinking (inserting) or still growing (retracting): a new extreme.
            SlideSign::Inserting => change < 0.0,
            SlideSign::Retracting => change > 0.0,
            SlideSign::Unknown => false,
        };
        if continues {
            self.reference_m = Some(distance_m);
            return false;
        }
        let sign = if change < -SLIDE_THRESHOLD_M {
            // Shrinking: A moves towards B, the rod slides along u.
            SlideSign::Inserting
        } else if change > SLIDE_THRESHOLD_M {
            SlideSign::Retracting
        } else {
            return false;
        };
        self.reference_m = Some(distance_m);
        let changed = sign != self.sign;
        self.sign = sign;
        changed
    }
}

/// Follows a = |B - A| over a sequence of active joint positions and keeps the
/// sign of the last slide of the rod in the support (see [`SlideDirection`]):
/// unknown before the first slide. A reversal counts once a has come back by
/// more than [`SLIDE_THRESHOLD_M`] from its extreme (the simulator's friction
/// reverses after the same slide), so that encoder quantisation does not flip it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlideTracker {
    support_m: Vec3,
    ujoint_at_zero_m: Vec3,
    direction: SlideDirection,
}

impl SlideTracker {
    /// A tracker for the geometry of `calibration` (B, P_home, a_off), with no
    /// position seen yet.
    pub fn new(calibration: &Calibration) -> Self {
        Self {
            support_m: calibration.support_m(),
            ujoint_at_zero_m: calibration.p_home_m() + calibration.ujoint_offset_m(),
            direction: SlideDirection::new(),
        }
    }

    /// The sign of the last slide ([`SlideSign::Unknown`] before any).
    pub fn sign(&self) -> SlideSign {
        self.direction.sign()
    }

    /// Takes the next position; returns true when the sign changed.
    pub fn update(&mut self, q: &ActiveJoints) -> bool {
        let a = (self.support_m - self.ujoint_at_zero_m - q.displacement_m()).norm();
        self.direction.update(a)
    }
}

// Snapshots (the support watch keeps a slide direction in the loop's state).
sar_snapshot::snap_enum!(SlideSign {
    0 => Unknown,
    1 => Inserting,
    2 => Retracting,
});
sar_snapshot::snap_struct!(SlideDirection { reference_m, sign });

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direction_is_unknown_until_the_first_slide_and_has_hysteresis() {
        let mut d = SlideDirection::new();
        assert_eq!(d.sign(), SlideSign::Unknown);
        assert!(!d.update(0.10));
        assert!(!d.update(0.10 + 0.5 * SLIDE_THRESHOLD_M));
        assert_eq!(d.sign(), SlideSign::Unknown);
        assert!(!d.update(f64::NAN));
        // Shrinking by more than the threshold: inserting.
        assert!(d.update(0.10 - 2.0 * SLIDE_THRESHOLD_M));
        assert_eq!(d.sign(), SlideSign::Inserting);
        assert!(!d.update(0.09));
        // Back by less than the threshold from the extreme: still inserting.
        assert!(!d.update(0.09 + 0.9 * SLIDE_THRESHOLD_M));
        assert_eq!(d.sign(), SlideSign::Inserting);
        assert!(d.update(0.09 + 1.1 * SLIDE_THRESHOLD_M));
        assert_eq!(d.sign(), SlideSign::Retracting);
    }

    #[test]
    fn sigma_follows_the_convention() {
        assert_eq!(SlideSign::Inserting.sigma(), Some(1.0));
        assert_eq!(SlideSign::Retracting.sigma(), Some(-1.0));
        assert_eq!(SlideSign::Unknown.sigma(), None);
        assert_eq!(SlideSign::default(), SlideSign::Unknown);
        assert!(!SlideSign::Unknown.is_known());
    }
}
