//! `scripts/bare-loop.c` with the RDT driver's reads in it: a loop of
//! `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)` at 1 kHz that calls
//! `drain` then `poll` each cycle, as `sard`'s loop does, and nothing else;
//! beside the bare loop in one run (`scripts/rt-figures.sh`), the CPU the
//! driver adds to the real-time path, every thread of it counted.
//!
//! `cargo run --release -p sar-rdt --example rdt_bare_loop -- ADDRESS CYCLES`
//! connects to the sensor (or emulator) at ADDRESS and prints the CPU time
//! the process used (user + system, s), then the samples drained and the
//! driver's counters.
#![allow(missing_docs, clippy::print_stdout)]

use sar_hal::{ForceSensor, SensorStatus, Vec3, WrenchSample};
use sar_rdt::{RdtConfig, RdtSensor};

const PERIOD_NS: i64 = 1_000_000;

const EMPTY: WrenchSample = WrenchSample {
    force_n: Vec3::new(0.0, 0.0, 0.0),
    torque_nm: Vec3::new(0.0, 0.0, 0.0),
    counter: 0,
    status: SensorStatus::OK,
    received_ns: 0,
};

/// The process's CPU time, user + system, s.
#[allow(unsafe_code)]
fn cpu_s() -> f64 {
    // SAFETY: a plain C struct written by getrusage.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: `u` is a valid rusage to write.
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let t = |v: libc::timeval| v.tv_sec as f64 + v.tv_usec as f64 / 1e6;
    t(u.ru_utime) + t(u.ru_stime)
}

#[allow(unsafe_code)]
fn main() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let address = args.next().ok_or("usage: rdt_bare_loop ADDRESS CYCLES")?;
    let address = address
        .parse()
        .map_err(|e| format!("ADDRESS {address:?}: {e}"))?;
    let cycles: u64 = match args.next() {
        Some(c) => c.parse().map_err(|e| format!("CYCLES {c:?}: {e}"))?,
        None => 1000,
    };
    let mut sensor = RdtSensor::connect(RdtConfig::new(address, 10_000.0, 100_000.0))
        .map_err(|e| e.to_string())?;
    sensor
        .wait(1_000_000_000)
        .map_err(|e| format!("no first sample: {e}"))?;
    let mut out = [EMPTY; 64];
    let mut drained = 0u64;
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid timespec to write.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut t) };
    for _ in 0..cycles {
        t.tv_nsec += PERIOD_NS;
        if t.tv_nsec >= 1_000_000_000 {
            t.tv_nsec -= 1_000_000_000;
            t.tv_sec += 1;
        }
        // SAFETY: an absolute deadline in a valid timespec.
        unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &t,
                std::ptr::null_mut(),
            )
        };
        if let Ok(d) = sensor.drain(&mut out) {
            drained += d.count as u64;
        }
        let _ = std::hint::black_box(sensor.poll());
    }
    println!("{:.3}", cpu_s());
    println!("drained {drained}; {:?}", sensor.stats());
    Ok(())
}
