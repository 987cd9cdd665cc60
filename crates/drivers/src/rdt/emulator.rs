//! A device emulator for tests: serves the RDT protocol on a loopback UDP
//! port, honours start (with its sample count), stop, bias, filter and rate,
//! and follows a deterministic script of faults keyed by packet index (loss,
//! duplicates, reordering, status faults, going mute until restarted).
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
    held: Option<[u8; super::codec::RESPONSE_LEN]>,
    next_send: Instant,
    requests: Vec<Request>,
    raw: Vec<Vec<u8>>,
    starts: u64,
}

impl State {
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
        let mut counts = self.counts;
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
