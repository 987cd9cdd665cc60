//! What the operator's queues carry: a request with its caller's id
//! ([`Envelope`]) in, the loop's [`Reply`] to it out. Below the controller
//! and the log queue, which both use them (so neither imports the other's
//! types back).

use crate::step::{ReplyDetail, ReplyStatus, Request};

/// A request with the caller's id (echoed in the reply).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// The caller's id.
    pub id: u64,
    /// The request.
    pub request: Request,
}

/// The reply to a request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reply {
    /// The request's id.
    pub id: u64,
    /// The request.
    pub request: Request,
    /// The cycle that judged it.
    pub cycle: u64,
    /// What became of it.
    pub status: ReplyStatus,
    /// The guard's reason code behind a refusal, 0 otherwise.
    pub reason: u16,
    /// The exact cause (what `sarctl` prints).
    pub detail: ReplyDetail,
}
