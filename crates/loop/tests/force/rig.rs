//! The force-control test rig: the real controller on the simulator in
//! simulated time (1 ms per cycle), the demo robot with its tip at
//! [`TIP_M`] (the rod along +X0), tissues that push back and a contact
//! script; every cycle's input and decision kept for a replay bit for bit.
#![allow(dead_code, clippy::unwrap_used)]

use sar_daemon::sim;
use sar_estimator::Vec3;
use sar_estimator::guard::GuardState;
use sar_hal::SimClock;
use sar_sim::{
    Breathing, ContactKey, PlantSpec, RodInertia, ServoSpec, SimDrives, SimSpec, Tissue,
    TissueModel, TissueShift,
};
use sar_test_support::rig::{RigBuilder, SimRig};

/// The tip at rest, base frame, m (the demo's start); the rod points +X0.
pub const TIP_M: [f64; 3] = [0.6, 0.2, 0.0];

/// The cycles the rig runs before it is ready (the first reset after the
/// mean at rest), ms of simulated time.
pub const READY_MS: u64 = 1100;

/// A linear tissue along +X0 (the rod) of stiffness `k`, 5 N s/m, whose
/// surface is `gap_m` ahead of the tip, breathing `breath_m` at 0.25 Hz
/// along the rod, with sudden `shifts`.
pub fn tissue(k_n_per_m: f64, gap_m: f64, breath_m: f64, shifts: Vec<TissueShift>) -> Tissue {
    let x = Vec3::new(1.0, 0.0, 0.0);
    Tissue {
        direction: x,
        rest_m: Vec3::new(TIP_M[0] + gap_m, TIP_M[1], TIP_M[2]),
        model: TissueModel::Linear {
            stiffness_n_per_m: k_n_per_m,
        },
        damping_n_s_per_m: 5.0,
        breathing: (breath_m > 0.0).then_some(Breathing {
            amplitude_m: breath_m,
            hz: 0.25,
            direction: x,
        }),
        shifts,
    }
}

/// The simulator's plant under the rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Plant {
    /// The demo scenario's plant as it is (none of issue 26's parts: no
    /// inertia, ideal axes).
    Demo,
    /// Issue 26's plant in motion: the rod's inertia (the slender rod's
    /// m L^2 / 12, no adapter) and each axis a servo of 30 Hz, damping 0.7,
    /// 5 m/s^2 (the scenario keys' defaults).
    Moving,
    /// The servos of [`Plant::Moving`] without the rod's inertia: the lag
    /// alone (what the loop sees once the estimator compensates the
    /// inertia exactly).
    Servo,
}

impl Plant {
    /// The simulator's plant for `spec`'s rod.
    pub fn spec(self, spec: &SimSpec) -> PlantSpec {
        match self {
            Plant::Demo => spec.plant,
            Plant::Moving => {
                let p = &spec.profile;
                PlantSpec {
                    inertia: Some(RodInertia {
                        inertia_perp_kgm2: p.mass_kg() * p.length_m().powi(2) / 12.0,
                        inertia_axial_kgm2: 0.0,
                        adapter_mass_kg: 0.0,
                    }),
                    ..Plant::Servo.spec(spec)
                }
            }
            Plant::Servo => PlantSpec {
                inertia: None,
                servo: Some(ServoSpec {
                    bandwidth_hz: 30.0,
                    damping: 0.7,
                    max_accel_mps2: 5.0,
                    delay_ns: 0,
                    inner_loop_hz: 0.0,
                }),
                ..spec.plant
            },
        }
    }
}

/// The demo robot on the simulator, ready (see [`SimRig`]).
pub struct Rig(pub SimRig<SimDrives<SimClock>>);

sar_test_support::deref_rig!(Rig => SimRig<SimDrives<SimClock>>);

impl Rig {
    /// The demo robot; a tissue of stiffness `k` whose surface is `gap_m`
    /// ahead of the tip along the rod, breathing `breath_m` at 0.25 Hz;
    /// `contact` on top. Reset after the mean at rest.
    pub fn new(k_n_per_m: f64, gap_m: f64, breath_m: f64, contact: Vec<ContactKey>) -> Self {
        Self::with(
            vec![tissue(k_n_per_m, gap_m, breath_m, Vec::new())],
            contact,
        )
    }

    /// The demo robot with these tissues and contact script, reset after
    /// the mean at rest ([`READY_MS`]).
    pub fn with(tissues: Vec<Tissue>, contact: Vec<ContactKey>) -> Self {
        Self::with_plant(tissues, contact, Plant::Demo)
    }

    /// [`Rig::with`] on the plant `plant`.
    pub fn with_plant(tissues: Vec<Tissue>, contact: Vec<ContactKey>, plant: Plant) -> Self {
        Self::with_scenario(tissues, contact, plant, |_| {})
    }

    /// [`Rig::with_plant`] with the scenario's spec changed by `edit` (the
    /// support moving, the drives' quick stop, ...) after the rig's parts.
    pub fn with_scenario(
        tissues: Vec<Tissue>,
        contact: Vec<ContactKey>,
        plant: Plant,
        edit: impl FnOnce(&mut SimSpec),
    ) -> Self {
        let mut scenario = sim::demo_scenario().unwrap();
        scenario.spec.contact = if contact.is_empty() {
            vec![ContactKey {
                t_ns: 0,
                force_n: Vec3::zeros(),
            }]
        } else {
            contact
        };
        scenario.spec.tissue = tissues;
        scenario.spec.plant = plant.spec(&scenario.spec);
        edit(&mut scenario.spec);
        let mut rig = Self(RigBuilder::new(&scenario).build());
        for _ in 0..READY_MS {
            rig.step();
        }
        assert_eq!(
            rig.c.output().guard_state,
            GuardState::Ok,
            "{:?}",
            rig.c.output().guard_reason
        );
        rig
    }

    /// [`Rig::with_plant`] running `cfg` instead of the built-in
    /// configuration (the simulated drives' limits set from it, as `sard
    /// --sim` sets them).
    pub fn with_config(
        tissues: Vec<Tissue>,
        contact: Vec<ContactKey>,
        plant: Plant,
        cfg: &sar_config::Config,
    ) -> Self {
        let seed = sim::demo_scenario().unwrap().spec.seed;
        Self::with_config_seed(tissues, contact, plant, cfg, seed)
    }

    /// [`Rig::with_config`] with the simulator's noise seeded by `seed`.
    pub fn with_config_seed(
        tissues: Vec<Tissue>,
        contact: Vec<ContactKey>,
        plant: Plant,
        cfg: &sar_config::Config,
        seed: u64,
    ) -> Self {
        let mut scenario = sim::demo_scenario().unwrap();
        scenario.spec.seed = seed;
        scenario.spec.contact = if contact.is_empty() {
            vec![ContactKey {
                t_ns: 0,
                force_n: Vec3::zeros(),
            }]
        } else {
            contact
        };
        scenario.spec.tissue = tissues;
        scenario.spec.plant = plant.spec(&scenario.spec);
        scenario.spec.axes.max_speed_mps = cfg.axes.max_speed_mps;
        scenario.spec.axes.max_accel_mps2 = cfg.axes.max_accel_mps2;
        let mut rig = Self(RigBuilder::new(&scenario).config(cfg).build());
        for _ in 0..READY_MS {
            rig.step();
        }
        assert_eq!(
            rig.c.output().guard_state,
            GuardState::Ok,
            "{:?}",
            rig.c.output().guard_reason
        );
        rig
    }

    /// [`Rig::with`] without the rod's inertia (the demo's servos kept),
    /// for a test whose figure is not the motion's.
    pub fn without_inertia(tissues: Vec<Tissue>, contact: Vec<ContactKey>) -> Self {
        Self::with_scenario(tissues, contact, Plant::Demo, |s| s.plant.inertia = None)
    }

    /// [`Rig::new`] on the static plant of before issue 26 (no inertia,
    /// ideal axes, a quick stop at the planned acceleration).
    pub fn static_plant(k_n_per_m: f64, gap_m: f64, breath_m: f64) -> Self {
        let tissues = vec![tissue(k_n_per_m, gap_m, breath_m, Vec::new())];
        Self::with_scenario(tissues, Vec::new(), Plant::Demo, |s| {
            s.plant = PlantSpec::default();
        })
    }

    /// The true F_tip, base frame, N.
    pub fn true_force_n(&self) -> Vec3 {
        self.sim.truth().unwrap().tip_force_n
    }
}

/// Root mean square.
pub fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}
