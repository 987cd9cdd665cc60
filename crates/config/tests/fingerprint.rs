//! The snapshot fingerprint of the built-in configuration
//! (`default_config.toml`), as `sard --sim` builds its loop step from it,
//! pinned: it changes only when a configuration value, a fingerprinted
//! field's name or order, or the hash itself changes, never with a `Debug`
//! text or a refactor that keeps names and order.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use sar_estimator::Vec3;
use sar_estimator::cycle::Bias;
use sar_loop::step::LoopStep;

/// The fingerprint of the built-in configuration's loop step.
const DEFAULT_FINGERPRINT: u64 = 0x6506_bae4_6af4_6761;

fn step_of(cfg: &sar_config::Config, bias: Bias) -> LoopStep {
    LoopStep::new(&cfg.estimator, bias, cfg.step_config()).unwrap()
}

fn fingerprint_of(cfg: &sar_config::Config) -> u64 {
    sar_snapshot::fingerprint(&step_of(cfg, Bias::force_only(Vec3::zeros())))
}

#[test]
fn the_default_configuration_has_its_pinned_fingerprint() {
    let cfg = sar_config::builtin().unwrap();
    let got = fingerprint_of(&cfg);
    assert_eq!(
        got, DEFAULT_FINGERPRINT,
        "the fingerprint of the default configuration changed ({got:#018x}, pinned {DEFAULT_FINGERPRINT:#018x}). \
         If default_config.toml changed, or a fingerprinted field was renamed, added or moved, \
         pin the new value here. If what sar_snapshot's ConfigHash hashes (or how) changed, \
         every snapshot of every existing recording is now refused as taken under another \
         configuration: raise sar_snapshot::VERSION too, so that they are refused as another \
         format instead (and say so in the change)."
    );
    // The step caches the same value, and a snapshot carries it.
    let step = step_of(&cfg, Bias::force_only(Vec3::zeros()));
    let mut snap = sar_snapshot::Snapshot::new();
    step.snapshot(&mut snap).unwrap();
    assert_eq!(snap.fingerprint(), got);
    assert_eq!(sar_snapshot::VERSION, 7);
}

#[test]
fn the_bias_and_the_guard_limits_are_state_not_configuration() {
    // The start bias and the guard (its limits included: an operator may
    // change them at run time) are stored in the snapshot, not hashed.
    let cfg = sar_config::builtin().unwrap();
    let step = step_of(&cfg, Bias::force_only(Vec3::new(0.5, -0.25, 1.0)));
    assert_eq!(sar_snapshot::fingerprint(&step), fingerprint_of(&cfg));
    let text = sar_config::DEFAULT_TOML.replace("stop_total_n = 15.0", "stop_total_n = 14.0");
    assert_ne!(text, sar_config::DEFAULT_TOML);
    let other = sar_config::parse(&text, "test").unwrap();
    assert_eq!(fingerprint_of(&other), fingerprint_of(&cfg));
}

#[test]
fn every_part_of_the_configuration_changes_it() {
    let cfg = sar_config::builtin().unwrap();
    let base = fingerprint_of(&cfg);
    type Edit = fn(&mut sar_config::Config);
    let edits: [(&str, Edit); 10] = [
        ("axes.following_tolerance_m", |c| {
            c.axes.following_tolerance_m *= 2.0;
        }),
        ("the profile's length", |c| {
            let p = c.estimator.profile;
            c.estimator.profile = sar_kinematics::Profile::new(&sar_kinematics::ProfileSpec {
                length_m: p.length_m() + 1e-9,
                offset_m: p.offset_m(),
                mass_kg: p.mass_kg(),
                com_m: p.com_m(),
            })
            .unwrap();
        }),
        ("the plausibility's counter gap", |c| {
            let mut l = c.estimator.plausibility.limits();
            l.max_counter_gap += 1;
            c.estimator.plausibility = sar_estimator::cycle::PlausibilityConfig::new(l).unwrap();
        }),
        ("no filter", |c| {
            c.estimator.filter = None;
        }),
        ("the tip estimator's observability limit", |c| {
            c.estimator.tip.max_std_n *= 1.5;
        }),
        ("the rod's I_perp", |c| {
            c.estimator.inertia.inertia_perp_kgm2 *= 1.1;
        }),
        ("the rod's I_perp std", |c| {
            c.estimator.inertia.inertia_perp_std_kgm2 *= 1.1;
        }),
        ("the rod's I_axial", |c| {
            c.estimator.inertia.inertia_axial_kgm2 = 1e-4;
        }),
        ("the adapter's mass", |c| {
            c.estimator.inertia.adapter_mass_kg = 0.1;
        }),
        ("the excitation's speed limit", |c| {
            c.identify.excitation_max_speed_mps *= 0.5;
        }),
    ];
    for (what, edit) in edits {
        let mut changed = cfg.clone();
        edit(&mut changed);
        assert_ne!(fingerprint_of(&changed), base, "{what}");
    }
}
