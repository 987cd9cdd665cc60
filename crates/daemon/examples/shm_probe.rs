//! A client's view of a running `sard`, for `scripts/sard-footprint.sh`:
//! the state's publish-to-receive latency (from the cycle's stamp,
//! `StateMsg::now_ns`, to a subscriber blocked on the state event having
//! it, as `sarctl monitor` is) and the commands' round trip (a LIMITS query,
//! answered by the publishing thread; a RESET, judged by the loop), as
//! `sarctl` sends them.
//!
//! `cargo run --release -p sar-daemon --example shm_probe -- PREFIX [SECONDS]`

use sar_msgs::wire::{CommandMsg, command_kind};
use std::time::{Duration, Instant};

/// Commands of each kind sent, one after the other.
const COMMANDS: usize = 40;

fn mono_ns() -> u64 {
    sar_loop::rt::monotonic_ns().unwrap_or(0)
}

/// p50, p99 and max of `v`, us.
fn quantiles_us(v: &mut [u64]) -> String {
    if v.is_empty() {
        return "none".to_owned();
    }
    v.sort_unstable();
    let at = |q: f64| {
        v.get(((v.len() - 1) as f64 * q).round() as usize)
            .map_or(0, |ns| ns / 1000)
    };
    format!(
        "p50 {} us, p99 {} us, max {} us ({} samples)",
        at(0.5),
        at(0.99),
        at(1.0),
        v.len()
    )
}

/// Round trips of `COMMANDS` commands of `kind`, ns.
fn round_trips(client: &sar_shm::Client, kind: u32) -> Result<Vec<u64>, String> {
    let mut v = Vec::with_capacity(COMMANDS);
    for id in 0..COMMANDS as u64 {
        let command = CommandMsg {
            kind,
            id: id + 1,
            ..CommandMsg::default()
        };
        let t = Instant::now();
        client
            .command(command, Duration::from_secs(2))
            .map_err(|e| e.to_string())?;
        v.push(t.elapsed().as_nanos() as u64);
        std::thread::sleep(Duration::from_millis(7));
    }
    Ok(v)
}

fn main() -> Result<(), String> {
    sar_shm::log_errors_only();
    let mut args = std::env::args().skip(1);
    let prefix = args.next().ok_or("usage: shm_probe PREFIX [SECONDS]")?;
    let seconds: u64 = args
        .next()
        .map_or(Ok(5), |s| s.parse())
        .map_err(|e| format!("{e}"))?;
    let client = sar_shm::Client::new(&prefix).map_err(|e| e.to_string())?;
    let sub = client.subscribe().map_err(|e| e.to_string())?;
    // The first batch (the history) is not a live sample.
    sub.latest(Duration::from_secs(2))
        .ok_or("no state within 2 s")?;
    let mut latency = Vec::new();
    let end = Instant::now() + Duration::from_secs(seconds);
    while Instant::now() < end {
        sub.wait(Duration::from_millis(50), |s| {
            latency.push(mono_ns().saturating_sub(s.now_ns))
        });
    }
    println!(
        "state publish-to-receive (cycle stamp to subscriber): {}",
        quantiles_us(&mut latency)
    );
    // With the subscriber connected, then without.
    for (with, held) in [("with", Some(sub)), ("without", None)] {
        let mut limits = round_trips(&client, command_kind::LIMITS)?;
        let mut reset = round_trips(&client, command_kind::RESET)?;
        println!(
            "command round trip {with} a subscriber: LIMITS (the publishing thread answers) {}; RESET (the loop judges it) {}",
            quantiles_us(&mut limits),
            quantiles_us(&mut reset)
        );
        drop(held);
    }
    Ok(())
}
