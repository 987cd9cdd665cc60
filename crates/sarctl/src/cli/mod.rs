//! `sarctl`'s subcommands, one module each (`main.rs` parses the command
//! line and dispatches here); the requests to the daemon share
//! [`request::Daemon`]. Each returns `Err` with a one-line reason (printed
//! by `sarctl`).

pub mod completions;
pub mod export;
pub mod identify;
pub mod identify_excite;
pub mod identify_servo;
pub mod limits;
pub mod monitor;
pub mod record;
pub mod recover;
pub mod replay;
pub mod request;
pub mod reset;
pub mod retreat;
pub mod status;
pub mod support;
pub mod workspace;

/// A write to stdout failed. A reader that went away (`sarctl monitor | head`)
/// ends the command quietly; any other failure is reported.
pub fn output_error(e: std::io::Error) -> String {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        OUTPUT_CLOSED.to_owned()
    } else {
        format!("cannot write the output: {e}")
    }
}

/// The marker of a closed output (see [`output_error`]): `sarctl` exits 0.
pub const OUTPUT_CLOSED: &str = "output closed";
