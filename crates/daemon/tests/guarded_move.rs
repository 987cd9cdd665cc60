//! Guarded moves (issue 15, force control): `sarctl move-tip X Y Z
//! --max-force N` through the real controller on the simulator in simulated
//! time, into a tissue that pushes back (the simulator's spring-damper, its
//! surface 5 mm ahead of the tip along the rod). The move is braked in the
//! cycle the filtered tip force reaches N, reports where and at what force,
//! and the largest true force stays bounded; the figures for 100 to 3000 N/m
//! are printed (`--nocapture`). Bad limits are refused with their cause; the
//! runs replay bit for bit through a fresh step; a recorded guarded move
//! decodes back to the same request.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_daemon::control::{Controller, Envelope, Operator, Reply, ReplyStatus, Request};
use sar_daemon::step::{LoopInput, LoopOutput, LoopStep, ReplyDetail};
use sar_daemon::{config, logq, sim};
use sar_drivers::SimClock;
use sar_drivers::sim::{SimDrives, SimSensor, Simulator, Tissue, TissueModel};
use sar_estimator::Vec3;
use sar_estimator::guard::GuardState;

struct Rig {
    c: Controller<SimSensor<SimClock>, SimDrives<SimClock>>,
    sim: Simulator<SimClock>,
    clock: SimClock,
    operator: Operator,
    cycle: u64,
    log: Vec<(LoopInput, LoopOutput)>,
    cfg: config::Config,
}

/// The tip at rest, base frame, m (the demo's start), and the rod's
/// direction there (+X0: the support is at x = 0.45 m).
const TIP_M: [f64; 3] = [0.6, 0.2, 0.0];

impl Rig {
    /// The demo robot with a tissue of stiffness `k` whose surface is
    /// `gap_m` ahead of the tip along +X0; reset after the mean at rest.
    fn new(k_n_per_m: f64, gap_m: f64) -> Self {
        let cfg = config::builtin().unwrap();
        let mut scenario = sim::demo_scenario().unwrap();
        scenario.spec.contact = Vec::new();
        scenario.spec.tissue = vec![Tissue {
            direction: Vec3::new(1.0, 0.0, 0.0),
            rest_m: Vec3::new(TIP_M[0] + gap_m, TIP_M[1], TIP_M[2]),
            model: TissueModel::Linear {
                stiffness_n_per_m: k_n_per_m,
            },
            damping_n_s_per_m: 5.0,
            breathing: None,
            shifts: Vec::new(),
        }];
        let clock = SimClock::new(1_000_000_000);
        let (sim, sensor, drives, bias) = sim::simulated(&scenario, clock.clone()).unwrap();
        let operator = Operator::new();
        let (log, _t, _q) = logq::channel(false);
        let c = Controller::new(
            &cfg.estimator,
            bias,
            cfg.step_config(),
            sensor,
            drives,
            operator.clone(),
            log,
            true,
        )
        .unwrap();
        let mut rig = Self {
            c,
            sim,
            clock,
            operator,
            cycle: 0,
            log: Vec::new(),
            cfg,
        };
        // The automatic reset, once the mean at rest is complete.
        for _ in 0..1100 {
            rig.step();
        }
        assert_eq!(rig.c.output().guard_state, GuardState::Ok);
        rig
    }

    fn step(&mut self) -> LoopOutput {
        self.cycle += 1;
        self.clock.advance_ns(1_000_000);
        let clock = self.clock.clone();
        self.c.step(self.cycle, || Some(clock.now_ns()));
        let d = *self.c.decision();
        self.log.push((*self.c.loop_input(), d));
        d
    }

    fn request(&mut self, id: u64, request: Request) -> Reply {
        self.operator
            .requests
            .push(Envelope { id, request })
            .unwrap();
        self.step();
        let r = self.operator.replies.pop().unwrap();
        assert_eq!(r.id, id);
        r
    }

    fn true_force_n(&self) -> f64 {
        self.sim.truth().unwrap().tip_force_n.norm()
    }

    fn replays_bit_for_bit(&self) {
        let scenario = sim::demo_scenario().unwrap();
        let bias = sar_estimator::cycle::Bias {
            force_n: scenario.spec.sensor.bias_n,
            torque_nm: scenario.spec.sensor.bias_nm,
        };
        let mut step = LoopStep::new(&self.cfg.estimator, bias, self.cfg.step_config()).unwrap();
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

/// What one guarded move into the tissue did.
struct Outcome {
    stop_force_n: f64,
    largest_true_n: f64,
    final_true_n: f64,
    stop_after_ms: u64,
}

fn guarded_move_into(k_n_per_m: f64, max_force_n: f64) -> (Rig, Outcome) {
    let gap_m = 0.005;
    let mut rig = Rig::new(k_n_per_m, gap_m);
    // Along the rod, half as deep again into the tissue as the limit needs.
    let depth_m = 1.5 * max_force_n / k_n_per_m + 0.005;
    let target = Vec3::new(TIP_M[0] + gap_m + depth_m, TIP_M[1], TIP_M[2]);
    let r = rig.request(
        1,
        Request::GuardedMove {
            tip_m: target,
            max_force_n,
        },
    );
    assert_eq!(r.status, ReplyStatus::Accepted, "{}", r.detail);
    let start = rig.cycle;
    let mut largest_true_n = 0.0f64;
    let mut stop = None;
    for _ in 0..6000 {
        let d = rig.step();
        largest_true_n = largest_true_n.max(rig.true_force_n());
        assert!(
            !d.estimate.guard_state.is_halting(),
            "k {k_n_per_m}: halted: {:?}",
            d.estimate.guard_reason
        );
        if stop.is_none() {
            stop = d.guarded_stop;
        }
    }
    let stop = stop.unwrap_or_else(|| panic!("k {k_n_per_m}: never braked"));
    assert!(stop.cycle > start);
    assert!(
        stop.force_n.norm() >= max_force_n,
        "braked below the limit: {}",
        stop.force_n.norm()
    );
    // It stopped short of the target, in the tissue.
    assert!(
        stop.tip_m.x > TIP_M[0] + gap_m && stop.tip_m.x < target.x - 0.001,
        "k {k_n_per_m}: braked at {:?}",
        stop.tip_m
    );
    let out = Outcome {
        stop_force_n: stop.force_n.norm(),
        largest_true_n,
        final_true_n: rig.true_force_n(),
        stop_after_ms: stop.cycle - start,
    };
    (rig, out)
}

#[test]
fn a_guarded_move_into_tissue_is_braked_at_its_force() {
    let max_force_n = 4.0;
    for k in [100.0, 300.0, 1000.0, 3000.0] {
        let (rig, o) = guarded_move_into(k, max_force_n);
        println!(
            "guarded move at 20 mm/s into {k} N/m, --max-force {max_force_n}: braked {} ms after the command at |F| {:.2} N (filtered); largest true |F| {:.2} N; at rest after {:.2} N",
            o.stop_after_ms, o.stop_force_n, o.largest_true_n, o.final_true_n
        );
        // The overshoot: the filter's lag and the braking distance (20 mm/s
        // at 0.2 m/s^2: 1 mm) times the stiffness; below the warn limit
        // (8 N axial) up to 1000 N/m.
        if k <= 1000.0 {
            assert!(o.largest_true_n < 8.0, "k {k}: {:.2} N", o.largest_true_n);
        }
        assert!(o.final_true_n <= o.largest_true_n + 1e-9);
        if k == 300.0 {
            rig.replays_bit_for_bit();
        }
    }
}

#[test]
fn guarded_move_limits_are_checked() {
    let mut rig = Rig::new(300.0, 0.010);
    let target = Vec3::new(TIP_M[0] + 0.005, TIP_M[1], TIP_M[2]);
    for bad in [0.0, -1.0, f64::NAN, 1e3] {
        let r = rig.request(
            2,
            Request::GuardedMove {
                tip_m: target,
                max_force_n: bad,
            },
        );
        assert_eq!(r.status, ReplyStatus::BadArgument, "{bad}");
        assert!(matches!(r.detail, ReplyDetail::BadMaxForce { .. }), "{bad}");
        assert!(r.detail.to_string().contains("stop limit"), "{}", r.detail);
    }
    // A limit below the force there is already (the estimate's own noise
    // and bias are above 0.01 N): refused, saying so.
    let r = rig.request(
        3,
        Request::GuardedMove {
            tip_m: target,
            max_force_n: 0.001,
        },
    );
    assert_eq!(r.status, ReplyStatus::Refused);
    assert!(
        matches!(r.detail, ReplyDetail::AlreadyAtForce { .. }),
        "{:?}",
        r.detail
    );
    // Nothing moved.
    assert!(rig.log.iter().all(|(_, d)| d.guarded_stop.is_none()));
}

#[test]
fn a_recorded_guarded_move_decodes_to_the_same_request() {
    let mut rig = Rig::new(300.0, 0.010);
    let request = Request::GuardedMove {
        tip_m: Vec3::new(0.61, 0.2, 0.0),
        max_force_n: 2.5,
    };
    rig.request(4, request);
    let (input, decision) = *rig.log.last().unwrap();
    let msg = sar_daemon::record::convert::cycle_input_msg(&input, &decision);
    assert_eq!(msg.move_max_force_n, 2.5);
    let back = sar_daemon::record::convert::loop_input(&msg);
    assert_eq!(back.request, Some(request));
    // And a plain move stays plain.
    let plain = Request::MoveTip {
        tip_m: Vec3::new(0.6, 0.2, 0.001),
    };
    rig.request(5, plain);
    let (input, decision) = *rig.log.last().unwrap();
    let msg = sar_daemon::record::convert::cycle_input_msg(&input, &decision);
    assert_eq!(msg.move_max_force_n, 0.0);
    assert_eq!(
        sar_daemon::record::convert::loop_input(&msg).request,
        Some(plain)
    );
}
