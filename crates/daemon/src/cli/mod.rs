//! `sarctl` subcommands that are more than a request to the daemon, one module each.

pub mod identify;
