//! Issue 35: the spike check sees every sample the sensor sent, not only
//! each cycle's newest. A late loop (a loaded host: here every cycle 4 ms
//! after the last, the sensor at 500 Hz, so two samples wait each cycle)
//! used to judge the newest alone, and a burst of one-packet spikes in the
//! older slot went unseen: the loop ran on Ok. Now the loop counts, while
//! draining the sensor, the jumps between consecutive samples
//! (`DrainedSamples`, recorded with the cycle's input) and the check takes
//! the counts: the tenth jump (the fifth spike's way back) faults
//! (`sensor_spikes`), and the recorded inputs replay to the same decisions
//! bit for bit.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_config as config;
use sar_daemon::sim;
use sar_estimator::guard::{GuardState, Reason};
use sar_hal::{Drained, ForceSensor, SimClock, WrenchSample};
use sar_loop::control::{Controller, Operator};
use sar_loop::logq;
use sar_loop::step::LoopStep;

/// A sensor whose samples are the simulator's, with a 30 N spike (along
/// the lever: sensor y, no torque) put into the older of the two samples
/// a late cycle drains, in the cycles `spike_cycles` (counted in drains).
struct OlderSlotSpikes<S> {
    inner: S,
    drains: u64,
    spike_cycles: Vec<u64>,
    spiked: u32,
}

impl<S: ForceSensor> ForceSensor for OlderSlotSpikes<S> {
    type Error = S::Error;

    fn poll(&mut self) -> Result<Option<WrenchSample>, S::Error> {
        // The newest sample: never spiked here.
        self.inner.poll()
    }

    fn wait(&mut self, timeout_ns: u64) -> Result<WrenchSample, S::Error> {
        self.inner.wait(timeout_ns)
    }

    fn tare(&mut self) -> Result<(), S::Error> {
        self.inner.tare()
    }

    fn clear_tare(&mut self) -> Result<(), S::Error> {
        self.inner.clear_tare()
    }

    fn drain(&mut self, out: &mut [WrenchSample]) -> Result<Drained, S::Error> {
        let d = self.inner.drain(out)?;
        self.drains += 1;
        if d.count >= 2 && self.spike_cycles.contains(&self.drains) {
            // The older of the cycle's samples (not the newest, which the
            // step reads).
            if let Some(s) = out.get_mut(d.count - 2) {
                s.force_n.y += 30.0;
                self.spiked += 1;
            }
        }
        Ok(d)
    }
}

#[test]
fn a_burst_of_one_packet_spikes_between_late_cycles_faults_at_the_tenth_jump() {
    let cfg = config::builtin().unwrap();
    let mut scenario = sim::demo_scenario().unwrap();
    // No contact: the guard stays Ok unless the spikes fault it.
    scenario.spec.contact = Vec::new();
    let clock = SimClock::new(1_000_000_000);
    let (_sim, sensor, drives, bias) = sim::simulated(&scenario, clock.clone()).unwrap();
    // Five spikes 20 ms (5 late cycles) apart, from 4 s (the first reset
    // waits for 500 samples at rest: 2 s of cycles that see one each).
    let first = 4000 / 4;
    let sensor = OlderSlotSpikes {
        inner: sensor,
        drains: 0,
        spike_cycles: (0..5).map(|k| first + 5 * k).collect(),
        spiked: 0,
    };
    let operator = Operator::new();
    let (log, _thread, _queue) = logq::channel(false);
    let step_config = cfg.step_config();
    let mut c = Controller::new(
        &cfg.estimator,
        bias,
        step_config,
        sensor,
        drives,
        operator,
        log,
        true,
    )
    .unwrap();
    let mut inputs = Vec::new();
    let mut fault_at = None;
    for cycle in 1..=first + 60 {
        // A late loop: 4 ms between cycles (two samples of the 500 Hz
        // sensor wait each time).
        clock.advance_ns(4_000_000);
        let t = clock.now_ns();
        let out = *c.step(cycle, || Some(t));
        inputs.push((*c.loop_input(), *c.decision()));
        if cycle == first - 1 {
            assert_eq!(
                out.guard_state,
                GuardState::Ok,
                "Ok before the spikes: {:?}",
                out.guard_reason
            );
        }
        if cycle >= first && fault_at.is_none() && out.guard_state == GuardState::Fault {
            fault_at = Some((cycle, out.guard_reason));
        }
    }
    let (cycle, reason) = fault_at.expect("the burst of spikes was not seen");
    assert!(
        matches!(reason, Reason::SensorSpikes { spikes: 10, .. }),
        "{reason:?}"
    );
    // The fifth spike's cycle: its way back is the tenth jump, in the
    // same cycle (the newest sample after it).
    assert_eq!(cycle, first + 20, "{reason:?}");
    // Every cycle's input says what was drained: two samples, and the
    // spikes' cycles two jumps each.
    let jumps: u32 = inputs
        .iter()
        .map(|(i, _)| u32::from(i.sensor.drained.jumps))
        .sum();
    assert!(inputs.iter().skip(1).all(|(i, _)| i.sensor.drained.counted));
    assert!(jumps >= 10, "{jumps} jumps counted");
    // The recorded inputs through a fresh step: the same decisions.
    let mut step = LoopStep::new(&cfg.estimator, bias, step_config).unwrap();
    for (k, (input, recorded)) in inputs.iter().enumerate() {
        let again = step.step(input);
        assert_eq!(
            format!("{again:?}"),
            format!("{recorded:?}"),
            "cycle {k} differs"
        );
    }
}
