//! A device emulator for tests: serves the RDT protocol on a loopback UDP
//! port, honours start (with its sample count), stop, bias, filter and rate,
//! and follows a deterministic script of faults keyed by packet index: of the
//! network ([`Action`]: loss, duplicates, reordering, status faults, going
//! mute until restarted) and of the sensor itself ([`SensorFault`]: frozen,
//! saturated, a spike, a drift, a gain error).
//!
//! The reading of packet `i`, in counts: the configured raw reading
//! ([`EmulatorConfig::counts`], or [`Emulator::set_counts`]) plus the drift
//! of the active [`SensorFault::Drift`]s, times the gain of the active
//! [`SensorFault::Scale`]s, plus seeded normal noise
//! ([`EmulatorConfig::noise_counts`], ChaCha8 from [`EmulatorConfig::seed`],
//! six draws for every packet produced), plus an active
//! [`SensorFault::Spike`], rounded, clipped to the measuring range
//! ([`EmulatorConfig::range_counts`]) and with saturated channels pinned at
//! it, less the device's bias; a frozen device then repeats the counts of the
//! packet before the freeze. A device that runs with another counts-per-newton
//! than the host's configuration is simply a reading made with another scale
//! ([`counts_for`]).
//!
//! Two pacings: [`Pacing::Periodic`] sends a packet every period from its
//! own thread (like a device; OnRobot's rate command changes the period), and
//! [`Pacing::Manual`] sends only when the test calls [`Emulator::step`], so
//! that a test decides exactly which packets exist. Either way a packet's
//! content depends only on the script and the requests received, never on
//! timing: packet `i` (0-based, counting every packet produced, sent or not)
//! carries RDT sequence "packets of this stream so far" and sample counter
//! `first_counter + i + 1`.
//!
//! Locks are fine here (a test utility): the state sits behind a mutex with a
//! condition variable for the test's bounded waits.

use crate::Flavour;
use crate::codec::{
    BIAS_ON, CMD_BIAS, CMD_FILTER, CMD_RATE, CMD_START, CMD_STOP, Request, Response,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sar_hal::{Channels, Rail};
use std::collections::BTreeMap;
use std::net::{Ipv4Addr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What happens to one packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Action {
    /// Produced (sequence and counter advance) but not sent: a loss.
    Drop,
    /// Sent twice.
    Duplicate,
    /// Held back and sent after the next packet produced (a reordering).
    SwapWithNext,
    /// Sent with this status word (non-zero: a fault).
    Status(u32),
    /// The device restarts its stream on its own: this packet's RDT
    /// sequence is 1 again (the sample counter goes on); sent normally.
    RestartStream,
    /// Not sent, and the stream ends: the device stays mute until it gets a
    /// new start request (as after a reboot or a lost stream).
    Mute,
}

/// A fault of the sensor itself, over a span of packets (indices as in
/// [`EmulatorConfig::script`]: 0-based over every packet produced).
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum SensorFault {
    /// From packet `from` (until `until`, exclusive, or for good) every packet
    /// carries the same counts, those of packet `from - 1` (stuck-at), while
    /// the RDT sequence and the sample counter go on counting.
    Frozen {
        /// First frozen packet.
        from: u64,
        /// First packet no longer frozen; `None`: for good.
        until: Option<u64>,
    },
    /// The chosen channels read the end of the measuring range (an amplifier
    /// at its rail) from packet `from` (until `until`, or for good).
    Saturated {
        /// First saturated packet.
        from: u64,
        /// First packet no longer saturated; `None`: for good.
        until: Option<u64>,
        /// Which channels (Fx, Fy, Fz, Tx, Ty, Tz).
        channels: Channels,
        /// Which end; `None`: the side of each channel's reading (+ at 0).
        rail: Option<Rail>,
    },
    /// Packets `at .. at + packets` carry `counts` more: an outlier.
    Spike {
        /// First packet.
        at: u64,
        /// Added counts per channel.
        counts: [i32; 6],
        /// How many packets.
        packets: u64,
    },
    /// From packet `from` the reading drifts by `counts_per_packet` per
    /// packet (packet `from` itself not yet).
    Drift {
        /// First packet of the drift.
        from: u64,
        /// Drift per channel, counts per packet.
        counts_per_packet: [f64; 6],
    },
    /// From packet `from` the gain is off by `factor` (a wrong calibration, a
    /// damaged gauge): the reading with its drift is multiplied by it.
    Scale {
        /// First packet.
        from: u64,
        /// The gain (> 0).
        factor: f64,
    },
}

/// The measuring range of an OnRobot HEX-E QC in counts at OnRobot's scale
/// (10 000 counts/N, 100 000 counts/N m): 200 N on each force channel, 10 N m
/// about x and y, 13 N m about z (the datasheet's nominal capacity, as
/// `sar_config::scenario::DEFAULT_RANGE_N` and `DEFAULT_RANGE_NM`).
pub const HEX_E_RANGE_COUNTS: [i32; 6] = [
    2_000_000, 2_000_000, 2_000_000, 1_000_000, 1_000_000, 1_300_000,
];

/// The counts a device with `counts_per_n` and `counts_per_nm` sends for a
/// wrench (force then torque, sensor frame; rounded, saturating at the i32
/// range).
pub fn counts_for(
    force_n: [f64; 3],
    torque_nm: [f64; 3],
    counts_per_n: f64,
    counts_per_nm: f64,
) -> [i32; 6] {
    let [fx, fy, fz] = force_n.map(|f| (f * counts_per_n).round() as i32);
    let [tx, ty, tz] = torque_nm.map(|t| (t * counts_per_nm).round() as i32);
    [fx, fy, fz, tx, ty, tz]
}

/// How packets are paced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// One packet every `period_ns` while streaming.
    Periodic {
        /// The period, ns (OnRobot's rate command replaces it).
        period_ns: u64,
    },
    /// Only on [`Emulator::step`].
    Manual,
}

/// The emulator's set-up.
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorConfig {
    /// Which dialect it speaks (bias semantics; filter and rate are OnRobot's).
    pub flavour: Flavour,
    /// How packets are paced.
    pub pacing: Pacing,
    /// The raw reading Fx, Fy, Fz, Tx, Ty, Tz, counts (before the bias).
    pub counts: [i32; 6],
    /// The sample counter before the first packet.
    pub first_counter: u32,
    /// Faults by packet index (0-based over all packets produced).
    pub script: Vec<(u64, Action)>,
    /// Noise std per channel, counts (>= 0). Default none: every packet then
    /// carries the same counts, which is exactly what a frozen sensor sends;
    /// a test of a live sensor gives it its noise (the HEX-E's resolution at
    /// OnRobot's scale: 2000, 2000, 8000, 1000, 1000, 200).
    pub noise_counts: [f64; 6],
    /// Seed of the noise (ChaCha8): same seed, same counts.
    pub seed: u64,
    /// Measuring range per channel, counts (> 0): readings are clipped to
    /// +-range. Default [`HEX_E_RANGE_COUNTS`].
    pub range_counts: [i32; 6],
    /// Faults of the sensor itself.
    pub faults: Vec<SensorFault>,
}

impl EmulatorConfig {
    /// An OnRobot device with a fixed reading and no faults.
    pub fn new(pacing: Pacing) -> Self {
        Self {
            flavour: Flavour::OnRobot,
            pacing,
            counts: [12_500, -25_000, 98_066, 1_000, -2_000, 3_000],
            first_counter: 1000,
            script: Vec::new(),
            noise_counts: [0.0; 6],
            seed: 0,
            range_counts: HEX_E_RANGE_COUNTS,
            faults: Vec::new(),
        }
    }
}

#[derive(Debug)]
struct State {
    flavour: Flavour,
    counts: [i32; 6],
    bias: Option<[i32; 6]>,
    filter_code: Option<u32>,
    period_ns: Option<u64>,
    script: BTreeMap<u64, Action>,
    client: Option<SocketAddr>,
    streaming: bool,
    remaining: Option<u32>,
    rdt_sequence: u32,
    counter: u32,
    produced: u64,
    held: Option<[u8; crate::codec::RESPONSE_LEN]>,
    next_send: Instant,
    requests: Vec<Request>,
    raw: Vec<Vec<u8>>,
    starts: u64,
    rng: ChaCha8Rng,
    noise_counts: [f64; 6],
    range_counts: [i32; 6],
    faults: Vec<SensorFault>,
    /// The counts of the last packet produced (sent or not).
    last_counts: Option<[i32; 6]>,
    /// While frozen: the counts repeated.
    frozen_counts: Option<[i32; 6]>,
}

/// Whether `index` is in `from .. until` (`until` `None`: for good).
fn within(index: u64, from: u64, until: Option<u64>) -> bool {
    from <= index && until.is_none_or(|u| index < u)
}

impl State {
    /// The reading of packet `index` before the device's bias, counts (the
    /// module doc's order); draws the packet's noise.
    fn reading(&mut self, index: u64) -> [i32; 6] {
        let mut noise = [0.0; 6];
        for n in &mut noise {
            *n = self.rng.sample(StandardNormal);
        }
        let mut raw = self.counts.map(f64::from);
        let mut gain = 1.0;
        let mut pinned: [Option<Option<Rail>>; 6] = [None; 6];
        for fault in &self.faults {
            match *fault {
                SensorFault::Drift {
                    from,
                    counts_per_packet,
                } if from <= index => {
                    let packets = (index - from) as f64;
                    for (r, d) in raw.iter_mut().zip(counts_per_packet) {
                        *r += d * packets;
                    }
                }
                SensorFault::Scale { from, factor } if from <= index => gain *= factor,
                SensorFault::Saturated {
                    from,
                    until,
                    channels,
                    rail,
                } if within(index, from, until) => {
                    for (p, on) in pinned.iter_mut().zip(channels) {
                        if on {
                            *p = Some(rail);
                        }
                    }
                }
                _ => {}
            }
        }
        for ((r, n), std) in raw.iter_mut().zip(noise).zip(self.noise_counts) {
            *r = *r * gain + n * std;
        }
        for fault in &self.faults {
            if let SensorFault::Spike {
                at,
                counts,
                packets,
            } = *fault
                && at <= index
                && index - at < packets
            {
                for (r, c) in raw.iter_mut().zip(counts) {
                    *r += f64::from(c);
                }
            }
        }
        let mut out = [0i32; 6];
        for (((o, r), range), pin) in out.iter_mut().zip(raw).zip(self.range_counts).zip(pinned) {
            let range = f64::from(range);
            let value = match pin {
                Some(rail) => rail.map_or(if r >= 0.0 { range } else { -range }, |rail| {
                    rail.sign() * range
                }),
                None => r.round().clamp(-range, range),
            };
            // Within the i32 range: the range is an i32.
            *o = value as i32;
        }
        out
    }

    /// The counts packet `index` carries: the reading less the bias, or
    /// (while a frozen fault lasts) the counts it froze at.
    fn packet_counts(&mut self, index: u64) -> [i32; 6] {
        let bias = self.bias.unwrap_or([0; 6]);
        let mut counts = self.reading(index);
        for (c, b) in counts.iter_mut().zip(bias) {
            *c = c.wrapping_sub(b);
        }
        let frozen = self.faults.iter().any(|f| match *f {
            SensorFault::Frozen { from, until } => within(index, from, until),
            _ => false,
        });
        if frozen {
            counts = *self
                .frozen_counts
                .get_or_insert(self.last_counts.unwrap_or(counts));
        } else {
            self.frozen_counts = None;
        }
        self.last_counts = Some(counts);
        counts
    }

    /// Produces one packet (if streaming) and sends what the script says.
    fn produce(&mut self, socket: &UdpSocket) -> bool {
        let Some(client) = self.client.filter(|_| self.streaming) else {
            return false;
        };
        let index = self.produced;
        self.produced += 1;
        let action = self.script.get(&index).copied();
        if action == Some(Action::RestartStream) {
            self.rdt_sequence = 0;
        }
        self.rdt_sequence = self.rdt_sequence.wrapping_add(1);
        self.counter = self.counter.wrapping_add(1);
        let counts = self.packet_counts(index);
        let response = Response {
            rdt_sequence: self.rdt_sequence,
            sample_counter: self.counter,
            status: match action {
                Some(Action::Status(s)) => s,
                _ => 0,
            },
            counts,
        };
        let bytes = response.encode();
        let send = |b: &[u8]| {
            let _ = socket.send_to(b, client);
        };
        match action {
            Some(Action::Drop) => {}
            Some(Action::Mute) => {
                self.streaming = false;
                return true;
            }
            Some(Action::Duplicate) => {
                send(&bytes);
                send(&bytes);
            }
            Some(Action::SwapWithNext) => {
                if let Some(held) = self.held.replace(bytes) {
                    send(&held);
                }
                return true;
            }
            Some(Action::Status(_) | Action::RestartStream) | None => send(&bytes),
        }
        if let Some(held) = self.held.take() {
            send(&held);
        }
        if let Some(left) = self.remaining.as_mut() {
            *left = left.saturating_sub(1);
            if *left == 0 {
                self.streaming = false;
            }
        }
        true
    }

    fn handle(&mut self, bytes: &[u8], from: SocketAddr) {
        self.raw.push(bytes.to_vec());
        let Ok(request) = Request::decode(bytes) else {
            return;
        };
        self.requests.push(request);
        let onrobot = self.flavour == Flavour::OnRobot;
        match request.command {
            CMD_START => {
                self.client = Some(from);
                self.streaming = true;
                self.remaining = (request.data != 0).then_some(request.data);
                self.rdt_sequence = 0;
                self.held = None;
                self.starts += 1;
                self.next_send = Instant::now();
            }
            CMD_STOP => self.streaming = false,
            CMD_BIAS if onrobot => {
                self.bias = (request.data == BIAS_ON).then_some(self.counts);
            }
            CMD_BIAS => self.bias = Some(self.counts),
            CMD_FILTER if onrobot && request.data <= 6 => self.filter_code = Some(request.data),
            CMD_RATE if onrobot && request.data > 0 && self.period_ns.is_some() => {
                self.period_ns = Some(u64::from(request.data) * 1_000_000);
            }
            _ => {}
        }
    }
}

#[derive(Debug)]
struct Shared {
    state: Mutex<State>,
    changed: Condvar,
    stop: AtomicBool,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        // A panic in a test thread poisons the lock; the state is still
        // consistent (every update is a few plain stores).
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// The emulated device (see the module doc). Dropping it stops its thread.
#[derive(Debug)]
pub struct Emulator {
    address: SocketAddr,
    socket: UdpSocket,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl Emulator {
    /// Binds `127.0.0.1:0` and starts serving.
    pub fn start(config: EmulatorConfig) -> std::io::Result<Self> {
        let socket = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))?;
        let address = socket.local_addr()?;
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                flavour: config.flavour,
                counts: config.counts,
                bias: None,
                filter_code: None,
                period_ns: match config.pacing {
                    Pacing::Periodic { period_ns } => Some(period_ns.max(1)),
                    Pacing::Manual => None,
                },
                script: config.script.into_iter().collect(),
                client: None,
                streaming: false,
                remaining: None,
                rdt_sequence: 0,
                counter: config.first_counter,
                produced: 0,
                held: None,
                next_send: Instant::now(),
                requests: Vec::new(),
                raw: Vec::new(),
                starts: 0,
                rng: ChaCha8Rng::seed_from_u64(config.seed),
                noise_counts: config.noise_counts,
                range_counts: config.range_counts,
                faults: config.faults,
                last_counts: None,
                frozen_counts: None,
            }),
            changed: Condvar::new(),
            stop: AtomicBool::new(false),
        });
        let thread = {
            let socket = socket.try_clone()?;
            let shared = Arc::clone(&shared);
            std::thread::Builder::new()
                .name("rdt-emulator".into())
                .spawn(move || serve(&socket, &shared))?
        };
        Ok(Self {
            address,
            socket,
            shared,
            thread: Some(thread),
        })
    }

    /// The address the device listens on.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Manual pacing: produces `n` packets now (each following the script);
    /// returns how many were produced (fewer when the stream is not running).
    pub fn step(&self, n: u64) -> u64 {
        let mut state = self.shared.lock();
        let mut produced = 0;
        for _ in 0..n {
            if !state.produce(&self.socket) {
                break;
            }
            produced += 1;
        }
        drop(state);
        self.shared.changed.notify_all();
        produced
    }

    /// Sends raw bytes to the client (the last host that sent a start).
    pub fn send_raw(&self, bytes: &[u8]) -> bool {
        let client = self.shared.lock().client;
        client.is_some_and(|c| self.socket.send_to(bytes, c).is_ok())
    }

    /// Replaces the raw reading, counts.
    pub fn set_counts(&self, counts: [i32; 6]) {
        self.shared.lock().counts = counts;
    }

    /// Adds a fault of the sensor (packet indices as in the config; a test
    /// with periodic pacing can key it on [`Emulator::produced`]).
    pub fn add_fault(&self, fault: SensorFault) {
        self.shared.lock().faults.push(fault);
    }

    /// Waits at most `timeout` until `done(state)` holds; whether it does.
    fn wait_until(&self, timeout: Duration, done: impl Fn(&State) -> bool) -> bool {
        let deadline = Instant::now() + timeout;
        let mut state = self.shared.lock();
        loop {
            if done(&state) {
                return true;
            }
            let now = Instant::now();
            if now >= deadline {
                return false;
            }
            state = match self.shared.changed.wait_timeout(state, deadline - now) {
                Ok((s, _)) => s,
                Err(poisoned) => poisoned.into_inner().0,
            };
        }
    }

    /// Waits at most `timeout` for the `n`-th start request; whether it came.
    pub fn wait_for_starts(&self, n: u64, timeout: Duration) -> bool {
        self.wait_until(timeout, |s| s.starts >= n)
    }

    /// Waits at most `timeout` for the `n`-th datagram; whether it came.
    pub fn wait_for_datagrams(&self, n: usize, timeout: Duration) -> bool {
        self.wait_until(timeout, |s| s.raw.len() >= n)
    }

    /// Start requests received so far.
    pub fn starts(&self) -> u64 {
        self.shared.lock().starts
    }

    /// Every well-formed request received, in order.
    pub fn requests(&self) -> Vec<Request> {
        self.shared.lock().requests.clone()
    }

    /// Every datagram received, as bytes, in order.
    pub fn datagrams(&self) -> Vec<Vec<u8>> {
        self.shared.lock().raw.clone()
    }

    /// Whether the device is streaming.
    pub fn is_streaming(&self) -> bool {
        self.shared.lock().streaming
    }

    /// Packets produced so far (sent or not).
    pub fn produced(&self) -> u64 {
        self.shared.lock().produced
    }

    /// The bias in force, counts (`None`: raw readings).
    pub fn bias(&self) -> Option<[i32; 6]> {
        self.shared.lock().bias
    }

    /// OnRobot's filter code last set.
    pub fn filter_code(&self) -> Option<u32> {
        self.shared.lock().filter_code
    }

    /// The period of periodic pacing, ns.
    pub fn period_ns(&self) -> Option<u64> {
        self.shared.lock().period_ns
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The emulator's thread: requests, and packets when periodic. The socket is
/// non-blocking and the thread sleeps between looks (at most 1 ms, less when
/// a packet is due): a socket timeout would be rounded up to the kernel's
/// tick (4 ms at 250 Hz), too coarse for a 1 kHz device.
fn serve(socket: &UdpSocket, shared: &Shared) {
    let idle = Duration::from_millis(1);
    let mut buf = [0u8; 64];
    if socket.set_nonblocking(true).is_err() {
        return;
    }
    while !shared.stop.load(Ordering::Acquire) {
        // Bounded: at most 64 requests per look.
        for _ in 0..64 {
            let Ok((n, from)) = socket.recv_from(&mut buf) else {
                break;
            };
            shared.lock().handle(buf.get(..n).unwrap_or(&[]), from);
            shared.changed.notify_all();
        }
        let mut state = shared.lock();
        let mut sleep = idle;
        if let Some(period_ns) = state.period_ns.filter(|_| state.streaming) {
            let now = Instant::now();
            if now >= state.next_send {
                state.produce(socket);
                let period = Duration::from_nanos(period_ns);
                state.next_send += period;
                // After a stall, resume the rhythm instead of a burst.
                if state.next_send + 10 * period < now {
                    state.next_send = now + period;
                }
                shared.changed.notify_all();
            }
            sleep = state.next_send.saturating_duration_since(now).min(idle);
        }
        drop(state);
        std::thread::sleep(sleep);
    }
}
