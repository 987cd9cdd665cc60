//! The daemon's pure per-cycle decision: [`LoopStep::step`] turns one cycle's
//! [`LoopInput`] (clock reading, sensor sample, joint sample, the drives'
//! state, the operator request applied in this cycle) into a [`LoopOutput`]:
//! the estimator's output, the commanded trajectory at the joint sample's
//! stamp (checked for following error), what the drives are told
//! ([`DriveAction`]) and the reply to the request. Nothing else enters a
//! decision: no device, no clock, no queue. So a recording of the inputs
//! (`/sar/cycle/input`) replays to the same outputs bit for bit, and the
//! controller ([`crate::control`]) only gathers inputs and carries out
//! [`DriveAction`]s.
//!
//! Rules carried here (the estimator carries the guard's):
//! - On Stop or Fault the drives get a quick stop in the same cycle, and again
//!   in every later cycle in which they report `Enabled`, until a reset is
//!   accepted; the commanded trajectory is dropped.
//! - An accepted reset brings the drives back (the way depends on their
//!   state) and holds the axes where they were measured.
//! - A move is planned here, with the time-optimal axis planner of
//!   [`sar_hal::motion`] under the configured speed and acceleration,
//!   from where the trajectory is now. The drives get the plan's end point
//!   once, when it is planned (or braked), and run the same planner under the
//!   same limits (the simulator's axes and the CANopen host take theirs from
//!   `[axes]`), so that the loop's plan is the trajectory they follow within a
//!   period; drives that do otherwise (other limits, a blocked or slipping
//!   axis) leave it and fault. A move is refused while halted, while the
//!   drives are not enabled, outside the travel or the kinematics, and,
//!   above the warn limit, when it pushes the tip further along its force; a
//!   move under way that would push further along the force once the force
//!   is above the warn limit is braked.
//! - Following error: the measured joints against the trajectory at their
//!   stamp, beyond the tolerance, is a Fault ([`Reason::FollowingError`]);
//!   during the drives' own quick stop (a halt begun under a trajectory),
//!   against the quick stop's profile at the configured deceleration
//!   ([`crate::motion::AxesMotion::halt_position`]): a drive that brakes
//!   weaker runs on beyond it and faults.
//! - Retreat (issue 14: the way back from a Stop whose force persists): a
//!   reset above the stop limit puts the guard in `Retreat`; then a move is
//!   accepted only when it reduces the tip force
//!   ([`sar_estimator::guard::reduces_force`]: against the force, or backing
//!   out along the rod, [`Request::BackOut`]), planned at `[axes]
//!   retreat_speed_mps` and streamed to the drives one set point per period
//!   ([`DriveAction::Stream`], cyclic synchronous position), so that they
//!   move at that speed. The guard stops again if the force rises.
//! - The carriage's motion (issue 26, [`crate::motion`]): each cycle the
//!   estimator is handed the velocity and acceleration of the commanded
//!   trajectory through a model of the drives' servo (the drives' own quick
//!   stop during a halt), where the sensor sample was measured. A guarded
//!   move brakes hard (`[axes] brake_decel_mps2`), streamed; the warn
//!   rule's brake stays at the planned deceleration.
//! - An excitation (issue 26, [`Request::Excite`], [`crate::excite`]):
//!   accepted in Ok with the drives enabled and the axes at rest, within
//!   `[identify]`'s limits (its fades' peaks included) and the travel;
//!   streamed one period ahead about
//!   where the axes rest. A Warn, a Stop or a new move ends it (braked from
//!   its position and velocity, or quick-stopped); so does a commanded
//!   speed or acceleration above the limits.
//! - A late cycle is an input, not a fault (issue 33): a cycle that comes
//!   more than a period after the last streamed set point delays the
//!   streamed trajectory by the excess before anything evaluates it
//!   ([`LoopStep::absorb_late_cycle`]), so that its set point follows the
//!   last one by one period of the trajectory's time: the drives, which
//!   held the last set point meanwhile, are never asked for a jump, and the
//!   servo model, which follows the set points as streamed, knows what
//!   they did. A late cycle beyond the sensor's accepted age is the
//!   estimator's `cycle_gap` Fault; the quick stop then starts from the axes
//!   as the model has them, so a reset is accepted once they rest.
//! - A guarded move anticipates its force's rise only once it is in contact
//!   (the force along its way significant against its noise:
//!   [`GUARDED_CONTACT_SIGMA`]), so that noise never brakes it; a limit
//!   within the noise is refused.
//! - A host fault: the publishing thread (the operator's commands and the
//!   published state) without progress for longer than the configured
//!   stall time is a Fault ([`Reason::PublisherStalled`]), from the
//!   recorded `LoopInput::publisher_idle_ns`.
//! - A move reply says accepted only when the move goes to the drives in
//!   the same cycle; every refusal carries its exact cause
//!   ([`ReplyDetail`]).
//!
//! Fixed-size state; no allocation, no panic.
//!
//! The files of this folder, each one idea, in their dependency order (a
//! file uses only those above it; this one, the pipeline, uses them all):
//! `request` (the operator's [`Request`]), `config` ([`StepConfig`] and the
//! step's constants), `answer` (the reply's [`ReplyDetail`]), `vocabulary`
//! ([`LoopInput`], [`LoopOutput`], [`DriveAction`]), `trajectory` (the
//! commanded trajectory and what a phase decides of it), `gather` (what the
//! step derives from the input before the estimator judges), `drives` (the
//! guard's drive action, a held reset, the ready check), `retreat` (the warn
//! rule and Retreat: which way a motion may go), `guarded` (guarded moves
//! and the one brake), `moves` (a move judged and planned), `force` (force
//! control), `excitation`, `support` (the support watch's free-tip samples,
//! issue 34), `commit` (the cycle's decision and the one commit point) and
//! `snapshot`.
//!
//! The one commit point: the phases of [`LoopStep::step`] return what they
//! decide (a `TrajectoryChange`, a reply, a drive action, a brake); the
//! step gathers them in a `Decision`, whose trajectory is a working copy,
//! and `LoopStep::commit` alone writes the trajectory, the model of the
//! axes, the drives' state remembered, a guarded stop and the output. A
//! move or an excitation accepted but not given to the drives in its cycle
//! is not undone: it is never committed (the cycle keeps the trajectory it
//! found). What the gathering derives (the following reference, the
//! carriage's motion, the host's faults) are queries; the axes' speed, the
//! guarded force's rate, the estimator and the force controller are
//! updated by their own named methods, in the pipeline's order.

mod answer;
mod commit;
mod config;
mod drives;
mod excitation;
mod force;
mod gather;
mod guarded;
mod inertia;
mod moves;
mod request;
mod retreat;
mod snapshot;
mod support;
mod trajectory;
mod vocabulary;

pub use answer::{ReplyDetail, ReplyStatus, SupportShifted};
pub use config::{
    GUARDED_CONTACT_SIGMA, MAX_BACK_OUT_M, RATE_LAG_FRACTION, REST_SPEED_MPS, StepConfig,
    StepConfigError,
};
pub use request::Request;
pub use snapshot::SNAPSHOT_KIND_LOOP_STEP;
pub use support::{SETTLE_NS, SUPPORT_CHECK_OFFSETS_M, SUPPORT_CHECK_ROUNDS};
pub use vocabulary::{
    DriveAction, GuardedStop, LoopInput, LoopOutput, Release, SupportNote, SupportWhy, reason_code,
    recorded_reason_code,
};

use crate::motion::AxesMotion;
use answer::Answer;
use commit::{AxesEvent, Decision};
use config::guarded_filter;
use drives::HeldReset;
use moves::MoveTarget;
use sar_estimator::cycle::{Bias, CycleContext, CycleOutput, Estimator, EstimatorConfig};
use sar_estimator::force_control::{ForceController, ForceMode};
#[cfg(doc)]
use sar_estimator::guard::Reason;
use sar_estimator::inertia_watch::InertiaWatch;
use sar_estimator::support::SupportWatch;
use sar_hal::DriveState;
use sar_kinematics::{ActiveJoints, Calibration, Profile};
use trajectory::{Trajectory, TrajectoryChange};

/// The pure per-cycle decision of the daemon (see the module documentation).
#[derive(Debug, Clone)]
pub struct LoopStep {
    estimator: Estimator,
    calibration: Calibration,
    profile: Profile,
    config: StepConfig,
    trajectory: Option<Trajectory>,
    /// The last valid joint sample (for the axes' speed).
    last_joints: Option<(ActiveJoints, u64)>,
    /// The largest axis speed between the last two joint samples, m/s.
    speed_mps: f64,
    /// The drives' state in the previous cycle (a new drive fault is a
    /// guard Fault in the cycle it appears).
    last_drive_state: Option<DriveState>,
    /// The last guarded move's stop.
    guarded_stop: Option<GuardedStop>,
    /// The guarded force's magnitude at the last new sensor sample (its
    /// counter, N) and its rate since the sample before, N/s.
    guarded_last: Option<(u32, f64)>,
    guarded_rate_n_per_s: f64,
    /// The guarded force's filter: its group delay and sample period, s
    /// (0 and the sensor's period without a filter).
    guarded_lag_s: f64,
    sample_period_s: f64,
    /// Force control (its filter runs in every cycle; a mode when active).
    force: ForceController,
    /// How the axes move: the servo model, the drives' quick stop.
    motion: AxesMotion,
    /// The inertia watch (issue 34: I_perp and m_s against the free motion).
    inertia_watch: InertiaWatch,
    /// The support watch (issue 34 section 3, `step/support.rs`).
    support: SupportWatch,
    /// The clock of the last cycle, if it streamed a set point: a streamed
    /// trajectory's time runs from it (issue 33, [`LoopStep::absorb_late_cycle`]).
    last_stream_ns: Option<u64>,
    out: LoopOutput,
    /// The fingerprint of the configuration parts, for snapshots (computed
    /// at construction: the configuration never changes after it).
    snapshot_fingerprint: u64,
}

impl LoopStep {
    /// Builds the step: the estimator with the sensor's bias, no trajectory
    /// (the guard starts in Fault; the first accepted reset holds the axes
    /// where they are).
    pub fn new(
        estimator: &EstimatorConfig,
        bias: Bias,
        config: StepConfig,
    ) -> Result<Self, StepConfigError> {
        config.check()?;
        let (calibration, profile) = (estimator.calibration, estimator.profile);
        let filter = estimator.filter;
        let estimator = Estimator::with_bias(estimator, bias)?;
        let support = SupportWatch::new(
            config.support,
            &calibration,
            &profile,
            estimator.tip_estimator(),
        )?;
        let (guarded_lag_s, sample_period_s) = guarded_filter(filter)?;
        let watch_period_s = if sample_period_s > 0.0 {
            sample_period_s
        } else {
            config.period_ns as f64 * 1e-9
        };
        let inertia_watch = InertiaWatch::new(
            config.inertia_watch,
            estimator.tip_estimator().inertia(),
            watch_period_s,
        )?;
        let out = LoopOutput::first(&estimator, inertia_watch.idle());
        let mut step = Self {
            calibration,
            profile,
            estimator,
            config,
            trajectory: None,
            last_joints: None,
            speed_mps: 0.0,
            last_drive_state: None,
            guarded_stop: None,
            guarded_last: None,
            guarded_rate_n_per_s: 0.0,
            guarded_lag_s,
            sample_period_s,
            force: ForceController::new(config.force_control)?,
            motion: AxesMotion::default(),
            inertia_watch,
            support,
            last_stream_ns: None,
            out,
            snapshot_fingerprint: 0,
        };
        // Hashed once here, not on the loop at every snapshot.
        step.snapshot_fingerprint = sar_snapshot::fingerprint(&step);
        Ok(step)
    }

    /// The output of the last cycle.
    pub fn last(&self) -> &LoopOutput {
        &self.out
    }

    /// The estimator (its bias, guard configuration).
    pub fn estimator(&self) -> &Estimator {
        &self.estimator
    }

    /// The settings.
    pub fn config(&self) -> &StepConfig {
        &self.config
    }

    /// Decides one cycle (see the module documentation). The result stays
    /// readable as [`LoopStep::last`] until the next cycle.
    pub fn step(&mut self, input: &LoopInput) -> &LoopOutput {
        // Gather: what the estimator judges (a held reset is not passed on).
        let found = self.absorb_late_cycle(input);
        let reference = self.following_reference(input, found.as_ref());
        self.measure_speed(&input.joints);
        let held = self.held_reset(input);
        let mut cycle_input = input.cycle_input();
        if held.is_some() {
            cycle_input.command = None;
        }
        let host_fault = self.host_fault(input);
        let (motion, axes_model) = self.carriage_motion(input, found.as_ref());
        // Judge: the estimator and its guard.
        let context = CycleContext {
            reference,
            host_fault,
            motion,
        };
        let awaiting = self.estimator.awaiting_first_reset();
        let estimate = *self.estimator.cycle(&cycle_input, &context);
        let inertia = self.watch_inertia(&estimate, found.as_ref(), &motion);
        // Decide, then commit once.
        let mut d = Decision::new(found, motion, axes_model);
        d.support_note = self.observe_support(input, &estimate, &motion, awaiting);
        if let Some(h) = held {
            d.reply = Some(self.held_reply(h, input));
        }
        self.decide(input, &estimate, held, &mut d);
        self.commit(input, estimate, reference, d);
        self.out.inertia = inertia;
        &self.out
    }

    /// The phases of a cycle's decision, in order, each one's result put in
    /// `d`: the answer to the guard, then to the request, force control's
    /// period, a brake, an excitation's end; what the drives are told of the
    /// trajectory.
    fn decide(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        held: Option<HeldReset>,
        d: &mut Decision,
    ) {
        if let Some(action) = drives::halt(input, estimate, held) {
            d.action = action;
            d.change(TrajectoryChange::Drop);
            if action == DriveAction::QuickStop {
                d.axes = AxesEvent::QuickStop;
            }
        }
        if let Some(outcome) = drives::command_outcome(input, estimate) {
            d.reply = Some(outcome.reply);
            if let Some((action, hold)) = outcome.released {
                (d.action, d.axes) = (action, AxesEvent::Released);
                d.change(hold);
            }
        }
        self.observe_force(input, estimate);
        if let Some(answered) = self.answer_request(input, estimate, d.decided.as_ref()) {
            d.reply = Some(answered.answer);
            d.change(answered.change);
            d.planned |= answered.started == Started::Move;
            d.accepted_motion = answered.started != Started::Nothing;
            if answered.note.is_some() {
                d.support_note = answered.note;
            }
        }
        if self.force.mode().is_some() && !estimate.guard_state.is_halting() {
            let change = self.force_period(input, estimate, d.decided.as_ref());
            d.change(change);
        }
        self.update_guarded_rate(input, estimate);
        if let Some(brake) = self.brake_if_due(input, estimate, d.decided.as_ref()) {
            d.change(TrajectoryChange::Replace(brake.trajectory));
            d.planned = true;
            d.guarded_stop = brake.guarded_stop;
        }
        d.change(self.end_excitation_if_due(input, estimate, d.decided.as_ref()));
        if let Some(action) = self.motion_action(input, estimate, d) {
            d.action = action;
        }
    }

    /// Answers the loop's own requests: force control and moves (the
    /// estimator's commands are answered by their event), from the
    /// trajectory as decided so far.
    fn answer_request(
        &mut self,
        input: &LoopInput,
        estimate: &CycleOutput,
        trajectory: Option<&Trajectory>,
    ) -> Option<Answered> {
        let target = match input.request {
            Some(Request::Hold { max_force_n }) => {
                let answer = self.start_force(input, estimate, ForceMode::Hold { max_force_n });
                return Some(Answered::only(answer));
            }
            Some(Request::Push { axial_n }) => {
                let answer = self.start_force(input, estimate, ForceMode::Push { axial_n });
                return Some(Answered::only(answer));
            }
            Some(Request::SupportConfirm) => {
                self.support.confirm();
                let cycle = estimate.cycle;
                return Some(Answered {
                    note: Some(self.support_note(cycle, SupportWhy::Confirmed)),
                    ..Answered::only((ReplyStatus::Accepted, ReplyDetail::None))
                });
            }
            Some(Request::Position) => {
                let change = self.end_force(input.now_ns, trajectory);
                return Some(Answered {
                    change,
                    ..Answered::only((ReplyStatus::Accepted, ReplyDetail::None))
                });
            }
            Some(Request::Excite(r)) => {
                let started = self.start_excitation(input, estimate, trajectory, &r);
                return Some(Answered::started(started, Started::Excitation));
            }
            Some(Request::MoveTip { tip_m }) => MoveTarget::Tip(tip_m, None),
            Some(Request::GuardedMove { tip_m, max_force_n }) => {
                MoveTarget::Tip(tip_m, Some(max_force_n))
            }
            Some(Request::BackOut { distance_m }) => MoveTarget::BackOut(distance_m),
            Some(Request::Reset | Request::Tare | Request::SetLimits(_)) | None => return None,
        };
        let planned = self.plan_move(input, estimate, trajectory, target);
        // An accepted move ends force control (it was planned from the last
        // set point); a refused one leaves the mode as it was.
        if planned.is_ok() {
            self.force.stop();
        }
        Some(Answered::started(planned, Started::Move))
    }

    /// What the drives are told of the trajectory when nothing else is said
    /// to them (not halting, the drives enabled): a streamed trajectory one
    /// period ahead, every cycle until the period after its end; a new plan
    /// its end point, once.
    fn motion_action(
        &self,
        input: &LoopInput,
        estimate: &CycleOutput,
        d: &Decision,
    ) -> Option<DriveAction> {
        let enabled = input.drive_state == Some(DriveState::Enabled);
        if estimate.guard_state.is_halting() || d.action != DriveAction::None || !enabled {
            return None;
        }
        let (Some(t), Some(now_ns)) = (d.decided, input.now_ns) else {
            return None;
        };
        if t.streamed {
            let ahead_ns = now_ns.saturating_add(self.config.period_ns);
            (now_ns <= t.end_ns.saturating_add(self.config.period_ns))
                .then(|| DriveAction::Stream(t.position(ahead_ns)))
        } else if d.planned {
            let [q1_m, q2_m, q3_m] = t.axes.map(|p| p.end_m());
            Some(DriveAction::Setpoint(ActiveJoints { q1_m, q2_m, q3_m }))
        } else {
            None
        }
    }
}

/// What a request started that must reach the drives in its cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Started {
    /// Nothing (a refusal, or a request that starts no motion).
    Nothing,
    /// A planned move: its end point goes to the drives.
    Move,
    /// An excitation: streamed.
    Excitation,
}

/// The answer to the loop's own request and what it decides of the
/// trajectory.
#[derive(Debug, Clone, Copy)]
struct Answered {
    answer: Answer,
    change: TrajectoryChange,
    started: Started,
    /// The support's status to log (a confirmation).
    note: Option<SupportNote>,
}

impl Answered {
    /// An answer that changes no trajectory.
    fn only(answer: Answer) -> Self {
        Self {
            answer,
            change: TrajectoryChange::Keep,
            started: Started::Nothing,
            note: None,
        }
    }

    /// A motion's trajectory, accepted; or its refusal.
    fn started(result: Result<Trajectory, Answer>, started: Started) -> Self {
        match result {
            Ok(t) => Self {
                answer: (ReplyStatus::Accepted, ReplyDetail::None),
                change: TrajectoryChange::Replace(t),
                started,
                note: None,
            },
            Err(refused) => Self::only(refused),
        }
    }
}
