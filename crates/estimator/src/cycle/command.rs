//! The operator's commands, applied after a cycle's step on that cycle's
//! input ([`super::Command`]): a reset (the first one also checked against
//! the model at rest: `mounting`), a tare or a bias (only in Ok, below every
//! warn limit, on this cycle's estimate; the tare's bias is `tare`'s), new
//! force limits (within the ceilings fixed at start); each accepted or
//! refused with a typed reason ([`super::CommandAccepted`],
//! [`super::CommandRefused`]).

use super::Estimator;
use super::vocabulary::{Command, CommandAccepted, CommandRefused, CycleInput, TipOutcome};
use crate::guard::{ForceLimits, GuardState, Reason};
use crate::{Pose, SettingError};

impl Estimator {
    /// Applies `command` after this cycle's step (whose output is in
    /// `self.last`).
    pub(super) fn apply(
        &mut self,
        command: Command,
        input: &CycleInput,
        now_ns: Option<u64>,
    ) -> Result<CommandAccepted, CommandRefused> {
        if let Command::SetBias(bias) = command {
            bias.check()
                .map_err(|value| CommandRefused::BiasNonFinite { value })?;
        }
        if let Command::SetLimits(limits) = command {
            return self.set_limits(limits);
        }
        if command == Command::Reset {
            return self.reset(input);
        }
        let pose = self.bias_allowed()?;
        let bias = match command {
            Command::SetBias(bias) => bias,
            _ => self.tare_now(&pose, input, now_ns)?,
        };
        let previous = self.bias;
        self.bias = bias;
        // The tare's age restarts (a clock is known: the guard is not Ok
        // without one).
        self.tare_ns = now_ns.or(self.tare_ns);
        Ok(CommandAccepted::BiasSet { previous, bias })
    }

    /// The operator's new force limits, handed to the guard.
    fn set_limits(&mut self, limits: ForceLimits) -> Result<CommandAccepted, CommandRefused> {
        match self.guard.set_force_limits(&limits) {
            Ok(previous) => Ok(CommandAccepted::LimitsSet { previous, limits }),
            Err(SettingError::Invalid { field, value, why }) => {
                Err(CommandRefused::Limits { field, value, why })
            }
            Err(_) => Err(CommandRefused::Limits {
                field: "limits",
                value: f64::NAN,
                why: "refused",
            }),
        }
    }

    /// The operator's reset. The first one: the wrench at rest must match
    /// the model, unless a fault blocks it anyway (the guard then names it).
    fn reset(&mut self, input: &CycleInput) -> Result<CommandAccepted, CommandRefused> {
        let fault_blocks = self
            .guard
            .reset_blocker()
            .is_some_and(|r| !matches!(r, Reason::AboveStop { .. }));
        if self.guard.awaiting_first_reset()
            && self.guard.state().is_halting()
            && !fault_blocks
            && let Some(limits) = self.limits.mounting
            && let Some(reason) = self.mounting_verdict(&limits)
        {
            return Err(CommandRefused::Reset { reason });
        }
        match self.guard.reset(input.cycle) {
            Ok(Some(t)) => {
                self.last.transition = Some(t);
                Ok(CommandAccepted::Reset)
            }
            Ok(None) => Ok(CommandAccepted::NothingToReset),
            Err(e) => Err(CommandRefused::Reset { reason: e.reason }),
        }
    }

    /// Whether a tare or a bias may be set now: only in Ok (or the Warn of a
    /// due tare), below every warn limit, on this cycle's estimate (whose
    /// pose it returns).
    fn bias_allowed(&self) -> Result<Pose, CommandRefused> {
        let state = self.guard.state();
        let tare_warn =
            state == GuardState::Warn && matches!(self.guard.reason(), Reason::TareDue { .. });
        if state != GuardState::Ok && !tare_warn {
            return Err(CommandRefused::NotOk {
                state,
                reason: self.guard.reason(),
            });
        }
        if let Some(reason) = self.guard.warn_blocker() {
            return Err(CommandRefused::AboveWarn { reason });
        }
        let (TipOutcome::Estimate(_), Some(pose)) = (self.last.tip, self.last.pose) else {
            return Err(CommandRefused::NoEstimate);
        };
        Ok(pose)
    }
}
