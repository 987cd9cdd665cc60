//! A device emulator for tests: serves the RDT protocol on a loopback UDP
//! port, honours start (with its sample count), stop, bias, filter and rate,
//! and follows a deterministic script of faults keyed by packet index (loss,
//! duplicates, reordering, status faults, going mute until restarted), and
//! of the sensor's own failure modes (a frozen reading, saturation, a spike,
//! a drifting bias). Its readings carry seeded Gaussian noise in counts
//! ([`EmulatorConfig::noise_counts`]) as a live sensor's do; with no noise
//! the device is, in effect, frozen (every reading the same), which the
//! daemon's frozen-sensor check rightly faults on.
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

use super::Flavour;
use super::codec::{
    BIAS_ON, CMD_BIAS, CMD_FILTER, CMD_RATE, CMD_START, CMD_STOP, Request, Response,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
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
    /// From this packet on the reading is frozen: every packet repeats the
    /// previous packet's six counts bit for bit while the RDT sequence and
    /// the sample counter go on (a stuck converter), until [`Action::Thaw`].
    Freeze,
    /// From this packet on the reading is live again (ends `Freeze` and
    /// `Saturate`).
    Thaw,
    /// From this packet on one channel (0..=5: Fx, Fy, Fz, Tx, Ty, Tz) reads
    /// this many counts (an amplifier at its rail: the configured range times
    /// counts per unit), until [`Action::Thaw`].
    Saturate {
        /// 0..=5.
        channel: usize,
        /// The counts it reads.
        counts: i32,
    },
    /// This packet alone carries these counts added to its reading.
    Spike([i32; 6]),
    /// From this packet on the bias drifts: each channel gains this many
    /// counts per 1000 packets (linear in the packet index).
    Drift([i32; 6]),
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
#[derive(Debug, Clone, PartialEq, Eq)]
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
    /// Standard deviation of each channel's noise, counts (0: an exact,
    /// noiseless reading: for protocol tests; a live device is never so).
    pub noise_counts: [u32; 6],
    /// Seed of the noise: the same seed gives the same packets.
    pub seed: u64,
}

impl EmulatorConfig {
    /// An OnRobot device with a fixed, noiseless reading and no faults (for
    /// tests of the protocol, where every count is checked).
    pub fn new(pacing: Pacing) -> Self {
        Self {
            flavour: Flavour::OnRobot,
            pacing,
            counts: [12_500, -25_000, 98_066, 1_000, -2_000, 3_000],
            first_counter: 1000,
            script: Vec::new(),
            noise_counts: [0; 6],
            seed: 0,
        }
    }

    /// A live OnRobot HEX-6 at 10000 counts/N and 100000 counts/N m: the
    /// article's noise (0.2, 0.2, 0.8 N; 0.01, 0.01, 0.002 N m) on the reading.
    pub fn live(pacing: Pacing, seed: u64) -> Self {
        Self {
            noise_counts: [2_000, 2_000, 8_000, 1_000, 1_000, 200],
            seed,
            ..Self::new(pacing)
        }
    }
}

/// The sensor's own state of failure in the emulator.
#[derive(Debug, Clone, Copy, Default)]
struct SensorModes {
    /// The counts every packet repeats.
    frozen: Option<[i32; 6]>,
    /// A channel pinned at a value.
    pinned: Option<(usize, i32)>,
    /// From which packet index, and how many counts per 1000 packets.
    drift: Option<(u64, [i32; 6])>,
    /// The previous packet's counts (before the bias).
    last: Option<[i32; 6]>,
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
    held: Option<[u8; super::codec::RESPONSE_LEN]>,
    next_send: Instant,
    requests: Vec<Request>,
    raw: Vec<Vec<u8>>,
    starts: u64,
    noise_counts: [u32; 6],
    rng: ChaCha8Rng,
    modes: SensorModes,
}

impl State {
    /// The raw counts of packet `index` (before the bias): the reading,
    /// the noise (drawn for every packet, so that a packet's noise depends
    /// only on the seed and its index), and the sensor's failure modes.
    fn reading(&mut self, index: u64, action: Option<Action>) -> [i32; 6] {
        let mut counts = self.counts;
        for (c, std) in counts.iter_mut().zip(self.noise_counts) {
            let z: f64 = self.rng.sample(StandardNormal);
            // Within i32 by far for any realistic std.
            *c = c.saturating_add((z * f64::from(std)).round() as i32);
        }
        match action {
            Some(Action::Freeze) => self.modes.frozen = self.modes.last.or(Some(counts)),
            Some(Action::Thaw) => {
                self.modes.frozen = None;
                self.modes.pinned = None;
            }
            Some(Action::Saturate { channel, counts }) => {
                self.modes.pinned = Some((channel, counts));
            }
            Some(Action::Drift(rate)) => self.modes.drift = Some((index, rate)),
            _ => {}
        }
        if let Some((from, rate)) = self.modes.drift {
            let k = index.saturating_sub(from);
            for (c, r) in counts.iter_mut().zip(rate) {
                let add = i64::from(r).saturating_mul(i64::try_from(k).unwrap_or(i64::MAX)) / 1000;
                *c = c.saturating_add(i32::try_from(add).unwrap_or(i32::MAX));
            }
        }
        if let Some(Action::Spike(spike)) = action {
            for (c, s) in counts.iter_mut().zip(spike) {
                *c = c.saturating_add(s);
            }
        }
        if let Some((channel, value)) = self.modes.pinned
            && let Some(c) = counts.get_mut(channel)
        {
            *c = value;
        }
        if let Some(frozen) = self.modes.frozen {
            counts = frozen;
        }
        self.modes.last = Some(counts);
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
        let bias = self.bias.unwrap_or([0; 6]);
        let mut counts = self.reading(index, action);
        for (c, b) in counts.iter_mut().zip(bias) {
            *c = c.wrapping_sub(b);
        }
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
            Some(
                Action::Status(_)
                | Action::RestartStream
                | Action::Freeze
                | Action::Thaw
                | Action::Saturate { .. }
                | Action::Spike(_)
                | Action::Drift(_),
            )
            | None => send(&bytes),
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
                noise_counts: config.noise_counts,
                rng: ChaCha8Rng::seed_from_u64(config.seed),
                modes: SensorModes::default(),
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
