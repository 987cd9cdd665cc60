//! The loop's pure step with force control (an axial push against a tissue)
//! beside the same step in position mode, in one criterion run (issue 15):
//! 1000 recorded cycles stepped from a cloned state, per batch. Beside them
//! (issue 17): taking a snapshot of the step's whole decision state (what
//! the recorder does on the loop at a recording's start and every
//! `[record] snapshot_s`), and restoring one (what replay does). Beside
//! the push (issue 26): the same inputs through a step without the model of
//! the drives' servo (`[axes] servo_bandwidth_hz = 0`), the baseline of the
//! model's cost (ten samples of its loop per cycle).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    missing_docs
)]

mod support;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use sar_config as config;
use sar_daemon::sim;
use sar_estimator::Vec3;
use sar_hal::SimClock;
use sar_loop::control::{Envelope, Operator, Request};
use sar_loop::logq;
use sar_loop::step::{LoopInput, LoopStep};
use sar_sim::{Tissue, TissueModel};
use std::hint::black_box;

/// Cycles measured per batch.
const N: usize = 1000;

/// The recorded inputs of a run on the simulator (a tissue 5 mm ahead of
/// the tip along the rod, 300 N/m), with a push of 3 N from cycle 1200 when
/// `push`; the step's state after `warm` cycles and the `N` inputs after.
fn recorded(push: bool, warm: usize) -> (LoopStep, Vec<LoopInput>) {
    recorded_with(push, warm, |_| {})
}

/// [`recorded`], the step built from the built-in configuration changed by
/// `edit` (the run recorded with the built-in one).
fn recorded_with(
    push: bool,
    warm: usize,
    edit: impl FnOnce(&mut config::Config),
) -> (LoopStep, Vec<LoopInput>) {
    let cfg = config::builtin().unwrap();
    let mut scenario = sim::demo_scenario().unwrap();
    scenario.spec.contact = Vec::new();
    scenario.spec.tissue = vec![Tissue {
        direction: Vec3::new(1.0, 0.0, 0.0),
        rest_m: Vec3::new(0.605, 0.2, 0.0),
        model: TissueModel::Linear {
            stiffness_n_per_m: 300.0,
        },
        damping_n_s_per_m: 5.0,
        breathing: None,
        shifts: Vec::new(),
    }];
    let clock = SimClock::new(1_000_000_000);
    let operator = Operator::new();
    let (log, _t, _q) = logq::channel(false);
    let (_sim, mut c, bias) =
        support::sim_controller(&cfg, &scenario, clock.clone(), operator.clone(), log);
    let mut inputs = Vec::new();
    for cycle in 1..=(warm + N) as u64 {
        if push && cycle == 1200 {
            let request = Request::Push { axial_n: 3.0 };
            operator.requests.push(Envelope { id: 1, request }).unwrap();
        }
        clock.advance_ns(1_000_000);
        c.step(cycle, || Some(clock.now_ns()));
        while operator.replies.pop().is_some() {}
        inputs.push(*c.loop_input());
    }
    let mut step_cfg = cfg.clone();
    edit(&mut step_cfg);
    let mut step = LoopStep::new(&step_cfg.estimator, bias, step_cfg.step_config()).unwrap();
    for input in &inputs[..warm] {
        step.step(input);
    }
    assert_eq!(step.last().force_mode.is_some(), push);
    (step, inputs.split_off(warm))
}

fn per_cycle(c: &mut Criterion) {
    let mut g = c.benchmark_group("step");
    g.throughput(criterion::Throughput::Elements(N as u64));
    let no_model = |c: &mut config::Config| c.axes.motion.servo_bandwidth_hz = 0.0;
    for (name, push, model) in [
        ("position (1000 cycles)", false, true),
        ("push 3 N (1000 cycles)", true, true),
        ("push 3 N, no servo model (1000 cycles)", true, false),
    ] {
        let (state, inputs) = if model {
            recorded(push, 5000)
        } else {
            recorded_with(push, 5000, no_model)
        };
        g.bench_function(name, |b| {
            b.iter_batched(
                || state.clone(),
                |mut s| {
                    for input in &inputs {
                        black_box(s.step(black_box(input)).action);
                    }
                    s
                },
                BatchSize::SmallInput,
            )
        });
    }
    g.finish();
    let mut g = c.benchmark_group("snapshot");
    let (state, _) = recorded(true, 5000);
    let mut snap = sar_snapshot::Snapshot::new();
    g.bench_function("take (push 3 N)", |b| {
        b.iter(|| black_box(&state).snapshot(&mut snap).unwrap())
    });
    state.snapshot(&mut snap).unwrap();
    let bytes = snap.as_bytes().to_vec();
    g.bench_function("restore (push 3 N)", |b| {
        b.iter_batched(
            || state.clone(),
            |mut s| {
                s.restore(black_box(&bytes)).unwrap();
                s
            },
            BatchSize::SmallInput,
        )
    });
    g.finish();
}

criterion_group!(benches, per_cycle);
criterion_main!(benches);
