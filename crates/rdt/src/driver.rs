//! The RDT driver: the loop's [`RdtSensor`], which owns its socket and has
//! no thread. Each read (`drain`, `poll`, `wait`) first takes what the socket
//! holds, without waiting ([`RdtSensor`]'s `read_socket`): one
//! `recvmmsg(MSG_DONTWAIT)` when fewer than [`crate::socket::BATCH`]
//! datagrams wait, at most [`MAX_DATAGRAMS_PER_READ`] in all. The loop's
//! `drain` then `poll` of one cycle share one read of the socket: one system
//! call a cycle, and no wake-up per packet.
//!
//! Acceptance of a packet, against the last accepted one of the present
//! stream:
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
//! configured counts per unit, the device's status, and as `received_ns` the
//! kernel's receive time of the datagram on the host's monotonic clock, see
//! [`RdtSensor`]), the newest for `poll` and `wait`, and pushed on the ring
//! for `drain`. Without an accepted packet for longer than the silence limit
//! the sensor is silent; each read then sends the configuration and a start
//! request every restart interval, and forgets the stream's sequence (the
//! next packet is the first of a new stream).

use crate::codec::{CodecError, Request, Response};
use crate::ring::Ring;
use crate::socket::{self, BATCH, Batch};
use crate::{Flavour, RdtConfig, RdtError, RdtStats, SilenceCause};
use sar_hal::sensor::Drained;
use sar_hal::{Clock, ForceSensor, MonotonicClock, SensorStatus, Vec3, WrenchSample};
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket};

/// A packet whose RDT sequence is behind the last accepted one by at most
/// this is late (dropped); by more, it starts a new stream.
pub const REORDER_WINDOW: u32 = 64;
/// A sample counter behind the last accepted one by at most this is late
/// (dropped); by more, it starts a new stream (9 s at 7 kHz).
pub const COUNTER_WINDOW: u32 = 1 << 16;

/// Datagrams one read of the socket takes at most: more than the receive
/// buffer can hold (about 630 of the kernel's ~830 bytes a datagram in the
/// 512 KiB it grants for [`RECEIVE_BUFFER_REQUEST_BYTES`]), so a read finds
/// the socket empty unless datagrams keep coming faster than it reads them.
pub const MAX_DATAGRAMS_PER_READ: usize = 1024;
/// The receive buffer the driver asks for, bytes (the kernel grants twice
/// as much for its bookkeeping, capped at twice `net.core.rmem_max`).
pub const RECEIVE_BUFFER_REQUEST_BYTES: usize = 256 * 1024;
/// The least receive buffer `connect` accepts, bytes: about 150 datagrams
/// (the kernel charges ~830 bytes for a 36-byte one), 20 ms of ATI's 7 kHz,
/// 150 loop periods at OnRobot's 1 kHz: room for several cycles between two
/// reads, and for the daemon's start-up after the first sample.
pub const MIN_RECEIVE_BUFFER_BYTES: usize = 128 * 1024;

/// Bounds of one sleep of `wait` while nothing arrives (how often it looks
/// at the clock to declare a silence and restart the stream), ns.
const MIN_WAIT_STEP_NS: u64 = 1_000_000;
const MAX_WAIT_STEP_NS: u64 = 50_000_000;

/// Host time, ns; the one place the driver reads the monotonic clock. A
/// failed read is [`RdtError::Clock`], never a made-up time.
fn host_now_ns(clock: &MonotonicClock) -> Result<u64, RdtError> {
    clock.now_ns().map_err(|_| RdtError::Clock)
}

fn io(op: &'static str) -> impl FnOnce(std::io::Error) -> RdtError {
    move |e| RdtError::Io { op, kind: e.kind() }
}

/// Refuses a receive buffer smaller than [`MIN_RECEIVE_BUFFER_BYTES`].
fn check_receive_buffer(granted_bytes: usize) -> Result<(), RdtError> {
    if granted_bytes < MIN_RECEIVE_BUFFER_BYTES {
        return Err(RdtError::ReceiveBuffer {
            granted_bytes,
            needed_bytes: MIN_RECEIVE_BUFFER_BYTES,
        });
    }
    Ok(())
}

/// The monotonic time of a datagram the kernel stamped at `kernel_real_ns`
/// (`CLOCK_REALTIME`), read when the clocks were at `mono_now_ns` and
/// `real_now_ns`, kept within `[floor_ns, mono_now_ns]`: never later than
/// the read, never earlier than the last time the socket was seen empty (a
/// step of the real-time clock cannot move it outside). Without a stamp:
/// `floor_ns`, the earliest it can have arrived (its age over-, never
/// underestimated).
fn monotonic_stamp_ns(
    kernel_real_ns: Option<u64>,
    mono_now_ns: u64,
    real_now_ns: u64,
    floor_ns: u64,
) -> u64 {
    let floor_ns = floor_ns.min(mono_now_ns);
    match kernel_real_ns {
        Some(stamp_ns) => mono_now_ns
            .saturating_sub(real_now_ns.saturating_sub(stamp_ns))
            .max(floor_ns),
        None => floor_ns,
    }
}

/// The RDT force/torque sensor (see the module doc).
///
/// Its reads run on the caller's thread: `poll` and `drain` never block
/// (one `recvmmsg(MSG_DONTWAIT)`, a few more after a long pause, at most
/// [`MAX_DATAGRAMS_PER_READ`] datagrams), never allocate. A `poll` right
/// after a `drain` takes that drain's read without a system call (the loop
/// calls `drain`, then `poll`, once a cycle): the samples a cycle drains
/// and the newest it polls come from one read, so a drained sample is
/// never newer than the cycle's polled one. Every other call reads.
/// `stats` and `is_silent` say what the reads so far found.
///
/// `received_ns` of a sample is the kernel's receive time of its datagram
/// (`SO_TIMESTAMPNS`), on the host's monotonic clock, kept between the last
/// time a read found the socket empty and the read that took it: the age
/// the loop computes is the datagram's, not the read's.
#[derive(Debug)]
pub struct RdtSensor {
    config: RdtConfig,
    socket: UdpSocket,
    clock: MonotonicClock,
    /// The buffers of one `recvmmsg`, allocated once.
    batch: Box<Batch>,
    /// Accepted samples not drained yet.
    ring: Ring,
    /// Counted so far (`ring_overflows` comes from the ring).
    counts: RdtStats,
    /// (RDT sequence, counter) of the last accepted packet of this stream.
    last: Option<(u32, u32)>,
    /// The newest accepted sample, until `poll` or `wait` returns it.
    newest: Option<WrenchSample>,
    /// No accepted packet within the silence limit.
    silent: bool,
    /// Receive time of the last accepted packet (or of the first start), ns.
    last_received_ns: u64,
    /// What was last rejected since the last accepted packet (the cause of
    /// a silence; `None`: nothing).
    last_reject: Option<SilenceCause>,
    /// When the start request was last sent, ns.
    last_start_ns: u64,
    /// When a read last found the socket empty (read before it), ns: every
    /// datagram waiting now arrived later.
    empty_at_ns: u64,
    /// The driver's last call was a `drain`: the next `poll` takes its read
    /// instead of reading again.
    after_drain: bool,
    /// Ring overflows already reported by `drain`.
    overflows_reported: u64,
    /// `wait`'s longest sleep while nothing arrives, ns.
    wait_step_ns: u64,
}

impl RdtSensor {
    /// Checks `config`, opens the socket (connected to the sensor: datagrams
    /// from elsewhere are not received; non-blocking; its receive buffer
    /// sized and checked against [`MIN_RECEIVE_BUFFER_BYTES`]; the kernel's
    /// receive times on), sends the configuration (filter, rate) and the
    /// start request. Does not wait for the first sample.
    pub fn connect(config: RdtConfig) -> Result<Self, RdtError> {
        config.validate()?;
        let clock = MonotonicClock::new().map_err(|_| RdtError::Clock)?;
        let opened_ns = host_now_ns(&clock)?;
        let socket = open_socket(&config)?;
        send_start(&socket, &config)?;
        let started_ns = host_now_ns(&clock)?;
        Ok(Self {
            config,
            socket,
            clock,
            batch: Box::default(),
            ring: Ring::new(config.ring_capacity),
            counts: RdtStats::default(),
            last: None,
            newest: None,
            silent: false,
            last_received_ns: started_ns,
            last_reject: None,
            last_start_ns: started_ns,
            empty_at_ns: opened_ns,
            after_drain: false,
            overflows_reported: 0,
            wait_step_ns: (config.silence_limit_ns / 4).clamp(MIN_WAIT_STEP_NS, MAX_WAIT_STEP_NS),
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

    /// What the reads of the socket have counted so far.
    pub fn stats(&self) -> RdtStats {
        RdtStats {
            ring_overflows: self.ring.overflows(),
            ..self.counts
        }
    }

    /// Whether the last read found the sensor silent (no accepted packet
    /// within the limit).
    pub fn is_silent(&self) -> bool {
        self.silent
    }

    /// OnRobot: sets the low-pass filter now and on every restart.
    pub fn set_filter(&mut self, filter: crate::Filter) -> Result<(), RdtError> {
        self.onrobot_only("filter")?;
        self.send(Request::filter(filter))?;
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
        self.send(Request::rate_period_ms(1000 / rate_hz))?;
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

    fn silent_error(&self) -> RdtError {
        RdtError::Silent {
            last_received_ns: self.last_received_ns,
            limit_ns: self.config.silence_limit_ns,
            cause: self.last_reject.unwrap_or(SilenceCause::NothingReceived),
            address: self.config.address,
        }
    }

    /// Takes what the socket holds (see the type's doc), then declares a
    /// silence and restarts the stream when due. Bounded: at most
    /// [`MAX_DATAGRAMS_PER_READ`] datagrams, one batch a system call.
    fn read_socket(&mut self) {
        let before_ns = host_now_ns(&self.clock).ok();
        let mut taken = 0;
        let emptied = loop {
            match socket::receive_batch(&self.socket, &mut self.batch) {
                Ok(n) => {
                    self.handle_batch(n, before_ns.is_some());
                    taken += n;
                    if n < BATCH {
                        break true;
                    }
                    if taken >= MAX_DATAGRAMS_PER_READ {
                        break false;
                    }
                }
                Err(e) => {
                    // ICMP port unreachable and the like: counted; the
                    // next read goes on.
                    self.counts.io_errors += 1;
                    self.last_reject = Some(SilenceCause::Socket { kind: e.kind() });
                    break false;
                }
            }
        };
        if let Some(now_ns) = before_ns {
            if emptied {
                self.empty_at_ns = now_ns;
            }
            self.check_silence(now_ns);
        }
    }

    /// The batch's `n` datagrams, stamped with the kernel's receive times
    /// (`clock_ok`: the monotonic clock was readable when the read began).
    fn handle_batch(&mut self, n: usize, clock_ok: bool) {
        if n == 0 {
            return;
        }
        let clocks = if clock_ok {
            host_now_ns(&self.clock).ok().zip(socket::realtime_ns())
        } else {
            None
        };
        for i in 0..n {
            let (bytes, kernel_ns) = self.batch.datagram(i);
            let mut copy = [0u8; socket::DATAGRAM_BYTES];
            let len = bytes.len().min(copy.len());
            if let (Some(to), Some(from)) = (copy.get_mut(..len), bytes.get(..len)) {
                to.copy_from_slice(from);
            }
            let Some((mono_ns, real_ns)) = clocks else {
                // No time to stamp it with: dropped and counted.
                self.counts.clock_errors += 1;
                self.last_reject = Some(SilenceCause::Clock);
                continue;
            };
            let floor_ns = self.empty_at_ns.max(self.last_received_ns);
            let received_ns = monotonic_stamp_ns(kernel_ns, mono_ns, real_ns, floor_ns);
            self.handle(copy.get(..len).unwrap_or(&[]), received_ns);
        }
    }

    fn handle(&mut self, bytes: &[u8], received_ns: u64) {
        let response = match Response::decode(bytes) {
            Ok(r) => r,
            Err(CodecError::WrongLength { .. } | CodecError::BadHeader { .. }) => {
                self.counts.malformed += 1;
                self.last_reject = Some(SilenceCause::WrongLength { got: bytes.len() });
                return;
            }
        };
        match judge(self.last, &response) {
            Verdict::Duplicate => {
                self.counts.duplicates += 1;
                self.last_reject = Some(SilenceCause::Duplicates);
                return;
            }
            Verdict::Late => {
                self.counts.reordered += 1;
                self.last_reject = Some(SilenceCause::Late);
                return;
            }
            Verdict::Resync => self.counts.resyncs += 1,
            Verdict::Accept { lost } => self.counts.lost += u64::from(lost),
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
            received_ns,
        };
        self.newest = Some(sample);
        self.ring.push(&sample);
        self.counts.accepted += 1;
        if response.status != 0 {
            self.counts.faults += 1;
        }
        self.last_received_ns = received_ns;
        self.last_reject = None;
        self.silent = false;
    }

    fn check_silence(&mut self, now_ns: u64) {
        if now_ns.saturating_sub(self.last_received_ns) <= self.config.silence_limit_ns {
            return;
        }
        if !self.silent {
            self.silent = true;
            self.counts.silences += 1;
        }
        if now_ns.saturating_sub(self.last_start_ns) >= self.config.restart_interval_ns {
            self.last_start_ns = now_ns;
            self.last = None;
            match send_start(&self.socket, &self.config) {
                Ok(()) => self.counts.restarts += 1,
                Err(e) => {
                    self.counts.io_errors += 1;
                    if let RdtError::Io { kind, .. } = e {
                        self.last_reject = Some(SilenceCause::Socket { kind });
                    }
                }
            }
        }
    }

    /// The newest sample if `poll` or `wait` did not return it yet.
    fn take_newest(&mut self) -> Option<WrenchSample> {
        self.newest.take()
    }
}

impl ForceSensor for RdtSensor {
    type Error = RdtError;

    /// The newest sample not yet returned; `Ok(None)` when none came;
    /// [`RdtError::Silent`] (kind `Disconnected`) when none came and the
    /// sensor has been silent beyond its limit, on every call until samples
    /// come back (the caller must treat its last sample as invalid). Reads
    /// the socket without waiting, unless the call before was a `drain`
    /// (see the type).
    fn poll(&mut self) -> Result<Option<WrenchSample>, RdtError> {
        if !std::mem::take(&mut self.after_drain) {
            self.read_socket();
        }
        if let Some(sample) = self.take_newest() {
            return Ok(Some(sample));
        }
        if self.silent {
            return Err(self.silent_error());
        }
        Ok(None)
    }

    /// Reads the socket until a new sample or the deadline, sleeping in
    /// `ppoll` on the socket between reads (at most a quarter of the silence
    /// limit, so that the stream is restarted meanwhile); at the deadline,
    /// [`RdtError::Silent`] if the sensor is silent, else
    /// [`RdtError::Timeout`]. For start-up: the loop never waits.
    fn wait(&mut self, timeout_ns: u64) -> Result<WrenchSample, RdtError> {
        self.after_drain = false;
        let deadline_ns = host_now_ns(&self.clock)?.saturating_add(timeout_ns);
        loop {
            self.read_socket();
            if let Some(sample) = self.take_newest() {
                return Ok(sample);
            }
            let now_ns = host_now_ns(&self.clock)?;
            if now_ns >= deadline_ns {
                return Err(if self.silent {
                    self.silent_error()
                } else {
                    RdtError::Timeout { timeout_ns }
                });
            }
            socket::wait_readable(&self.socket, (deadline_ns - now_ns).min(self.wait_step_ns))
                .map_err(io("ppoll"))?;
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
    /// dropped (counted in `lost`). Reads the socket first, without
    /// waiting.
    fn drain(&mut self, out: &mut [WrenchSample]) -> Result<Drained, RdtError> {
        self.read_socket();
        self.after_drain = true;
        let (count, remaining) = self.ring.pop_into(out);
        let overflows = self.ring.overflows();
        let lost = overflows.wrapping_sub(self.overflows_reported);
        self.overflows_reported = overflows;
        Ok(Drained {
            count,
            lost,
            remaining,
        })
    }
}

impl Drop for RdtSensor {
    /// Stops the stream (best effort).
    fn drop(&mut self) {
        let _ = self.send(Request::stop());
    }
}

/// The socket, bound and connected to the sensor, non-blocking (a send on
/// the loop's path never waits), its receive buffer checked, the kernel's
/// receive times on.
fn open_socket(config: &RdtConfig) -> Result<UdpSocket, RdtError> {
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
    socket
        .set_nonblocking(true)
        .map_err(io("set_nonblocking"))?;
    let granted = socket::size_receive_buffer(&socket, RECEIVE_BUFFER_REQUEST_BYTES)
        .map_err(io("SO_RCVBUF"))?;
    check_receive_buffer(granted)?;
    socket::enable_timestamps(&socket).map_err(io("SO_TIMESTAMPNS"))?;
    Ok(socket)
}

/// Sends the settings to repeat (filter, rate) and the start request.
fn send_start(socket: &UdpSocket, config: &RdtConfig) -> Result<(), RdtError> {
    if let Some(filter) = config.filter {
        socket
            .send(&Request::filter(filter).encode())
            .map_err(io("send"))?;
    }
    if let Some(rate_hz) = config.rate_hz {
        socket
            .send(&Request::rate_period_ms(1000 / rate_hz.max(1)).encode())
            .map_err(io("send"))?;
    }
    socket
        .send(&Request::start(0).encode())
        .map_err(io("send"))?;
    Ok(())
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

    #[test]
    fn a_receive_buffer_below_the_minimum_is_refused_with_both_sizes() {
        assert_eq!(check_receive_buffer(MIN_RECEIVE_BUFFER_BYTES), Ok(()));
        let e = check_receive_buffer(MIN_RECEIVE_BUFFER_BYTES - 1).unwrap_err();
        assert_eq!(
            e,
            RdtError::ReceiveBuffer {
                granted_bytes: MIN_RECEIVE_BUFFER_BYTES - 1,
                needed_bytes: MIN_RECEIVE_BUFFER_BYTES
            }
        );
        assert!(e.to_string().contains("rmem_max"), "{e}");
    }

    /// The kernel's stamp, moved to the monotonic clock, within the floor
    /// (the socket last seen empty) and the read: a real-time step cannot
    /// move it outside; no stamp gives the floor (age overestimated).
    #[test]
    fn a_kernel_stamp_becomes_monotonic_within_its_bounds() {
        let (mono, real) = (5_000_000, 1_700_000_000_000_000_000);
        assert_eq!(
            monotonic_stamp_ns(Some(real - 300_000), mono, real, 4_000_000),
            4_700_000
        );
        assert_eq!(
            monotonic_stamp_ns(Some(real - 3_000_000), mono, real, 4_000_000),
            4_000_000
        );
        assert_eq!(
            monotonic_stamp_ns(Some(real + 1_000), mono, real, 4_000_000),
            mono
        );
        assert_eq!(monotonic_stamp_ns(None, mono, real, 4_000_000), 4_000_000);
        assert_eq!(monotonic_stamp_ns(None, mono, real, 9_000_000), mono);
    }
}
