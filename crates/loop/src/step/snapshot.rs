//! The step's snapshots (issue 17): the whole decision state, restorable
//! into a step built from the same configuration ([`LoopStep::snapshot`],
//! [`LoopStep::restore`]); every field of [`LoopStep`] is classified
//! (`snap_state!`: a new one does not compile until placed).

use super::LoopStep;
use super::config::StepConfig;
use super::trajectory::Trajectory;
use super::vocabulary::GuardedStop;

// Snapshots (issue 17): the whole decision state, restorable into a step
// built from the same configuration ([`LoopStep::snapshot`]). `out` is the
// latest cycle's result, rewritten whole by every cycle.
sar_snapshot::snap_struct!(GuardedStop {
    cycle,
    tip_m,
    force_n,
    max_force_n,
});
sar_snapshot::snap_struct!(Trajectory {
    axes,
    target_tip_m,
    end_ns,
    streamed,
    max_force_n,
    excite,
});
// The configuration fingerprint (names and values, never `Debug`).
sar_snapshot::config_struct!(StepConfig {
    travel_m,
    axis_limits,
    following_tolerance_m,
    retreat_speed_mps,
    period_ns,
    publisher_stall_ns,
    force_control,
    motion,
    excite,
    inertia_watch,
    support,
});
sar_snapshot::snap_state!(LoopStep {
    state: [
        trajectory,
        last_joints,
        speed_mps,
        last_drive_state,
        guarded_stop,
        guarded_last,
        guarded_rate_n_per_s,
        motion,
        last_stream_ns,
    ],
    nested: [estimator, force, inertia_watch, support],
    config: [calibration, profile, config, guarded_lag_s, sample_period_s],
    output: [out],
    derived: [snapshot_fingerprint],
});

/// The kind number of a [`LoopStep`] snapshot (the snapshot header's kind).
pub const SNAPSHOT_KIND_LOOP_STEP: u16 = 1;

impl LoopStep {
    /// Writes the whole decision state into `out`, between two cycles. No
    /// allocation; the configuration is not stored: its fingerprint, hashed
    /// once at construction, is.
    pub fn snapshot(
        &self,
        out: &mut sar_snapshot::Snapshot,
    ) -> Result<(), sar_snapshot::SnapshotError> {
        sar_snapshot::take_with(
            self,
            SNAPSHOT_KIND_LOOP_STEP,
            self.snapshot_fingerprint,
            out,
        )
    }

    /// Restores a snapshot taken by [`LoopStep::snapshot`] of a step built
    /// from the same configuration: from the next cycle on this step decides
    /// exactly what that one did. Every check of the bytes is made first;
    /// on an error the step is unchanged.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), sar_snapshot::SnapshotError> {
        let fingerprint = self.snapshot_fingerprint;
        sar_snapshot::restore_with(self, SNAPSHOT_KIND_LOOP_STEP, fingerprint, bytes)
    }
}
