//! `[loop]`: the control loop's rate, scheduling and the publisher's stall
//! limit.

use crate::decl::{int, num};
use crate::keys::ns;
use sar_loop::runloop::LoopConfig;

crate::section! {
    /// The control loop: its rate and its real-time thread.
    section "loop";
    /// the control loop's rate, Hz
    rate_hz: f64 = value(1000.0), num(100.0, 10_000.0, "Hz") => [LoopConfig.rate_hz];
    /// SCHED_FIFO priority of the loop thread
    priority: i64 = value(80), int(1, 99, "") => [LoopConfig.priority];
    /// pin the loop thread to this CPU
    cpu: i64 = absent("no pinning", 1), int(0, 1023, "") => [LoopConfig.cpu];
    /// publishing thread without progress this long: Fault
    publisher_stall_s: f64 = value(0.5), num(0.01, 60.0, "s") => [LoopConfig.publisher_stall_ns];
}

/// The loop's settings.
pub(crate) fn build(l: &Section) -> LoopConfig {
    LoopConfig {
        rate_hz: l.rate_hz,
        // 100..=10000 Hz: 1e5..=1e7 ns.
        period_ns: (1e9 / l.rate_hz).round() as u64,
        priority: i32::try_from(l.priority).unwrap_or(1),
        cpu: l.cpu.and_then(|c| usize::try_from(c).ok()),
        publisher_stall_ns: ns(l.publisher_stall_s),
    }
}
