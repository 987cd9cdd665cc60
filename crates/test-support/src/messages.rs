//! Deterministic messages of every topic, cycle by cycle (the recording's
//! tests push them), and the simulator's contact pulses.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use sar_msgs::cdr::FixedStr;
use sar_msgs::msgs::*;
use sar_sim::ContactKey;

/// splitmix64: a deterministic stream of bits.
pub fn mix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// A finite value with arbitrary low bits, in about [-50, 50).
pub fn val(seed: u64) -> f64 {
    (mix(seed) >> 11) as f64 / (1u64 << 53) as f64 * 100.0 - 50.0
}

/// Three values of [`val`].
pub fn v3(seed: u64) -> [f64; 3] {
    [val(seed), val(seed ^ 0x11), val(seed ^ 0x22)]
}

/// Cycle k's monotonic time: 4 kHz from t0 = 12 345 s.
pub fn now_ns(k: u64) -> u64 {
    12_345_000_000_000 + k * 250_000
}

/// Every message the daemon records in cycle `k` (a guard event every 100th).
pub fn cycle_messages(k: u64) -> Vec<Outgoing> {
    let t = now_ns(k);
    let mut out = vec![
        Outgoing::CycleInput(CycleInput {
            stamp_ns: t,
            cycle: k,
            now_ns: t,
            clock_status: ClockStatusCode::from_code((k % 3) as u8).unwrap(),
            sensor_force_n: v3(k),
            sensor_torque_nm: v3(k + 1),
            sensor_counter: (k as u32).wrapping_mul(7),
            sensor_status: (k % 5) as u32,
            sensor_stamp_ns: t - 90_000,
            sensor_valid: !k.is_multiple_of(7),
            joints_q_m: v3(k + 2),
            joints_stamp_ns: t - 120_000,
            joints_valid: !k.is_multiple_of(11),
            drive_state: DriveStateCode::from_code((k % 5) as u8).unwrap(),
            drive_fault_axis: if k % 4 == 3 { (k % 3) as i8 } else { -1 },
            drive_fault_code: if k % 4 == 3 { 0x2310 } else { 0 },
            target_q_m: v3(k + 3),
            target_valid: k.is_multiple_of(2),
            command_kind: CommandKindCode::ALL[(k % CommandKindCode::ALL.len() as u64) as usize],
            command_values: {
                let (a, b) = (v3(k + 4), v3(k + 5));
                [a[0], a[1], a[2], b[0], b[1], b[2]]
            },
            command_arg: mix(k),
            move_tip_m: v3(k + 17),
            limits_n: {
                let (a, b) = (v3(k + 18), v3(k + 19));
                [a[0], a[1], a[2], b[0], b[1], b[2]]
            },
            drive_action: DriveActionCode::from_code((k % 8) as u8).unwrap(),
            setpoint_q_m: v3(k + 20),
            reply_status: if k.is_multiple_of(3) {
                REPLY_NONE
            } else {
                (k % 12) as u8
            },
            reply_reason: (k % 26) as u16,
            limits_in_use_n: {
                let (a, b) = (v3(k + 21), v3(k + 22));
                [a[0], a[1], a[2], b[0], b[1], b[2]]
            },
            publisher_idle_ns: mix(k + 23) % 1_000_000_000,
            back_out_m: v3(k + 24)[0],
            move_max_force_n: v3(k + 25)[0],
            sensor_drained_counted: !k.is_multiple_of(13),
            sensor_drained_samples: (k % 17) as u16,
            sensor_drained_jumps: (k % 3) as u16,
            command_layout: CommandLayoutCode::ALL[(k % 2) as usize],
            hold_max_force_n: v3(k + 26)[0],
            push_axial_n: v3(k + 26)[1],
            excite_amplitude_m: v3(k + 27),
            excite_freq_hz: v3(k + 28),
            excite_duration_s: v3(k + 29)[0],
            excite_fade_s: v3(k + 29)[1],
        }),
        Outgoing::SensorWrench(WrenchStamped::sensor(t - 90_000, v3(k), v3(k + 1))),
        Outgoing::Joints(ActiveJointState {
            stamp_ns: t - 120_000,
            q_m: v3(k + 2),
        }),
        Outgoing::TipWrench(WrenchStamped::base_force(t, v3(k + 5))),
        Outgoing::TipWrenchFiltered(WrenchStamped::base_force(t, v3(k + 6))),
        Outgoing::PassiveJoints(PassiveJointState {
            stamp_ns: t,
            q_rad: [val(k + 7), val(k + 8)],
        }),
        Outgoing::EstimatorState(EstimatorState {
            stamp_ns: t,
            cycle: k,
            now_ns: t,
            sensor_stamp_ns: t - 90_000,
            joints_stamp_ns: t - 120_000,
            sensor_age_ns: 90_000,
            joints_age_ns: 120_000,
            tip_outcome: TipOutcomeCode::from_code((k % 5) as u8).unwrap(),
            ujoint_m: v3(k + 9),
            tip_m: v3(k + 10),
            support_distance_m: val(k + 11),
            ujoint_force_n: v3(k + 12),
            tip_force_n: v3(k + 5),
            tip_force_std_n: v3(k + 13),
            axial_n: val(k + 14),
            lateral_n: val(k + 15),
            torsion_nm: val(k + 16),
            tip_force_filtered_n: v3(k + 6),
            guard_state: GuardStateCode::from_code((k % 4) as u8).unwrap(),
            guard_reason_code: (k % 16) as u8,
            guard_reason_text: FixedStr::new(&format!("reason of cycle {k}: ü")).unwrap(),
            flags: (mix(k) & 0x7f) as u32,
        }),
    ];
    if k.is_multiple_of(100) {
        out.push(Outgoing::GuardEvent(GuardEvent {
            stamp_ns: t,
            cycle: k,
            from_state: GuardStateCode::Ok,
            to_state: GuardStateCode::Warn,
            reason_code: 22, // above_warn
            reason_text: FixedStr::new(
                "total tip force 4.200 N is at or above the warn limit 4.000 N",
            )
            .unwrap(),
        }));
    }
    out
}

/// A tip contact that ramps from nothing at `start_ns` to `force_n` at
/// `on_ns`, holds it until `hold_ns` and is gone at `off_ns` (simulator keys).
pub fn contact_pulse(
    start_ns: u64,
    on_ns: u64,
    hold_ns: u64,
    off_ns: u64,
    force_n: sar_kinematics::Vec3,
) -> Vec<ContactKey> {
    let zero = sar_kinematics::Vec3::zeros();
    [
        (start_ns, zero),
        (on_ns, force_n),
        (hold_ns, force_n),
        (off_ns, zero),
    ]
    .into_iter()
    .map(|(t_ns, force_n)| ContactKey { t_ns, force_n })
    .collect()
}

/// A push of 20 N along the rod (+X0 at the demo's start: above its stop
/// limit) as a [`contact_pulse`] of the times `[start, on, hold, off]`, ns.
pub fn rod_push_20n([start_ns, on_ns, hold_ns, off_ns]: [u64; 4]) -> Vec<ContactKey> {
    let force_n = sar_kinematics::Vec3::new(20.0, 0.0, 0.0);
    contact_pulse(start_ns, on_ns, hold_ns, off_ns, force_n)
}
