//! The support watch in the step (issue 34 section 3, MODEL.md 5.1): which
//! cycles' samples count as the tip free at a varying pose, fed to the
//! estimator's [`SupportWatch`]; the confirmation of a named shift; and the
//! notes the controller logs (the first reset's figures, a verdict's
//! change, a confirmation).
//!
//! A sample counts when it is new, its estimate observable, no force
//! control runs, the trajectory is not a guarded move (which seeks a
//! contact) and either the guard waits for its first reset (at rest: the
//! mounting check takes the tip as free there too) or, in Ok, a move runs or
//! ended less than [`SETTLE_NS`] ago; and the filtered tip force is below
//! `[support] free_tip_max_n`. With a contact the support cannot be seen
//! (the U-joint passes no moment: the sensor measures F_A alone), so no
//! sample in force control or a guarded move is used.

use super::LoopStep;
use super::trajectory::Trajectory;
use super::vocabulary::{LoopInput, SupportNote, SupportWhy};
use sar_estimator::cycle::{CycleOutput, TipOutcome};
use sar_estimator::guard::GuardState;
use sar_estimator::motion::CarriageMotion;
#[cfg(doc)]
use sar_estimator::support::SupportWatch;
use sar_estimator::support::{SupportStatus, SupportVerdict};

/// After a move's end the samples still count for this long, ns (the
/// settling poses of `sarctl support check`).
pub const SETTLE_NS: u64 = 500_000_000;

/// The poses of `sarctl support check`: the tip's offsets from where it
/// starts, base frame, m (the rod turned up, down and to each side by
/// 30 mm at the tip, about 11 degrees at 0.15 m past the support, which
/// determines the support across it even against a constant tip force;
/// 40 mm back along it, which changes a and the friction's sign; then
/// home). Run twice (longer than the default 5 s window, so that samples
/// from before a shift weigh little).
pub const SUPPORT_CHECK_OFFSETS_M: [[f64; 3]; 6] = [
    [0.0, 0.03, 0.03],
    [0.0, -0.03, 0.03],
    [0.0, -0.03, -0.03],
    [0.0, 0.03, -0.03],
    [-0.04, 0.0, 0.0],
    [0.0, 0.0, 0.0],
];

/// How many times `sarctl support check` runs [`SUPPORT_CHECK_OFFSETS_M`].
pub const SUPPORT_CHECK_ROUNDS: usize = 2;

impl LoopStep {
    /// Feeds the cycle's sample to the watch when the tip can be taken as
    /// free; `awaiting` is whether the guard waited for its first reset
    /// before this cycle. Returns the note to log, if any.
    pub(super) fn observe_support(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        motion: &CarriageMotion,
        awaiting: bool,
    ) -> Option<SupportNote> {
        let before = self.support.status().verdict;
        if self.free_tip(input, estimate, awaiting)
            && let (TipOutcome::Estimate(e), Some(pose)) = (&estimate.tip, &estimate.pose)
        {
            let bias = self.estimator.bias().force_n;
            self.support.observe(
                &input.joints.joints,
                &input.sensor.force_n,
                &bias,
                motion,
                e,
                pose,
            );
        }
        let why = if awaiting && !self.estimator.awaiting_first_reset() {
            SupportWhy::FirstReset
        } else if self.support.status().verdict != before {
            SupportWhy::Verdict
        } else {
            return None;
        };
        Some(self.support_note(estimate.cycle, why))
    }

    /// The watch's status as a note.
    pub(super) fn support_note(&self, cycle: u64, why: SupportWhy) -> SupportNote {
        SupportNote {
            cycle,
            why,
            status: self.support.status(),
            max_shift_m: self.support.config().max_shift_m,
            max_std_m: self.support.config().max_std_m,
        }
    }

    /// Whether this cycle's sample is one of a free tip (see the module
    /// documentation).
    fn free_tip(&self, input: &LoopInput, estimate: &CycleOutput, awaiting: bool) -> bool {
        let observable = matches!(estimate.tip, TipOutcome::Estimate(e) if e.observable);
        let small = estimate
            .filtered
            .is_some_and(|f| f.force_n.norm() < self.support.config().free_tip_max_n);
        let moving = match (&self.trajectory, input.now_ns) {
            (Some(t), Some(now_ns)) => free_move(t, now_ns),
            _ => false,
        };
        let running = estimate.guard_state == GuardState::Ok && moving;
        estimate.new_sample
            && observable
            && small
            && self.force.mode().is_none()
            && (awaiting || running)
    }

    /// A shift named and not confirmed: force control is refused.
    pub(super) fn support_refuses_force(&self) -> Option<SupportStatus> {
        let s = self.support.status();
        (s.verdict == SupportVerdict::Shifted).then_some(s)
    }
}

/// A move that seeks no contact, running or ended within [`SETTLE_NS`].
fn free_move(t: &Trajectory, now_ns: u64) -> bool {
    t.max_force_n.is_none() && now_ns <= t.end_ns.saturating_add(SETTLE_NS)
}
