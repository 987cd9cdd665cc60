//! `sarctl` subcommands that are more than a request to the daemon, one module each.
//! Each returns `Err` with a one-line reason (printed by `sarctl`).

pub mod export;
pub mod identify;
pub mod record;
pub mod recover;
pub mod replay;
pub mod workspace;
