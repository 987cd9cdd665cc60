//! The RDT driver: a receive thread that owns the socket's receiving side,
//! and the loop's handle ([`RdtSensor`]) that reads its results lock-free.
//!
//! Acceptance of a packet (receive thread), against the last accepted one of
//! the present stream:
//! - not a 36-byte response: dropped, `malformed`;
//! - the first packet of a stream (after a start request) is accepted;
//! - RDT sequence equal: dropped, `duplicates`; behind by at most
//!   [`REORDER_WINDOW`]: dropped, `reordered`; behind by more: a new stream
//!   of the device, accepted, `resyncs`;
//! - RDT sequence ahead by `k`: `lost += k - 1`, then the sample counter must
//!   move forward too: equal is a duplicate, behind by at most
//!   [`COUNTER_WINDOW`] is late (dropped), behind by more is a resync.
//!
//! An accepted packet becomes a [`WrenchSample`] (counts divided by the
//! configured counts per unit, the device's status, the host's monotonic
//! receive time), published to the seqlock (`poll`, `wait`) and pushed on
//! the ring (`drain`). Without an accepted packet for longer than the silence
//! limit the sensor is silent; the thread then sends the configuration and a
//! start request every restart interval, and forgets the stream's sequence
//! (the next packet is the first of a new stream).

use crate::codec::{CodecError, RESPONSE_LEN, Request, Response};
use crate::handoff::{Latest, Ring};
use crate::{Flavour, RdtConfig, RdtError, RdtStats, SilenceCause};
use sar_hal::sensor::Drained;
use sar_hal::{Clock, ForceSensor, MonotonicClock, SensorStatus, Vec3, WrenchSample};
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// A packet whose RDT sequence is behind the last accepted one by at most
/// this is late (dropped); by more, it starts a new stream.
pub const REORDER_WINDOW: u32 = 64;
/// A sample counter behind the last accepted one by at most this is late
/// (dropped); by more, it starts a new stream (9 s at 7 kHz).
pub const COUNTER_WINDOW: u32 = 1 << 16;

/// Longest sleep of one step of `wait`, ns.
const WAIT_STEP_NS: u64 = 50_000;
/// Bounds of the receive thread's socket timeout (how often it looks at the
/// clock and the stop flag without traffic), ns.
const MIN_RECV_TIMEOUT_NS: u64 = 1_000_000;
const MAX_RECV_TIMEOUT_NS: u64 = 50_000_000;
/// "No filter or rate to send" in the shared settings.
const UNSET: u32 = u32::MAX;

/// Host time, ns; the one place the driver reads the clock. A failed read is
/// [`RdtError::Clock`], never a made-up time.
fn host_now_ns(clock: &MonotonicClock) -> Result<u64, RdtError> {
    clock.now_ns().map_err(|_| RdtError::Clock)
}

fn io(op: &'static str) -> impl FnOnce(std::io::Error) -> RdtError {
    move |e| RdtError::Io { op, kind: e.kind() }
}

/// Counters, written by the receive thread, read by anyone.
#[derive(Debug, Default)]
struct Counters {
    accepted: AtomicU64,
    faults: AtomicU64,
    lost: AtomicU64,
    duplicates: AtomicU64,
    reordered: AtomicU64,
    resyncs: AtomicU64,
    malformed: AtomicU64,
    silences: AtomicU64,
    restarts: AtomicU64,
    io_errors: AtomicU64,
    clock_errors: AtomicU64,
}

fn bump(counter: &AtomicU64, by: u64) {
    counter.fetch_add(by, Ordering::Relaxed);
}

/// What the receive thread and the loop's handle share.
#[derive(Debug)]
struct Shared {
    latest: Latest,
    ring: Ring,
    counters: Counters,
    /// The handle asks the thread to end.
    stop: AtomicBool,
    /// The thread is running (cleared when it ends, even by a panic).
    alive: AtomicBool,
    /// No accepted packet within the silence limit.
    silent: AtomicBool,
    /// Host time of the last accepted packet (or of the first start), ns.
    last_received_ns: AtomicU64,
    /// What the receive thread last rejected since the last accepted
    /// packet ([`Reject`] encoded; 0: nothing).
    last_reject: AtomicU64,
    /// The settings sent again on each restart (`UNSET`: none).
    filter_code: AtomicU32,
    rate_period_ms: AtomicU32,
}

/// What the receive thread rejected, as one atomic word: the code in the
/// low byte, the detail (a length, an OS error number) above.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Reject {
    WrongLength(usize),
    Duplicate,
    Late,
    Socket(std::io::ErrorKind),
    Clock,
}

/// The socket errors a silence can name by kind (others: `Other`).
const SOCKET_KINDS: [std::io::ErrorKind; 6] = [
    std::io::ErrorKind::Other,
    std::io::ErrorKind::ConnectionRefused,
    std::io::ErrorKind::ConnectionReset,
    std::io::ErrorKind::PermissionDenied,
    std::io::ErrorKind::AddrNotAvailable,
    std::io::ErrorKind::NotConnected,
];

impl Reject {
    fn encode(self) -> u64 {
        match self {
            Self::WrongLength(n) => 1 | ((n.min(0xFFFF) as u64) << 8),
            Self::Duplicate => 2,
            Self::Late => 3,
            Self::Socket(kind) => {
                let code = SOCKET_KINDS.iter().position(|k| *k == kind).unwrap_or(0);
                4 | ((code as u64) << 8)
            }
            Self::Clock => 5,
        }
    }

    /// The cause of a silence from the encoded word (0: nothing rejected).
    fn cause(word: u64) -> SilenceCause {
        let detail = word >> 8;
        match word & 0xFF {
            1 => SilenceCause::WrongLength {
                got: usize::try_from(detail).unwrap_or(usize::MAX),
            },
            2 => SilenceCause::Duplicates,
            3 => SilenceCause::Late,
            4 => SilenceCause::Socket {
                kind: usize::try_from(detail)
                    .ok()
                    .and_then(|i| SOCKET_KINDS.get(i).copied())
                    .unwrap_or(std::io::ErrorKind::Other),
            },
            5 => SilenceCause::Clock,
            _ => SilenceCause::NothingReceived,
        }
    }
}

/// Clears `alive` when the receive thread ends, however it ends.
struct AliveGuard(Arc<Shared>);

impl Drop for AliveGuard {
    fn drop(&mut self) {
        self.0.alive.store(false, Ordering::Release);
    }
}

/// The RDT force/torque sensor (see the module doc).
#[derive(Debug)]
pub struct RdtSensor {
    config: RdtConfig,
    shared: Arc<Shared>,
    /// For commands from the loop's thread (a clone of the thread's socket).
    socket: UdpSocket,
    clock: MonotonicClock,
    thread: Option<JoinHandle<()>>,
    /// Publication number of the last sample `poll` or `wait` returned.
    last_returned: u64,
    /// Ring overflows already reported by `drain`.
    overflows_reported: u64,
}

impl RdtSensor {
    /// Checks `config`, opens the socket (connected to the sensor: datagrams
    /// from elsewhere are not received), sends the configuration (filter,
    /// rate) and the start request, and starts the receive thread. Does not
    /// wait for the first sample.
    pub fn connect(config: RdtConfig) -> Result<Self, RdtError> {
        config.validate()?;
        let clock = MonotonicClock::new().map_err(|_| RdtError::Clock)?;
        let local = config.local_address.unwrap_or_else(|| {
            let ip = match config.address.ip() {
                IpAddr::V4(ip) if ip.is_loopback() => IpAddr::V4(Ipv4Addr::LOCALHOST),
                IpAddr::V4(_) => IpAddr::V4(Ipv4Addr::UNSPECIFIED),
                IpAddr::V6(ip) if ip.is_loopback() => IpAddr::V6(Ipv6Addr::LOCALHOST),
                IpAddr::V6(_) => IpAddr::V6(Ipv6Addr::UNSPECIFIED),
            };
            SocketAddr::new(ip, 0)
        });
        let socket = UdpSocket::bind(local).map_err(io("bind"))?;
        socket.connect(config.address).map_err(io("connect"))?;
        let timeout_ns =
            (config.silence_limit_ns / 4).clamp(MIN_RECV_TIMEOUT_NS, MAX_RECV_TIMEOUT_NS);
        socket
            .set_read_timeout(Some(Duration::from_nanos(timeout_ns)))
            .map_err(io("set_read_timeout"))?;
        let shared = Arc::new(Shared {
            latest: Latest::default(),
            ring: Ring::new(config.ring_capacity),
            counters: Counters::default(),
            stop: AtomicBool::new(false),
            alive: AtomicBool::new(true),
            silent: AtomicBool::new(false),
            last_received_ns: AtomicU64::new(0),
            last_reject: AtomicU64::new(0),
            filter_code: AtomicU32::new(config.filter.map_or(UNSET, crate::Filter::code)),
            rate_period_ms: AtomicU32::new(config.rate_hz.map_or(UNSET, |hz| 1000 / hz.max(1))),
        });
        send_start(&socket, &shared)?;
        let started_ns = host_now_ns(&clock)?;
        shared.last_received_ns.store(started_ns, Ordering::Relaxed);
        let mut receiver = Receiver {
            socket: socket.try_clone().map_err(io("try_clone"))?,
            shared: Arc::clone(&shared),
            clock,
            config,
            last: None,
            last_start_ns: started_ns,
        };
        let guard = AliveGuard(Arc::clone(&shared));
        let thread = std::thread::Builder::new()
            .name("rdt-receive".into())
            .spawn(move || {
                let _guard = guard;
                receiver.run();
            })
            .map_err(io("spawn"))?;
        Ok(Self {
            config,
            shared,
            socket,
            clock,
            thread: Some(thread),
            last_returned: 0,
            overflows_reported: 0,
        })
    }

    /// The configuration in force (with the latest filter and rate set).
    pub fn config(&self) -> &RdtConfig {
        &self.config
    }

    /// The local address of the socket.
    pub fn local_address(&self) -> Result<SocketAddr, RdtError> {
        self.socket.local_addr().map_err(io("local_addr"))
    }

    /// What the receive thread has counted so far (lock-free).
    pub fn stats(&self) -> RdtStats {
        let c = &self.shared.counters;
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        RdtStats {
            accepted: get(&c.accepted),
            faults: get(&c.faults),
            lost: get(&c.lost),
            duplicates: get(&c.duplicates),
            reordered: get(&c.reordered),
            resyncs: get(&c.resyncs),
            malformed: get(&c.malformed),
            silences: get(&c.silences),
            restarts: get(&c.restarts),
            ring_overflows: self.shared.ring.overflows(),
            io_errors: get(&c.io_errors),
            clock_errors: get(&c.clock_errors),
        }
    }

    /// Whether the sensor is silent now (no accepted packet within the limit).
    pub fn is_silent(&self) -> bool {
        self.shared.silent.load(Ordering::Acquire)
    }

    /// OnRobot: sets the low-pass filter now and on every restart.
    pub fn set_filter(&mut self, filter: crate::Filter) -> Result<(), RdtError> {
        self.onrobot_only("filter")?;
        self.send(Request::filter(filter))?;
        self.shared
            .filter_code
            .store(filter.code(), Ordering::Relaxed);
        self.config.filter = Some(filter);
        Ok(())
    }

    /// OnRobot: sets the output rate (1 to 1000 Hz; sent as the period
    /// 1000 / `rate_hz` ms) now and on every restart.
    pub fn set_rate_hz(&mut self, rate_hz: u32) -> Result<(), RdtError> {
        self.onrobot_only("rate")?;
        if !(1..=1000).contains(&rate_hz) {
            return Err(RdtError::InvalidConfig {
                field: "rate_hz",
                value: f64::from(rate_hz),
            });
        }
        let period_ms = 1000 / rate_hz;
        self.send(Request::rate_period_ms(period_ms))?;
        self.shared
            .rate_period_ms
            .store(period_ms, Ordering::Relaxed);
        self.config.rate_hz = Some(rate_hz);
        Ok(())
    }

    fn onrobot_only(&self, command: &'static str) -> Result<(), RdtError> {
        match self.config.flavour {
            Flavour::OnRobot => Ok(()),
            flavour => Err(RdtError::Unsupported { command, flavour }),
        }
    }

    fn send(&self, request: Request) -> Result<(), RdtError> {
        self.socket.send(&request.encode()).map_err(io("send"))?;
        Ok(())
    }

    fn check_alive(&self) -> Result<(), RdtError> {
        if self.shared.alive.load(Ordering::Acquire) {
            Ok(())
        } else {
            Err(RdtError::ReceiverGone)
        }
    }

    fn silent_error(&self) -> RdtError {
        RdtError::Silent {
            last_received_ns: self.shared.last_received_ns.load(Ordering::Relaxed),
            limit_ns: self.config.silence_limit_ns,
            cause: Reject::cause(self.shared.last_reject.load(Ordering::Relaxed)),
            address: self.config.address,
        }
    }

    /// The newest sample if it was not returned yet.
    fn take_new(&mut self) -> Option<WrenchSample> {
        let (seq, sample) = self.shared.latest.read()?;
        if seq == self.last_returned {
            return None;
        }
        self.last_returned = seq;
        Some(sample)
    }
}

impl ForceSensor for RdtSensor {
    type Error = RdtError;

    /// The newest sample not yet returned; `Ok(None)` when none came;
    /// [`RdtError::Silent`] (kind `Disconnected`) when none came and the
    /// sensor has been silent beyond its limit, on every call until samples
    /// come back (the caller must treat its last sample as invalid). A few
    /// atomic loads: no lock, no system call.
    fn poll(&mut self) -> Result<Option<WrenchSample>, RdtError> {
        if let Some(sample) = self.take_new() {
            return Ok(Some(sample));
        }
        self.check_alive()?;
        if self.is_silent() {
            return Err(self.silent_error());
        }
        Ok(None)
    }

    /// Polls, sleeping at most 50 us between tries, until a new sample or
    /// the deadline; at the deadline, [`RdtError::Silent`] if the sensor is
    /// silent, else [`RdtError::Timeout`].
    fn wait(&mut self, timeout_ns: u64) -> Result<WrenchSample, RdtError> {
        let deadline_ns = host_now_ns(&self.clock)?.saturating_add(timeout_ns);
        loop {
            if let Some(sample) = self.take_new() {
                return Ok(sample);
            }
            self.check_alive()?;
            let now_ns = host_now_ns(&self.clock)?;
            if now_ns >= deadline_ns {
                return Err(if self.is_silent() {
                    self.silent_error()
                } else {
                    RdtError::Timeout { timeout_ns }
                });
            }
            std::thread::sleep(Duration::from_nanos(
                (deadline_ns - now_ns).min(WAIT_STEP_NS),
            ));
        }
    }

    /// OnRobot: bias on (0x0042, 0xFF). ATI: the one-shot bias (0x0042).
    fn tare(&mut self) -> Result<(), RdtError> {
        self.send(match self.config.flavour {
            Flavour::OnRobot => Request::bias(true),
            Flavour::Ati => Request::bias_once(),
        })
    }

    /// OnRobot: bias off (0x0042, 0x00). ATI: unsupported.
    fn clear_tare(&mut self) -> Result<(), RdtError> {
        self.onrobot_only("clear_tare")?;
        self.send(Request::bias(false))
    }

    /// Every accepted sample since the last drain, from the fixed ring of
    /// [`RdtConfig::ring_capacity`]; when it was full the NEWEST samples were
    /// dropped (counted in `lost`). Lock-free like `poll`.
    fn drain(&mut self, out: &mut [WrenchSample]) -> Result<Drained, RdtError> {
        let (count, remaining) = self.shared.ring.pop_into(out);
        let overflows = self.shared.ring.overflows();
        let lost = overflows.wrapping_sub(self.overflows_reported);
        self.overflows_reported = overflows;
        Ok(Drained {
            count,
            lost,
            remaining,
        })
    }
}

/// How long dropping an [`RdtSensor`] waits for its receive thread at most.
pub const RECEIVE_JOIN_WAIT: std::time::Duration = std::time::Duration::from_secs(1);

impl Drop for RdtSensor {
    /// Stops the stream (best effort) and the receive thread (it ends within
    /// its socket timeout, 50 ms; waited for at most [`RECEIVE_JOIN_WAIT`],
    /// then left behind and named: `sar_hal::join::left_behind`).
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        let _ = self.send(Request::stop());
        if let Some(thread) = self.thread.take() {
            let _ = sar_hal::join::join_within(thread, RECEIVE_JOIN_WAIT);
        }
    }
}

/// Sends the settings to repeat (filter, rate) and the start request.
fn send_start(socket: &UdpSocket, shared: &Shared) -> Result<(), RdtError> {
    let filter = shared.filter_code.load(Ordering::Relaxed);
    if filter != UNSET {
        socket
            .send(
                &Request {
                    command: crate::codec::CMD_FILTER,
                    data: filter,
                }
                .encode(),
            )
            .map_err(io("send"))?;
    }
    let period = shared.rate_period_ms.load(Ordering::Relaxed);
    if period != UNSET {
        socket
            .send(&Request::rate_period_ms(period).encode())
            .map_err(io("send"))?;
    }
    socket
        .send(&Request::start(0).encode())
        .map_err(io("send"))?;
    Ok(())
}

/// The receive thread's state.
struct Receiver {
    socket: UdpSocket,
    shared: Arc<Shared>,
    clock: MonotonicClock,
    config: RdtConfig,
    /// (RDT sequence, counter) of the last accepted packet of this stream.
    last: Option<(u32, u32)>,
    last_start_ns: u64,
}

/// What to do with a decoded packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Verdict {
    Accept { lost: u32 },
    Resync,
    Duplicate,
    Late,
}

/// The acceptance rule of the module doc, against the last accepted
/// (sequence, counter) of the stream.
fn judge(last: Option<(u32, u32)>, r: &Response) -> Verdict {
    let Some((seq, counter)) = last else {
        return Verdict::Accept { lost: 0 };
    };
    let ahead = r.rdt_sequence.wrapping_sub(seq);
    if ahead == 0 {
        return Verdict::Duplicate;
    }
    if ahead > u32::MAX / 2 {
        return if seq.wrapping_sub(r.rdt_sequence) <= REORDER_WINDOW {
            Verdict::Late
        } else {
            Verdict::Resync
        };
    }
    let counter_ahead = r.sample_counter.wrapping_sub(counter);
    if counter_ahead == 0 {
        return Verdict::Duplicate;
    }
    if counter_ahead > u32::MAX / 2 {
        return if counter.wrapping_sub(r.sample_counter) <= COUNTER_WINDOW {
            Verdict::Late
        } else {
            Verdict::Resync
        };
    }
    Verdict::Accept { lost: ahead - 1 }
}

impl Receiver {
    fn run(&mut self) {
        // One byte more than a response: a longer datagram shows as such.
        let mut buf = [0u8; RESPONSE_LEN + 1];
        while !self.shared.stop.load(Ordering::Acquire) {
            match self.socket.recv(&mut buf) {
                Ok(n) => match host_now_ns(&self.clock) {
                    Ok(now_ns) => self.handle(buf.get(..n).unwrap_or(&[]), now_ns),
                    // No time to stamp it with: dropped and counted.
                    Err(_) => {
                        bump(&self.shared.counters.clock_errors, 1);
                        self.reject(Reject::Clock);
                    }
                },
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) => {
                    // ICMP port unreachable and the like: counted, and a
                    // pause so that a failing socket does not spin.
                    bump(&self.shared.counters.io_errors, 1);
                    self.reject(Reject::Socket(e.kind()));
                    std::thread::sleep(Duration::from_nanos(MIN_RECV_TIMEOUT_NS));
                }
            }
            if let Ok(now_ns) = host_now_ns(&self.clock) {
                self.check_silence(now_ns);
            }
        }
    }

    /// Notes what was rejected (the cause of a silence, if one follows).
    fn reject(&self, what: Reject) {
        self.shared
            .last_reject
            .store(what.encode(), Ordering::Relaxed);
    }

    fn handle(&mut self, bytes: &[u8], now_ns: u64) {
        let c = &self.shared.counters;
        let response = match Response::decode(bytes) {
            Ok(r) => r,
            Err(CodecError::WrongLength { .. } | CodecError::BadHeader { .. }) => {
                bump(&c.malformed, 1);
                self.reject(Reject::WrongLength(bytes.len()));
                return;
            }
        };
        match judge(self.last, &response) {
            Verdict::Duplicate => {
                self.reject(Reject::Duplicate);
                return bump(&c.duplicates, 1);
            }
            Verdict::Late => {
                self.reject(Reject::Late);
                return bump(&c.reordered, 1);
            }
            Verdict::Resync => bump(&c.resyncs, 1),
            Verdict::Accept { lost } => bump(&c.lost, u64::from(lost)),
        }
        self.last = Some((response.rdt_sequence, response.sample_counter));
        let [fx, fy, fz, tx, ty, tz] = response.counts.map(f64::from);
        let per_n = self.config.counts_per_n;
        let per_nm = self.config.counts_per_nm;
        let sample = WrenchSample {
            force_n: Vec3::new(fx / per_n, fy / per_n, fz / per_n),
            torque_nm: Vec3::new(tx / per_nm, ty / per_nm, tz / per_nm),
            counter: response.sample_counter,
            status: SensorStatus(response.status),
            received_ns: now_ns,
        };
        self.shared.latest.publish(&sample);
        self.shared.ring.push(&sample);
        bump(&c.accepted, 1);
        if response.status != 0 {
            bump(&c.faults, 1);
        }
        self.shared
            .last_received_ns
            .store(now_ns, Ordering::Relaxed);
        self.shared.last_reject.store(0, Ordering::Relaxed);
        self.shared.silent.store(false, Ordering::Release);
    }

    fn check_silence(&mut self, now_ns: u64) {
        let last_ns = self.shared.last_received_ns.load(Ordering::Relaxed);
        if now_ns.saturating_sub(last_ns) <= self.config.silence_limit_ns {
            return;
        }
        if !self.shared.silent.swap(true, Ordering::AcqRel) {
            bump(&self.shared.counters.silences, 1);
        }
        if now_ns.saturating_sub(self.last_start_ns) >= self.config.restart_interval_ns {
            self.last_start_ns = now_ns;
            self.last = None;
            match send_start(&self.socket, &self.shared) {
                Ok(()) => bump(&self.shared.counters.restarts, 1),
                Err(e) => {
                    bump(&self.shared.counters.io_errors, 1);
                    if let RdtError::Io { kind, .. } = e {
                        self.reject(Reject::Socket(kind));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packet(seq: u32, counter: u32) -> Response {
        Response {
            rdt_sequence: seq,
            sample_counter: counter,
            ..Response::default()
        }
    }

    #[test]
    fn acceptance_rule() {
        let last = Some((10, 1000));
        assert_eq!(judge(None, &packet(5, 5)), Verdict::Accept { lost: 0 });
        assert_eq!(judge(last, &packet(11, 1001)), Verdict::Accept { lost: 0 });
        assert_eq!(judge(last, &packet(14, 1010)), Verdict::Accept { lost: 3 });
        assert_eq!(judge(last, &packet(10, 1000)), Verdict::Duplicate);
        assert_eq!(judge(last, &packet(11, 1000)), Verdict::Duplicate);
        assert_eq!(judge(last, &packet(9, 999)), Verdict::Late);
        assert_eq!(judge(last, &packet(11, 990)), Verdict::Late);
        assert_eq!(
            judge(last, &packet(10u32.wrapping_sub(65), 0)),
            Verdict::Resync
        );
        assert_eq!(
            judge(last, &packet(11, 1000u32.wrapping_sub(70_000))),
            Verdict::Resync
        );
        // Across the wrap of both numbers.
        let wrap = Some((u32::MAX, u32::MAX));
        assert_eq!(judge(wrap, &packet(1, 3)), Verdict::Accept { lost: 1 });
        assert_eq!(judge(Some((1, 3)), &packet(u32::MAX, 1)), Verdict::Late);
    }
}
