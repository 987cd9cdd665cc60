//! The one builder of the daemon tests' simulated rigs: the real controller
//! on the simulator of a scenario, on a simulated clock that starts at 1 s,
//! with the built-in configuration unless told otherwise, the automatic
//! reset on and the log events kept in their queue (no thread drains them).
//! A rig steps 1 ms of simulated time per cycle and keeps every cycle's
//! input and decision, for a replay bit for bit through a fresh step.
#![allow(clippy::unwrap_used, clippy::panic)]

use sar_config as config;
use sar_daemon::sim;
use sar_estimator::cycle::Bias;
use sar_hal::{AxisDrives, ForceSensor, SimClock};
use sar_loop::control::{Controller, Envelope, Operator, Reply, Request};
use sar_loop::logq::{self, LogQueue, LogSender};
use sar_loop::step::{LoopInput, LoopOutput, LoopStep, StepConfig, StepConfigError};
use sar_sim::scenario::Scenario;
use sar_sim::{ContactKey, SimDrives, SimSensor, Simulator};

/// What a rig is made of.
pub struct SimRig<D: AxisDrives> {
    /// The controller (the step, the simulated sensor, the drives).
    pub c: Controller<SimSensor<SimClock>, D>,
    /// The simulator (its truth, its faults).
    pub sim: Simulator<SimClock>,
    /// The simulated clock the simulator and the tests advance.
    pub clock: SimClock,
    /// The operator's side of the controller's queues.
    pub operator: Operator,
    /// The configuration the controller runs.
    pub cfg: config::Config,
    /// The controller's log events.
    pub queue: LogQueue,
    /// The scenario's start bias, which the estimator starts with.
    pub bias: Bias,
    /// The loop's settings the controller runs.
    pub step_config: StepConfig,
    /// The cycles stepped so far by [`SimRig::step`].
    pub cycle: u64,
    /// Every cycle's input and decision stepped by [`SimRig::step`].
    pub log: Vec<(LoopInput, LoopOutput)>,
}

impl<D: AxisDrives> SimRig<D> {
    /// One cycle, 1 ms of simulated time after the last: its decision (the
    /// input and the decision kept in [`SimRig::log`]).
    pub fn step(&mut self) -> LoopOutput {
        self.step_after(1_000_000)
    }

    /// One cycle `dt_ns` of simulated time after the last (more than the
    /// 1 ms period: a late cycle; the simulator ran on meanwhile): its
    /// decision, kept as [`SimRig::step`]'s.
    pub fn step_after(&mut self, dt_ns: u64) -> LoopOutput {
        self.cycle += 1;
        self.clock.advance_ns(dt_ns);
        let clock = self.clock.clone();
        self.c.step(self.cycle, || Some(clock.now_ns()));
        let d = *self.c.decision();
        self.log.push((*self.c.loop_input(), d));
        d
    }

    /// Applies `request` in the next cycle and returns its reply.
    pub fn request(&mut self, id: u64, request: Request) -> Reply {
        self.operator
            .requests
            .push(Envelope { id, request })
            .unwrap();
        self.step();
        let r = self.operator.replies.pop().unwrap();
        assert_eq!(r.id, id);
        r
    }

    /// Steps until `done` holds, at most `max` cycles: that decision.
    pub fn until(&mut self, max: u32, done: impl Fn(&LoopOutput) -> bool) -> Option<LoopOutput> {
        (0..max).map(|_| self.step()).find(|d| done(d))
    }

    /// The run's inputs through a fresh step give the same decisions.
    pub fn replays_bit_for_bit(&self) {
        let mut step = LoopStep::new(&self.cfg.estimator, self.bias, self.step_config).unwrap();
        for (k, (input, recorded)) in self.log.iter().enumerate() {
            let again = step.step(input);
            assert_eq!(
                format!("{again:?}"),
                format!("{recorded:?}"),
                "cycle {k} differs"
            );
        }
    }
}

/// `Deref` and `DerefMut` of a test's rig type `$rig` (a tuple struct of
/// one field) to the [`SimRig`] `$target` it wraps: the test's own methods
/// beside the shared ones.
#[macro_export]
macro_rules! deref_rig {
    ($rig:ty => $target:ty) => {
        impl ::std::ops::Deref for $rig {
            type Target = $target;
            fn deref(&self) -> &$target {
                &self.0
            }
        }
        impl ::std::ops::DerefMut for $rig {
            fn deref_mut(&mut self) -> &mut $target {
                &mut self.0
            }
        }
    };
}

/// The real controller running `cfg` (its loop settings too) with the
/// automatic reset on, as `sard` makes it, on `sensor` and `drives` (any:
/// simulated, emulated or real), the estimator starting from `bias`.
pub fn controller<S: ForceSensor, D: AxisDrives>(
    cfg: &config::Config,
    bias: Bias,
    sensor: S,
    drives: D,
    operator: Operator,
    log: LogSender,
) -> Result<Controller<S, D>, StepConfigError> {
    let step_config = cfg.step_config();
    Controller::new(
        &cfg.estimator,
        bias,
        step_config,
        sensor,
        drives,
        operator,
        log,
        true,
    )
}

/// Builds a [`SimRig`].
pub struct RigBuilder {
    scenario: Scenario,
    cfg: Option<config::Config>,
    step_config: Option<StepConfig>,
    auto_reset: bool,
}

impl RigBuilder {
    /// A rig on `scenario`.
    pub fn new(scenario: &Scenario) -> Self {
        Self {
            scenario: scenario.clone(),
            cfg: None,
            step_config: None,
            auto_reset: true,
        }
    }

    /// A rig on the built-in demo scenario with the tip contact `contact`
    /// (simulator keys) instead of its own.
    pub fn demo(contact: Vec<ContactKey>) -> Self {
        let mut scenario = sim::demo_scenario().unwrap();
        scenario.spec.contact = contact;
        Self::new(&scenario)
    }

    /// Without the demo's automatic reset (the operator resets).
    pub fn without_auto_reset(mut self) -> Self {
        self.auto_reset = false;
        self
    }

    /// Runs `cfg` instead of the built-in configuration.
    pub fn config(mut self, cfg: &config::Config) -> Self {
        self.cfg = Some(cfg.clone());
        self
    }

    /// Steps with `step_config` instead of the configuration's.
    pub fn step_config(mut self, step_config: StepConfig) -> Self {
        self.step_config = Some(step_config);
        self
    }

    /// The rig with the simulator's drives.
    pub fn build(self) -> SimRig<SimDrives<SimClock>> {
        self.build_with(|drives| drives)
    }

    /// The rig with the simulator's drives wrapped by `wrap` (a test's
    /// faulty drives).
    pub fn build_with<D: AxisDrives>(
        self,
        wrap: impl FnOnce(SimDrives<SimClock>) -> D,
    ) -> SimRig<D> {
        let cfg = match self.cfg {
            Some(cfg) => cfg,
            None => config::builtin().unwrap(),
        };
        let clock = SimClock::new(1_000_000_000);
        let (sim, sensor, drives, bias) = sim::simulated(&self.scenario, clock.clone()).unwrap();
        let operator = Operator::new();
        let (log, _thread, queue) = logq::channel(false);
        let step_config = self.step_config.unwrap_or_else(|| cfg.step_config());
        let c = Controller::new(
            &cfg.estimator,
            bias,
            step_config,
            sensor,
            wrap(drives),
            operator.clone(),
            log,
            self.auto_reset,
        )
        .unwrap();
        SimRig {
            c,
            sim,
            clock,
            operator,
            cfg,
            queue,
            bias,
            step_config,
            cycle: 0,
            log: Vec::new(),
        }
    }
}
