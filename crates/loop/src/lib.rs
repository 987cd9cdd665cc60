//! The SAR control loop (`sar-loop`), below the daemon: the pure per-cycle
//! step and the controller that runs it, with what the loop needs at its
//! edges and nothing of files, configuration or transport.
//!
//! - [`step`]: the pure step, a function of the cycle's recorded inputs.
//! - [`excite`]: the dynamic identification's excitation, run by the step.
//! - [`control`]: the controller: gathers a cycle's inputs from the drivers,
//!   runs the step, carries out its outputs.
//! - [`reply`]: what the operator's queues carry (a request with its id,
//!   the loop's reply).
//! - [`logq`]: the bounded queue of log events the loop hands off.
//! - [`motion`]: the carriage's commanded motion handed to the estimator
//!   (the trajectory through a model of the drives' servo; their quick stop).
//! - [`observer`]: the servo observer: the model of the drives corrected
//!   by the encoders (a Kalman filter per axis), how far they follow it.
//! - [`stats`]: the loop's timing statistics.
//! - [`notify`]: the guard's transitions as operator notifications.
//! - [`rt`]: real-time setup (SCHED_FIFO, mlockall), the monotonic clock,
//!   the stop signal.
//! - [`publish`]: the loop's types as the shared-memory payloads.
//! - [`sink`]: what the loop hands each cycle to (one interface, one
//!   shared health struct).
//! - [`runloop`]: the fixed-rate loop itself.
//! - [`time`]: the loop's clock: real time, or simulated time paced or as
//!   fast as the machine allows.

pub mod control;
pub mod excite;
pub mod logq;
pub mod motion;
pub mod notify;
pub mod observer;
pub mod publish;
pub mod reply;
pub mod rt;
pub mod runloop;
pub mod sink;
pub mod stats;
pub mod step;
pub mod time;
