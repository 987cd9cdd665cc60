//! The force-limit guard: a state machine fed once per control cycle with the
//! tip-force estimate F_tip (MODEL.md 4.1), its standard deviation and the age
//! and validity of every input. It decides whether the robot may keep moving.
//!
//! States, from least to most severe: [`GuardState::Ok`], [`GuardState::Warn`],
//! [`GuardState::Stop`] (latched), [`GuardState::Fault`] (latched).
//!
//! Each [`Guard::step`] first looks for a fault condition in a fixed order
//! (cycle order, a fault the caller found in the cycle's inputs (clock, sensor
//! counter and status, joint jump, sensor torque), sensor validity, sensor age,
//! joints validity, joints age, pose, invalid numbers, observability flag). Any
//! fault condition sends the guard to `Fault` at once, without debounce: NaN,
//! infinite, stale or unobservable input is never `Ok` or `Warn`. Otherwise the
//! tip force is split into three parts, total |F|, axial |F . u| and lateral
//! |F - (F . u) u|, each compared with its own warn and stop limits.
//!
//! Debounce: entering `Warn` or `Stop` and leaving `Warn` are decided by
//! up/down counts over NEW sensor samples (a cycle that repeats the previous
//! sample, [`GuardInput::new_sample`] false, counts nothing: a 500 Hz sensor
//! read by a 4 kHz loop gives one vote per sample, not eight). Each new sample
//! moves a count up by one when its condition holds and down by one when it
//! does not, within `0..=debounce_samples`; the state changes when the count
//! reaches `debounce_samples`. So a force that is above a limit in more than
//! half of the samples trips it (30, 30, 11 N repeating against a 12 N limit
//! stops on the fifth sample), where a count that restarted at 0 never would.
//! Worst case: a force continuously at or above a stop limit stops within
//! `debounce_samples` new samples, i.e. within
//! [`GuardConfig::stop_within_ns`] = `debounce_samples * max_sensor_age_ns`
//! (a sample older than `max_sensor_age_ns`, measured from when its counter
//! changed, is a Fault).
//!
//! `Stop` and `Fault` are left only through an accepted [`Guard::reset`], which
//! must name the cycle just stepped: it is judged on that cycle's input, never
//! on an older one.
//!
//! Real-time path: no allocation, no panic, O(1) per step, fixed-size state.
//!
//! Its files: the machine here; `state` (the decision, and the rule of
//! motion in `Retreat`), `input` (what it looks at, and its fault
//! conditions), `limits` (its configuration), `reason` (why it is in its
//! state) and `parts` (what a reason names). Their items are public here,
//! under `guard`.

mod input;
mod limits;
mod parts;
mod reason;
mod state;

pub use input::{GuardInput, ROD_DIR_UNIT_TOLERANCE, TipInput};
pub use limits::{
    DEFAULT_RETREAT_RISE_N, ForceLimits, GuardConfig, GuardLimits, MAX_DEBOUNCE_SAMPLES,
    MAX_STD_MARGIN,
};
pub use parts::{Axis, ForcePart, RestResidual, SensorChannel, TipField};
pub use reason::{CODE_OTHER, REASONS, Reason, reason_name, recorded_code};
pub use state::{GuardState, reduces_force};

use crate::{SettingError, Vec3};
use input::{check_estimate, check_samples};

/// Above this largest component magnitude (N) the force is scaled before its
/// norms are taken, so that no square overflows.
const SCALE_ABOVE_N: f64 = 1e150;

/// A change of state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition {
    /// The input's cycle (for a reset, the cycle passed to it).
    pub cycle: u64,
    /// The state left.
    pub from: GuardState,
    /// The state entered.
    pub to: GuardState,
    /// Why.
    pub reason: Reason,
}

/// A reset was refused because its cause persists in the most recent input.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("reset refused: {reason}")]
pub struct ResetRefused {
    /// The cause that persists.
    pub reason: Reason,
}

/// The force-limit guard. Fixed-size; see the module documentation. Not
/// `Copy`, so that a copy cannot be stepped by mistake instead of the original.
#[derive(Debug, Clone, PartialEq)]
pub struct Guard {
    config: GuardConfig,
    state: GuardState,
    reason: Reason,
    /// The largest cycle stepped so far (None before the first step).
    last_cycle: Option<u64>,
    /// What in the most recent input would refuse a reset (a fault condition,
    /// a part at or above its stop limit, or no input yet).
    blocker: Option<Reason>,
    /// What in the most recent input is at or above a warn limit (or a fault
    /// condition, or no input yet): what refuses a tare.
    above_warn: Option<Reason>,
    /// Up/down count over new samples of a part at or above its stop limit.
    stop_count: u32,
    /// Up/down count over new samples of a part at or above its warn limit.
    warn_count: u32,
    /// Up/down count over new samples of every part below warn minus hysteresis.
    clear_count: u32,
    /// Still in the initial latch (no reset accepted yet).
    initial: bool,
    /// The filtered parts of the most recent input (no margin), N.
    smoothed_parts_n: Option<[f64; 3]>,
    /// In `Retreat`: the lowest filtered value of each part since it began, N.
    retreat_min_n: [f64; 3],
}

/// Magnitudes of the total, axial and lateral parts of `force_n` for the unit
/// direction `rod_dir` (both finite), in [`ForcePart::ALL`] order. Never NaN;
/// +inf only when the magnitude exceeds `f64::MAX`.
fn force_parts_n(force_n: &Vec3, rod_dir: &Vec3) -> [f64; 3] {
    let largest = force_n.x.abs().max(force_n.y.abs()).max(force_n.z.abs());
    let (f, scale) = if largest > SCALE_ABOVE_N {
        (force_n / largest, largest)
    } else {
        (*force_n, 1.0)
    };
    let along = f.dot(rod_dir);
    let lateral = f - rod_dir * along;
    [
        f.norm() * scale,
        along.abs() * scale,
        lateral.norm() * scale,
    ]
}

/// The first part (in [`ForcePart::ALL`] order) at or above its limit, with
/// its value and limit. A NaN value would count as above (conservative).
fn first_at_or_above(parts_n: &[f64; 3], limits_n: &[f64; 3]) -> Option<(ForcePart, f64, f64)> {
    ForcePart::ALL
        .iter()
        .zip(parts_n.iter().zip(limits_n.iter()))
        .find(|(_, (value, limit))| value.is_nan() || **value >= **limit)
        .map(|(part, (value, limit))| (*part, *value, *limit))
}

impl Guard {
    /// A guard in `Fault` with [`Reason::NoInputYet`]: a reset after a good
    /// input is needed before the robot may move (while it waits, with good
    /// input, its reason is [`Reason::AwaitingFirstReset`]).
    pub fn new(config: GuardConfig) -> Self {
        Self {
            config,
            state: GuardState::Fault,
            reason: Reason::NoInputYet,
            last_cycle: None,
            blocker: Some(Reason::NoInputYet),
            above_warn: Some(Reason::NoInputYet),
            stop_count: 0,
            warn_count: 0,
            clear_count: 0,
            initial: true,
            smoothed_parts_n: None,
            retreat_min_n: [0.0; 3],
        }
    }

    /// The current state.
    pub fn state(&self) -> GuardState {
        self.state
    }

    /// Why the guard is in its current state (the latched first reason for
    /// `Stop` and `Fault`, except in the initial latch, which shows this
    /// cycle's fault or [`Reason::AwaitingFirstReset`]; the entering reason
    /// for `Warn` and `Retreat`; `Reset`, `BelowWarn` or `Tared` for `Ok`).
    pub fn reason(&self) -> Reason {
        self.reason
    }

    /// Whether no reset has been accepted yet (the initial latch).
    pub fn awaiting_first_reset(&self) -> bool {
        self.initial
    }

    /// The configuration.
    pub fn config(&self) -> &GuardConfig {
        &self.config
    }

    /// Replaces the six force limits (checked by
    /// [`GuardConfig::with_force_limits`]: within the ceilings); returns the
    /// previous ones. The state, its reason and the debounce counts are
    /// kept: the new limits act from the next step.
    pub fn set_force_limits(&mut self, limits: &ForceLimits) -> Result<ForceLimits, SettingError> {
        let next = self.config.with_force_limits(limits)?;
        let previous = self.config.force_limits();
        self.config = next;
        Ok(previous)
    }

    /// What in the most recent input would make [`Guard::reset`] refuse, if
    /// anything: a fault condition, a part at or above its stop limit (which
    /// a reset turns into `Retreat` when a filtered force is available), or
    /// [`Reason::NoInputYet`].
    pub fn reset_blocker(&self) -> Option<Reason> {
        self.blocker
    }

    /// What in the most recent input is at or above a warn limit (with the
    /// margin), or a fault condition, or [`Reason::NoInputYet`]; `None` when
    /// every part was below its warn limit.
    pub fn warn_blocker(&self) -> Option<Reason> {
        self.above_warn
    }

    /// Feeds one control cycle. Returns `Some` only when the state (or, in
    /// `Warn`, its reason) changed.
    #[inline]
    pub fn step(&mut self, input: &GuardInput) -> Option<Transition> {
        let transition = self.step_state(input);
        self.debug_check();
        transition
    }

    /// The invariants a reader of the guard would otherwise have to trust,
    /// checked in debug builds after every step and reset: each debounce
    /// count within `0..=debounce_samples` (a vote never passes the
    /// threshold); the initial latch only in `Fault` (nothing leaves it but
    /// an accepted reset, which ends the latch).
    #[inline]
    fn debug_check(&self) {
        let debounce = self.config.limits.debounce_samples;
        debug_assert!(
            self.stop_count <= debounce
                && self.warn_count <= debounce
                && self.clear_count <= debounce,
            "debounce counts {}/{}/{} above {debounce}",
            self.stop_count,
            self.warn_count,
            self.clear_count
        );
        debug_assert!(
            !self.initial || self.state == GuardState::Fault,
            "the initial latch in {}",
            self.state
        );
    }

    /// [`Guard::step`] without the invariants' check: judge the input (a
    /// fault condition latches Fault), count the votes of its force parts,
    /// then decide the move of the state it is in.
    #[inline]
    fn step_state(&mut self, input: &GuardInput) -> Option<Transition> {
        let cycle = input.cycle;
        let parts_n = match self.evaluate(input) {
            Err(fault) => return self.on_fault(fault, cycle),
            Ok(parts_n) => parts_n,
        };
        if self.initial && self.state == GuardState::Fault {
            self.reason = Reason::AwaitingFirstReset;
        }
        self.smoothed_parts_n = match (input.smoothed_force_n, input.tip) {
            (Some(f), TipInput::Estimate { rod_dir, .. }) if f.iter().all(|v| v.is_finite()) => {
                Some(force_parts_n(&f, &rod_dir))
            }
            _ => None,
        };
        let hits = self.count_votes(&parts_n, input.new_sample);
        match self.state {
            GuardState::Stop | GuardState::Fault => None,
            GuardState::Retreat => self.step_retreat(&parts_n, hits.clear, cycle),
            GuardState::Ok | GuardState::Warn => self.step_ok_warn(&hits, input.tare_due, cycle),
        }
    }

    /// A fault condition in this cycle's input: it blocks a reset and a
    /// tare, clears the votes and the filtered parts, and latches Fault (in
    /// the initial latch it becomes the reason shown, without a transition).
    #[inline]
    fn on_fault(&mut self, fault: Reason, cycle: u64) -> Option<Transition> {
        self.blocker = Some(fault);
        self.above_warn = Some(fault);
        self.smoothed_parts_n = None;
        self.stop_count = 0;
        self.warn_count = 0;
        self.clear_count = 0;
        if self.initial && self.state == GuardState::Fault {
            // The initial latch shows what blocks the first reset now.
            self.reason = fault;
            return None;
        }
        self.enter(GuardState::Fault, fault, cycle)
    }

    /// Compares the parts (margin included) with the stop, warn and clear
    /// limits; a new sample moves each up/down count by one; what is at or
    /// above a stop (warn) limit becomes what blocks a reset (a tare).
    #[inline]
    fn count_votes(&mut self, parts_n: &[f64; 3], new_sample: bool) -> Hits {
        let cfg = &self.config;
        let hits = Hits {
            stop: first_at_or_above(parts_n, &cfg.stop_n),
            warn: first_at_or_above(parts_n, &cfg.warn_n),
            clear: parts_n
                .iter()
                .zip(cfg.clear_n.iter())
                .all(|(value, limit)| *value < *limit),
        };
        let debounce = cfg.limits.debounce_samples;
        if new_sample {
            let vote = |count: u32, holds: bool| {
                if holds {
                    count.saturating_add(1).min(debounce)
                } else {
                    count.saturating_sub(1)
                }
            };
            self.stop_count = vote(self.stop_count, hits.stop.is_some());
            self.warn_count = vote(self.warn_count, hits.warn.is_some());
            self.clear_count = vote(self.clear_count, hits.clear);
        }
        self.blocker = hits.stop.map(|(part, force_n, limit_n)| Reason::AboveStop {
            part,
            force_n,
            limit_n,
        });
        self.above_warn = hits.warn.map(|(part, force_n, limit_n)| Reason::AboveWarn {
            part,
            force_n,
            limit_n,
        });
        hits
    }

    /// `Ok` or `Warn`: Stop once a stop limit is debounced; from Ok (or a
    /// tare's Warn) Warn once a warn limit is debounced, else the tare's
    /// warning begins or ends; from a force's Warn, Ok once every part is
    /// debounced clear.
    #[inline]
    fn step_ok_warn(
        &mut self,
        hits: &Hits,
        tare_due: Option<Reason>,
        cycle: u64,
    ) -> Option<Transition> {
        let debounce = self.config.limits.debounce_samples;
        if let Some((part, force_n, limit_n)) = hits.stop
            && self.stop_count >= debounce
        {
            let reason = Reason::AboveStop {
                part,
                force_n,
                limit_n,
            };
            return self.enter(GuardState::Stop, reason, cycle);
        }
        let warn_due = hits.warn.filter(|_| self.warn_count >= debounce);
        let tare_warn = matches!(self.reason, Reason::TareDue { .. });
        if self.state == GuardState::Ok || tare_warn {
            if let Some((part, force_n, limit_n)) = warn_due {
                let reason = Reason::AboveWarn {
                    part,
                    force_n,
                    limit_n,
                };
                // Leaving Warn needs a fresh run of clear samples.
                self.clear_count = 0;
                return self.enter_reason(GuardState::Warn, reason, cycle);
            }
            return match (self.state, tare_due) {
                (GuardState::Ok, Some(due)) => self.enter(GuardState::Warn, due, cycle),
                // The tare was done: the tare warning is over.
                (GuardState::Warn, None) => self.enter(GuardState::Ok, Reason::Tared, cycle),
                _ => None,
            };
        }
        if hits.clear && self.clear_count >= debounce {
            // Re-entering Warn needs a fresh run of warn samples.
            self.warn_count = 0;
            return self.enter(GuardState::Ok, Reason::BelowWarn, cycle);
        }
        None
    }

    /// `Retreat`: Stop when a filtered part rises above
    /// max(stop limit, its lowest value since the retreat began + the rise
    /// allowance); Ok when every part has been below its warn limit minus
    /// the hysteresis for the debounce.
    fn step_retreat(&mut self, parts_n: &[f64; 3], clear: bool, cycle: u64) -> Option<Transition> {
        // Without a filtered value (the filter restarting after lost
        // samples) the unfiltered parts, margin included, stand in.
        let watched = self.smoothed_parts_n.unwrap_or(*parts_n);
        let rise_n = self.config.retreat_rise_n;
        let mut rising = None;
        for (((part, value), lowest), stop) in ForcePart::ALL
            .iter()
            .zip(watched.iter())
            .zip(self.retreat_min_n.iter_mut())
            .zip(self.config.stop_n.iter())
        {
            *lowest = lowest.min(*value);
            let bound_n = stop.max(*lowest + rise_n);
            // NaN counts as rising (conservative).
            if rising.is_none() && (value.is_nan() || *value > bound_n) {
                rising = Some(Reason::ForceRising {
                    part: *part,
                    force_n: *value,
                    bound_n,
                });
            }
        }
        if let Some(reason) = rising {
            return self.enter(GuardState::Stop, reason, cycle);
        }
        if clear && self.clear_count >= self.config.limits.debounce_samples {
            self.warn_count = 0;
            self.stop_count = 0;
            return self.enter(GuardState::Ok, Reason::BelowWarn, cycle);
        }
        None
    }

    /// Asks to leave `Stop` or `Fault`, judged on the input of `cycle`, which
    /// must be the cycle just stepped (else refused with
    /// [`Reason::ResetNotCurrent`]; before any step with
    /// [`Reason::NoInputYet`]): call it right after [`Guard::step`] of the same
    /// cycle (as [`crate::cycle::Estimator::cycle`] does for a reset command).
    /// In `Ok`, `Warn` or `Retreat` it does nothing (`Ok(None)`). Refused
    /// while a fault condition persists in that input. With every part below
    /// its stop limit it goes to `Ok`; with a part still at or above its
    /// stop limit (not debounced) it goes to `Retreat` when a filtered force
    /// was given this cycle, and is refused otherwise. An accepted reset
    /// clears the debounce counts.
    pub fn reset(&mut self, cycle: u64) -> Result<Option<Transition>, ResetRefused> {
        match self.state {
            GuardState::Ok | GuardState::Warn | GuardState::Retreat => Ok(None),
            GuardState::Stop | GuardState::Fault => {
                let Some(last) = self.last_cycle else {
                    return Err(ResetRefused {
                        reason: Reason::NoInputYet,
                    });
                };
                if cycle != last {
                    return Err(ResetRefused {
                        reason: Reason::ResetNotCurrent { last, got: cycle },
                    });
                }
                let (to, reason) = match (self.blocker, self.smoothed_parts_n) {
                    (None, _) => (GuardState::Ok, Reason::Reset),
                    (
                        Some(Reason::AboveStop {
                            part,
                            force_n,
                            limit_n,
                        }),
                        Some(smoothed),
                    ) => {
                        self.retreat_min_n = smoothed;
                        (
                            GuardState::Retreat,
                            Reason::RetreatEntered {
                                part,
                                force_n,
                                limit_n,
                            },
                        )
                    }
                    (Some(reason), _) => return Err(ResetRefused { reason }),
                };
                self.stop_count = 0;
                self.warn_count = 0;
                self.clear_count = 0;
                self.initial = false;
                let transition = self.enter(to, reason, cycle);
                self.debug_check();
                Ok(transition)
            }
        }
    }

    /// Like [`Guard::enter`], but a change of reason within the same state
    /// is a transition too (Warn for a due tare becoming Warn for a force).
    fn enter_reason(&mut self, to: GuardState, reason: Reason, cycle: u64) -> Option<Transition> {
        if self.state == to {
            let from = self.state;
            self.reason = reason;
            return Some(Transition {
                cycle,
                from,
                to,
                reason,
            });
        }
        self.enter(to, reason, cycle)
    }

    /// Moves to `to` with `reason` unless already there (a latched state keeps
    /// its first reason).
    fn enter(&mut self, to: GuardState, reason: Reason, cycle: u64) -> Option<Transition> {
        if self.state == to {
            return None;
        }
        let from = self.state;
        self.state = to;
        self.reason = reason;
        Some(Transition {
            cycle,
            from,
            to,
            reason,
        })
    }

    /// The first fault condition of `input` in the fixed order (cycle
    /// order, the caller's input fault, the samples' validity and age, the
    /// estimate), or the force parts with their margin. Records the cycle if
    /// it is in order.
    #[inline]
    fn evaluate(&mut self, input: &GuardInput) -> Result<[f64; 3], Reason> {
        if let Some(previous) = self.last_cycle
            && input.cycle <= previous
        {
            return Err(Reason::CycleOutOfOrder {
                previous,
                got: input.cycle,
            });
        }
        self.last_cycle = Some(input.cycle);
        check_samples(input, &self.config.limits)?;
        let (force_n, std_n, rod_dir) = check_estimate(&input.tip)?;
        let limits = &self.config.limits;
        // The margin: k |std| bounds k standard deviations of every part.
        let mut margin_n = if limits.std_margin > 0.0 {
            limits.std_margin * std_n.norm()
        } else {
            0.0
        };
        // The drift bound: a negative or NaN one counts as unbounded.
        margin_n += if input.extra_margin_n >= 0.0 {
            input.extra_margin_n
        } else {
            f64::INFINITY
        };
        Ok(force_parts_n(&force_n, &rod_dir).map(|part_n| part_n + margin_n))
    }
}

/// What one cycle's force parts hit: the first part at or above its stop
/// limit and the first at or above its warn limit (part, value, limit), and
/// whether every part is below its clear limit.
struct Hits {
    stop: Option<(ForcePart, f64, f64)>,
    warn: Option<(ForcePart, f64, f64)>,
    clear: bool,
}

// Snapshots (issue 17): the guard is stored whole, its limits included
// (an operator may change them at run time). The tags of `Reason` are its
// codes ([`REASONS`]; its `Snap` is made by `reasons!`).

sar_snapshot::snap_struct!(Guard {
    config,
    state,
    reason,
    last_cycle,
    blocker,
    above_warn,
    stop_count,
    warn_count,
    clear_count,
    initial,
    smoothed_parts_n,
    retreat_min_n,
});

#[cfg(test)]
mod tests;
