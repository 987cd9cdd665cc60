//! The workspace's shared test rigs. A dev-dependency only (never a normal
//! one): integration tests and benchmarks of any crate may use it, since they
//! link the crates' normal libraries, the same ones this crate links.
//!
//! - [`rig`]: the one builder of the simulated rigs (the real controller on
//!   the simulator of a scenario, on a simulated clock).
//! - [`drives`]: the one pass-through drive wrapper ([`drives::Hooked`]),
//!   which forwards every call to the drives it wraps except those its hook
//!   takes over (a blocked axis, a refused quick stop, a truth tap).
//! - [`truth`]: the simulator's truth at every position read of a run.
//! - [`counting`]: the counting global allocator of the no-alloc tests (a
//!   test binary declares it: `#[global_allocator] static GLOBAL:
//!   sar_test_support::counting::Counting = sar_test_support::counting::Counting;`).
//! - [`messages`]: deterministic messages of every topic, cycle by cycle.
//! - [`process`]: a program run to its end that must succeed ([`process::run_ok`]).
//! - [`files`]: scratch directories ([`scratch!`]), named pipes, a
//!   configuration that records.

pub mod counting;
pub mod drives;
pub mod files;
pub mod messages;
pub mod process;
pub mod rig;
pub mod truth;

/// A fresh scratch directory `name` under the test's target tmp dir, in a
/// folder of its package (`CARGO_TARGET_TMPDIR` is only set for tests and
/// benchmarks, so the macro reads it where it is used).
#[macro_export]
macro_rules! scratch {
    ($name:expr) => {
        $crate::files::scratch_in(env!("CARGO_TARGET_TMPDIR"), env!("CARGO_PKG_NAME"), $name)
    };
}
