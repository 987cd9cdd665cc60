//! `sarctl` subcommands that need more than a few lines, one module each.
//! Each returns `Err` with a one-line reason (printed by `sarctl`).

pub mod record;
pub mod recover;
pub mod replay;
