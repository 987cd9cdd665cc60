//! Recording from `sard`: the loop's recording sink [`LiveRecorder`]
//! (`sar_loop::sink`), which pushes each cycle's messages into the active [`Recorder`]'s bounded
//! queue (no wait, no allocation: a full queue drops and counts), and a
//! manager thread ([`RecordManager`]) that opens and closes recordings on
//! request (`sarctl record start|stop`, through [`RecordSwitch`]) or by
//! configuration (`[record] enabled`), so that no file is created, no thread
//! started and no writer joined on the loop's thread.
//!
//! Per cycle: `/sar/cycle/input`, `/sar/sensor/wrench` (every sample the
//! sensor's driver received since the previous cycle, drained by the loop:
//! a sensor faster than the loop loses none), `/sar/joints` (a new stamp),
//! then the outputs of [`super::convert::outputs`]. On the simulator
//! (the loop's [`Cycle::truth`]), each cycle with a new sensor sample also
//! records the simulator's truth on `/sar/sim/tip_wrench_truth` (the
//! reference of `sarctl replay --compare`). After the cycle's messages, at
//! the start of a recording and every `snapshot_period_ns`,
//! `/sar/cycle/snapshot`: the loop's whole decision state after that cycle
//! (pushed as chunks; the writer joins them and starts each rotated file
//! with one). So a recording started at any time (`sarctl record start`),
//! and each of its files, replays bit for bit from its first snapshot (the
//! `sar_replay` metadata still says `from_first_cycle`). Every recording
//! carries the daemon's configuration (`sar_config` metadata:
//! [`super::convert::config_metadata`]), so that `sarctl replay` needs no
//! `--config`.

use super::convert;
use super::file::{FileOptions, SceneOptions};
use super::recorder::{FailureWatch, Recorder, RecorderConfig};
use crossbeam_queue::ArrayQueue;
use sar_config::RecordSettings;
use sar_estimator::cycle::Bias;
use sar_loop::sink::{Cycle, Sink, SinkHealth};
use sar_msgs::msgs::SnapshotChunk;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

const WANT_NONE: u8 = 0;
const WANT_START: u8 = 1;
const WANT_STOP: u8 = 2;

/// Bytes a recorded cycle takes at most before compression (measured: about
/// 1.4 kB with one sensor sample a cycle, about 0.24 kB in the file after
/// zstd on the simulator): the bound behind the free-space check of a
/// recording's start.
pub const RECORD_BYTES_PER_CYCLE_BOUND: u64 = 2048;

/// What a start or stop request came to (the answer `sarctl record
/// start|stop` prints): the recording's first file, or why it failed.
pub type RecordAnswer = Result<String, String>;

/// Requests to start or stop recording, and what the loop reports back;
/// shared by the command server, the loop and the manager thread.
#[derive(Debug)]
pub struct RecordSwitch {
    want: AtomicU8,
    recording: AtomicBool,
    dropped: AtomicU64,
    /// `sar_msgs::wire::recording_code::failed(errno)` after a recording
    /// failed (written by the manager thread, read by the loop), else 0.
    failure: AtomicU64,
    /// The loop's period, ns (the free-space check's rate).
    cycle_period_ns: u64,
    /// Requests numbered (start and stop), for their answers.
    tickets: AtomicU64,
    /// The start request waiting for the manager's answer.
    start_ticket: AtomicU64,
    /// The stop request waiting for the manager's answer.
    stop_ticket: AtomicU64,
    /// The answer to a request, by its ticket. Locked by the command server
    /// and the manager thread, never the loop.
    answer: std::sync::Mutex<Option<(u64, RecordAnswer)>>,
    /// The recordings' directory (set by [`RecordManager::start`]).
    directory: std::sync::OnceLock<PathBuf>,
    /// The first file of the present or last recording.
    /// Locked by the command server and the manager thread, never the loop.
    current: std::sync::Mutex<Option<PathBuf>>,
    /// The manager thread, woken by the requests (set by
    /// [`RecordManager::start`]).
    manager: std::sync::OnceLock<std::thread::Thread>,
}

impl Default for RecordSwitch {
    /// A 1 kHz loop.
    fn default() -> Self {
        Self::new(1_000_000)
    }
}

impl RecordSwitch {
    /// The switch of a loop running every `cycle_period_ns`.
    pub fn new(cycle_period_ns: u64) -> Self {
        Self {
            want: AtomicU8::new(WANT_NONE),
            recording: AtomicBool::new(false),
            dropped: AtomicU64::new(0),
            failure: AtomicU64::new(0),
            cycle_period_ns: cycle_period_ns.max(1),
            tickets: AtomicU64::new(0),
            start_ticket: AtomicU64::new(0),
            stop_ticket: AtomicU64::new(0),
            answer: std::sync::Mutex::new(None),
            directory: std::sync::OnceLock::new(),
            current: std::sync::Mutex::new(None),
            manager: std::sync::OnceLock::new(),
        }
    }
    /// Wakes the manager thread (a request for it).
    fn wake_manager(&self) {
        if let Some(t) = self.manager.get() {
            t.unpark();
        }
    }
    /// Asks for a recording to start (no effect while one runs): the
    /// request's ticket, for [`RecordSwitch::answer`].
    pub fn request_start(&self) -> u64 {
        let ticket = self.tickets.fetch_add(1, Ordering::AcqRel) + 1;
        self.start_ticket.store(ticket, Ordering::Release);
        self.want.store(WANT_START, Ordering::Release);
        self.wake_manager();
        ticket
    }
    /// The manager's answer to request `ticket`, once given (the first
    /// file, or why the start was refused or the recording failed).
    pub fn answer(&self, ticket: u64) -> Option<RecordAnswer> {
        let guard = self.answer.lock().ok()?;
        match &*guard {
            Some((t, a)) if *t == ticket => Some(a.clone()),
            _ => None,
        }
    }
    fn give_answer(&self, ticket: u64, answer: RecordAnswer) {
        if ticket == 0 {
            return;
        }
        if let Ok(mut a) = self.answer.lock() {
            *a = Some((ticket, answer));
        }
    }
    /// The first file of the present or last recording (`None`: none yet).
    pub fn current_path(&self) -> Option<PathBuf> {
        self.current.lock().ok().and_then(|c| c.clone())
    }
    /// The recordings' directory (`None` before [`RecordManager::start`]).
    pub fn directory(&self) -> Option<&std::path::Path> {
        self.directory.get().map(PathBuf::as_path)
    }
    /// Remembers recording `name` (started) as the current one.
    fn set_current(&self, directory: &std::path::Path, name: &str) {
        if let Ok(mut c) = self.current.lock() {
            *c = Some(first_file(directory, name));
        }
    }
    /// Asks for the recording to stop: the request's ticket, for
    /// [`RecordSwitch::answer`] (given once the file is closed).
    pub fn request_stop(&self) -> u64 {
        let ticket = self.tickets.fetch_add(1, Ordering::AcqRel) + 1;
        self.stop_ticket.store(ticket, Ordering::Release);
        self.want.store(WANT_STOP, Ordering::Release);
        self.wake_manager();
        ticket
    }
    /// Whether the loop records now.
    pub fn recording(&self) -> bool {
        self.recording.load(Ordering::Acquire)
    }
    /// Messages dropped by every recording so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
    /// Takes a pending start request: whether there was one. Atomic
    /// (compare-exchange): a stop asked for at the same moment stays
    /// pending instead of being overwritten.
    pub fn take_start(&self) -> bool {
        self.take(WANT_START)
    }
    /// Takes a pending stop request (see [`RecordSwitch::take_start`]).
    pub fn take_stop(&self) -> bool {
        self.take(WANT_STOP)
    }
    fn take(&self, want: u8) -> bool {
        self.want
            .compare_exchange(want, WANT_NONE, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
    }
    /// Bytes a minute of recording needs at most (before compression).
    pub fn bytes_per_minute(&self) -> u64 {
        RECORD_BYTES_PER_CYCLE_BOUND.saturating_mul(60_000_000_000 / self.cycle_period_ns)
    }
}

/// The loop's recording sink: pushes every cycle into the active recorder
/// and keeps the recorder's counters in the loop's [`SinkHealth`].
pub struct LiveRecorder {
    switch: Arc<RecordSwitch>,
    incoming: Arc<ArrayQueue<Recorder>>,
    outgoing: Arc<ArrayQueue<Recorder>>,
    active: Option<Recorder>,
    /// A recorder handed back while the hand-back queue was full: kept, and
    /// handed back at the next cycle (never dropped on the loop's thread).
    held: Option<Recorder>,
    /// Drops of the recordings already handed back.
    dropped_before: u64,
    last_joints_stamp_ns: Option<u64>,
    /// The snapshot taken on the loop's thread (allocated at start).
    snapshot: Box<sar_snapshot::Snapshot>,
    snapshot_period_ns: u64,
    /// When the next snapshot is due (cycle stamp, ns); `None`: at once.
    next_snapshot_ns: Option<u64>,
}

impl LiveRecorder {
    /// Hands the active recorder back to the manager (a stop, a failed
    /// writer, the end). Never drops it on the loop's thread (freeing its
    /// queue would be a large deallocation there): when the hand-back queue
    /// is full it is held and handed back at the next cycle
    /// ([`LiveRecorder::hand_back_held`]), and no new recording is taken
    /// meanwhile, so at most one is ever held.
    pub fn release(&mut self) {
        self.hand_back_held();
        if let Some(rec) = self.active.take() {
            self.dropped_before += rec.dropped();
            // Handed over before the flag falls: the manager that reads
            // "not recording" finds the recorder to close.
            if let Err(rec) = self.outgoing.push(rec) {
                if self.held.is_none() {
                    self.held = Some(rec);
                } else {
                    // Unreachable (a recorder is held only while none is
                    // active); kept recording rather than dropped here.
                    self.active = Some(rec);
                    return;
                }
            }
            self.switch.recording.store(false, Ordering::Release);
        }
    }

    /// At the start of a cycle: hands back a held recorder first (while one
    /// is held, no new recording is taken: at most one is ever held); ends
    /// the recording on a stop request or a writer that failed (a full
    /// disk: the manager closes it and says why); takes a new one the
    /// manager opened. Wait-free, allocation-free.
    fn switch_recorder(&mut self) {
        let holding = self.hand_back_held();
        if let Some(rec) = self.active.as_ref().filter(|r| r.failed()) {
            // Published from this cycle on (the manager's close confirms it).
            self.switch.failure.store(
                sar_msgs::wire::recording_code::failed(rec.os_error()),
                Ordering::Relaxed,
            );
            self.release();
        }
        if self.switch.take_stop() {
            self.release();
        }
        if self.active.is_none()
            && !holding
            && let Some(rec) = self.incoming.pop()
        {
            self.active = Some(rec);
            self.last_joints_stamp_ns = None;
            self.next_snapshot_ns = None;
            self.switch.recording.store(true, Ordering::Release);
        }
    }

    /// Hands back the recorder [`LiveRecorder::release`] had to hold (the
    /// queue was full), once the manager has made room. Whether one is
    /// still held.
    pub fn hand_back_held(&mut self) -> bool {
        if let Some(rec) = self.held.take()
            && let Err(rec) = self.outgoing.push(rec)
        {
            self.held = Some(rec);
        }
        self.held.is_some()
    }

    /// The recorder still held at the end (the manager never made room):
    /// for the caller to stop off the loop's thread.
    pub fn take_held(&mut self) -> Option<Recorder> {
        self.held.take()
    }
}

/// The free places in a recording's queue that a simulated clock waits for
/// before a cycle (or half the queue, if smaller): more than one cycle
/// pushes, its snapshot's chunks included.
pub const ROOM_FOR_A_CYCLE: usize = 2 * sar_msgs::msgs::SNAPSHOT_CHUNKS_MAX + 64;

/// The simulator's truth of a cycle ([`Cycle::truth`]) is recorded on
/// `/sar/sim/tip_wrench_truth`: the visible part, `tip_force_n -
/// friction_force_n`, with every new sensor sample, stamped as the cycle.
impl Sink for LiveRecorder {
    /// Room for a cycle: at least [`ROOM_FOR_A_CYCLE`] free places in the
    /// recording's queue (a cycle with a snapshot pushes its chunks), or no
    /// recording, or a failed one (its writer no longer drains the queue:
    /// waiting would stall the simulation for good; it drops and counts, as
    /// in real time). Asked on a simulated clock only.
    fn has_room(&self) -> bool {
        self.active.as_ref().is_none_or(|rec| {
            rec.failed() || rec.free_slots() >= ROOM_FOR_A_CYCLE.min(rec.capacity() / 2)
        })
    }

    fn cycle(&mut self, c: &Cycle<'_>, health: &mut SinkHealth) {
        self.switch_recorder();
        let truth = c.truth;
        let mut dropped = self.dropped_before;
        if let Some(rec) = &mut self.active {
            let input = c.loop_input;
            let joints_new = self.last_joints_stamp_ns != Some(input.joints.stamp_ns);
            self.last_joints_stamp_ns = Some(input.joints.stamp_ns);
            convert::cycle_record_samples(
                c.loop_input,
                c.decision,
                joints_new,
                c.sensor_samples,
                truth,
                |m| {
                    rec.push(m);
                },
            );
            // The state after this cycle, at the start of a recording and
            // then periodically: replay restores it and steps the cycles
            // after it (the writer starts a rotated file with one).
            let stamp_ns = convert::cycle_stamp_ns(&input.cycle_input());
            if self.next_snapshot_ns.is_none_or(|due| stamp_ns >= due)
                && c.step.snapshot(&mut self.snapshot).is_ok()
            {
                self.next_snapshot_ns = Some(stamp_ns.saturating_add(self.snapshot_period_ns));
                SnapshotChunk::split(stamp_ns, input.cycle, self.snapshot.as_bytes(), |m| {
                    rec.push(m)
                });
            }
            dropped += rec.dropped();
        }
        self.switch.dropped.store(dropped, Ordering::Relaxed);
        health.recorder_drops = dropped;
        health.recording = if self.active.is_some() {
            sar_msgs::wire::recording_code::ON
        } else {
            self.switch.failure.load(Ordering::Relaxed)
        };
    }
}

/// Opens recordings for the loop and closes the ones it hands back, on its
/// own thread.
pub struct RecordManager {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// The recorder's file options under `settings` for a recording named `name`.
fn recorder_config(
    settings: &RecordSettings,
    scene: Option<SceneOptions>,
    name: &str,
    bias: &Bias,
    first: bool,
) -> RecorderConfig {
    let mut files = FileOptions::new(settings.directory.clone(), name);
    files.rotation = settings.rotation;
    let mut replay = convert::replay_metadata(bias, first);
    // Its files start with a snapshot (replay waits for one).
    replay.1.insert(
        convert::SNAPSHOT_FORMAT_KEY.to_owned(),
        sar_snapshot::VERSION.to_string(),
    );
    let lean = settings.mode == sar_config::RecordMode::Inputs;
    if lean {
        // A lean file (`crate::lean`): replay reads its batches.
        replay.1.insert(
            crate::lean::RECORD_MODE_KEY.to_owned(),
            settings.mode.name().to_owned(),
        );
    }
    files.metadata = vec![replay];
    if let Some(source) = &settings.config_source {
        files.metadata.push(convert::config_metadata(source));
    }
    // The lean mode records what replay needs: no scene (`replay
    // --output` draws it).
    files.scene = if lean { None } else { scene };
    files.lean = lean;
    // Rotation waits for the next snapshot, or rotates anyway after twice
    // its period and a second more (snapshots dropped).
    files.rotate_at_snapshots_grace_ns = Some(
        settings
            .snapshot_period_ns
            .saturating_mul(2)
            .saturating_add(1_000_000_000),
    );
    let mut c = RecorderConfig::new(files);
    c.queue_capacity = settings.queue_capacity;
    c.lean = lean.then_some(settings.scales);
    c
}

/// The first file of recording `name` in `directory` (as [`FileOptions::path`] names it).
fn first_file(directory: &std::path::Path, name: &str) -> PathBuf {
    FileOptions::new(directory, name).path(0)
}

fn recording_name() -> String {
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    format!("sar-{}-{:03}", now.as_secs(), now.subsec_millis())
}

impl RecordManager {
    /// The manager and the loop's recording sink; with `settings.enabled`,
    /// the first recording is open before this returns (it holds the
    /// daemon's first cycle).
    pub fn start(
        settings: RecordSettings,
        scene: Option<SceneOptions>,
        bias: Bias,
        switch: Arc<RecordSwitch>,
    ) -> Result<(Self, LiveRecorder), String> {
        let incoming = Arc::new(ArrayQueue::new(1));
        let outgoing = Arc::new(ArrayQueue::new(4));
        let snapshot_period_ns = settings.snapshot_period_ns;
        let _ = switch.directory.set(settings.directory.clone());
        if settings.enabled {
            check_directory(&settings.directory, switch.bytes_per_minute())?;
            let name = recording_name();
            let rec = Recorder::start(recorder_config(&settings, scene, &name, &bias, true))
                .map_err(|e| {
                    format!(
                        "cannot start recording into {}: {e}",
                        settings.directory.display()
                    )
                })?;
            tracing::info!(
                "recording into {}/{name}-*.mcap",
                settings.directory.display()
            );
            switch.set_current(&settings.directory, &name);
            let _ = incoming.push(rec);
        }
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (incoming, outgoing, switch, stop) = (
                Arc::clone(&incoming),
                Arc::clone(&outgoing),
                Arc::clone(&switch),
                Arc::clone(&stop),
            );
            std::thread::Builder::new()
                .name("sar-record-mgr".into())
                .spawn(move || {
                    manage(
                        &settings, scene, &bias, &switch, &incoming, &outgoing, &stop,
                    )
                })
                .map_err(|e| format!("cannot start the recording thread: {e}"))?
        };
        let _ = switch.manager.set(thread.thread().clone());
        Ok((
            Self {
                stop,
                thread: Some(thread),
            },
            LiveRecorder {
                switch,
                incoming,
                outgoing,
                active: None,
                held: None,
                dropped_before: 0,
                last_joints_stamp_ns: None,
                snapshot: Box::new(sar_snapshot::Snapshot::new()),
                snapshot_period_ns: snapshot_period_ns.max(1),
                next_snapshot_ns: None,
            },
        ))
    }

    /// After the loop: closes every recording (call after
    /// [`LiveRecorder::release`]), waiting for the manager thread at most
    /// [`FINISH_WAIT`] (a disk that stalls holds its last write): false when
    /// it was left behind (`sar_hal::join::left_behind` names it; the
    /// file is then cut short, and `sarctl recover` rewrites it).
    pub fn finish(mut self) -> bool {
        self.stop.store(true, Ordering::Release);
        match self.thread.take() {
            Some(t) => {
                t.thread().unpark();
                sar_hal::join::join_within(t, FINISH_WAIT).is_some()
            }
            None => true,
        }
    }
}

/// How long [`RecordManager::finish`] waits for the recordings to close at
/// most (the unit's `TimeoutStopSec` is 5 s for the whole stop).
pub const FINISH_WAIT: Duration = Duration::from_secs(3);

/// Megabytes (10^6 bytes), for the messages.
fn mb(bytes: u64) -> f64 {
    bytes as f64 / 1e6
}

/// Whether a recording can start in `directory` (made if missing): it must
/// be writable and hold at least a minute of recording
/// (`bytes_per_minute`, the bound before compression). The refusal says
/// which, with the free space and the need.
#[allow(unsafe_code)]
pub fn check_directory(directory: &Path, bytes_per_minute: u64) -> Result<(), String> {
    use std::os::unix::ffi::OsStrExt;
    let shown = directory.display();
    std::fs::create_dir_all(directory)
        .map_err(|e| format!("{shown}: the recordings' directory cannot be made: {e}"))?;
    let c = std::ffi::CString::new(directory.as_os_str().as_bytes())
        .map_err(|_| format!("{shown}: the path holds a NUL byte"))?;
    // SAFETY: `c` is a valid NUL-terminated path; `vfs` is written by the
    // call before it is read (zeroed: a plain C struct).
    let mut vfs: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut vfs) } != 0 {
        let e = std::io::Error::last_os_error();
        return Err(format!(
            "{shown}: cannot read the file system's free space: {e}"
        ));
    }
    if vfs.f_flag & libc::ST_RDONLY != 0 {
        return Err(format!(
            "{shown}: read-only file system: a recording cannot be written there"
        ));
    }
    // SAFETY: as above; `access` only reads the path.
    if unsafe { libc::access(c.as_ptr(), libc::W_OK | libc::X_OK) } != 0 {
        let e = std::io::Error::last_os_error();
        return Err(format!("{shown}: not writable by the daemon: {e}"));
    }
    // (u64 on 64-bit Linux, narrower elsewhere.)
    #[allow(clippy::useless_conversion)]
    let free = u64::from(vfs.f_bavail).saturating_mul(u64::from(vfs.f_frsize));
    if free < bytes_per_minute {
        return Err(format!(
            "{shown}: too little space: {:.1} MB free, a minute of recording needs up to {:.1} MB ({} bytes a cycle before compression)",
            mb(free),
            mb(bytes_per_minute),
            RECORD_BYTES_PER_CYCLE_BOUND
        ));
    }
    Ok(())
}

/// Closes a recording handed back by the loop: its first file, or why it
/// is incomplete (logged at once either way), and the OS error behind a
/// failure (0: none).
fn close(rec: Recorder, first: Option<&Path>) -> (RecordAnswer, u32) {
    let first = first.map_or_else(String::new, |p| p.display().to_string());
    match rec.stop() {
        Ok(r) => {
            tracing::info!(
                "recording closed: {} messages written, {} dropped, files {}",
                r.written,
                r.dropped,
                r.files
                    .iter()
                    .map(|f| f.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            (Ok(first), 0)
        }
        Err(e) => {
            let errno = e.os_error().map_or(0, i32::unsigned_abs);
            tracing::error!(
                "the recording {first} is incomplete, it stopped at a write error: {e}; \
                 the loop goes on (`sarctl recover` rewrites a file cut short)"
            );
            // The reply's detail is short (256 bytes): the file and the cause.
            let cause = match e.os_error() {
                Some(n) => format!("write error: {}", std::io::Error::from_raw_os_error(n)),
                None => e.to_string(),
            };
            (Err(format!("{first} is incomplete: {cause}")), errno)
        }
    }
}

/// The manager thread's longest sleep: it is woken by the requests
/// ([`RecordSwitch::request_start`], [`RecordSwitch::request_stop`]), by a
/// writer that fails ([`Recorder::failure_watch`]: then it polls until the
/// loop hands the recording back, and closes it and says why at once) and
/// at the end; the drop warnings' period.
pub const MANAGER_WAIT: Duration = Duration::from_secs(1);
/// The manager thread's sleep while the loop has a request or a recording
/// to take or hand back (one to a few cycles).
pub const MANAGER_POLL: Duration = Duration::from_millis(5);

/// The manager thread's body: closes what the loop hands back and answers
/// the stops, opens what is asked for, sleeps until there is work.
fn manage(
    settings: &RecordSettings,
    scene: Option<SceneOptions>,
    bias: &Bias,
    switch: &RecordSwitch,
    incoming: &ArrayQueue<Recorder>,
    outgoing: &ArrayQueue<Recorder>,
    stop: &AtomicBool,
) {
    let mut m = Manager {
        settings,
        scene,
        bias,
        switch,
        incoming,
        outgoing,
        told: (0, std::time::Instant::now()),
        last: None,
        watch: None,
    };
    loop {
        m.warn_drops();
        let stopping = stop.load(Ordering::Acquire);
        m.close_handed_back();
        if stopping {
            // Never handed to the loop: close it too.
            while let Some(rec) = incoming.pop() {
                let _ = close(rec, switch.current_path().as_deref());
            }
            return;
        }
        m.start_if_asked();
        m.sleep();
    }
}

/// What the manager thread works with and remembers.
struct Manager<'a> {
    settings: &'a RecordSettings,
    scene: Option<SceneOptions>,
    bias: &'a Bias,
    switch: &'a RecordSwitch,
    incoming: &'a ArrayQueue<Recorder>,
    outgoing: &'a ArrayQueue<Recorder>,
    /// The drops the log has told of, and when (at most one line a second).
    told: (u64, std::time::Instant),
    /// What the last recording came to (`None`: none closed yet).
    last: Option<RecordAnswer>,
    /// The failure of the recording started last, until it is closed.
    watch: Option<FailureWatch>,
}

impl Manager<'_> {
    /// Warns of the messages the recorder dropped since the last warning
    /// (at most once a second).
    fn warn_drops(&mut self) {
        let dropped = self.switch.dropped();
        if dropped > self.told.0 && self.told.1.elapsed() >= Duration::from_secs(1) {
            tracing::warn!(
                "the recorder dropped {} messages ({dropped} so far): its writer does not keep \
                 up (disk stalled or full); the loop goes on, the recording has gaps",
                dropped - self.told.0
            );
            self.told = (dropped, std::time::Instant::now());
        }
    }

    /// Closes the recordings the loop handed back, then answers a stop the
    /// loop took.
    fn close_handed_back(&mut self) {
        let switch = self.switch;
        // Read before closing: a stop taken by the loop with the recording
        // handed back (the flag falls after the hand-over) is answered below.
        let stop_ticket = switch.stop_ticket.load(Ordering::Acquire);
        let stop_taken = stop_ticket != 0 && switch.want.load(Ordering::Acquire) != WANT_STOP;
        let idle = !switch.recording();
        while let Some(rec) = self.outgoing.pop() {
            let (answer, errno) = close(rec, switch.current_path().as_deref());
            let code = match &answer {
                Ok(_) => 0,
                Err(_) => sar_msgs::wire::recording_code::failed(errno),
            };
            switch.failure.store(code, Ordering::Relaxed);
            self.last = Some(answer);
            self.watch = None;
        }
        if stop_taken && idle {
            // Taken: a later stop with nothing recorded is answered "no
            // recording ran", not with this recording's outcome again.
            let answer = self.last.take().unwrap_or_else(|| Ok(String::new()));
            switch.give_answer(stop_ticket, answer);
            let _ = switch.stop_ticket.compare_exchange(
                stop_ticket,
                0,
                Ordering::AcqRel,
                Ordering::Acquire,
            );
        }
    }

    /// Opens a recording when one was asked for (the request is taken
    /// first, atomically, then judged) and answers the request.
    fn start_if_asked(&mut self) {
        let switch = self.switch;
        if !switch.take_start() {
            return;
        }
        let ticket = switch.start_ticket.swap(0, Ordering::AcqRel);
        // The name chosen with the request, taken even when the request
        // has no effect (a recording runs or is being handed over).
        let name = recording_name();
        let answer = if switch.recording() || !self.incoming.is_empty() {
            Ok(switch
                .current_path()
                .map_or_else(String::new, |p| p.display().to_string()))
        } else {
            start_one(
                self.settings,
                self.scene,
                self.bias,
                switch,
                self.incoming,
                &name,
                &mut self.watch,
            )
        };
        if let Err(e) = &answer {
            tracing::error!("cannot start recording: {e}");
        }
        switch.give_answer(ticket, answer);
    }

    /// Sleeps until a request or the end wakes it: [`MANAGER_POLL`] while
    /// the loop has something to take or hand back, else at most
    /// [`MANAGER_WAIT`].
    fn sleep(&self) {
        let switch = self.switch;
        let settling = switch.want.load(Ordering::Acquire) != WANT_NONE
            || switch.stop_ticket.load(Ordering::Acquire) != 0
            || !self.incoming.is_empty()
            || !self.outgoing.is_empty()
            || self.watch.as_ref().is_some_and(FailureWatch::failed);
        std::thread::park_timeout(if settling { MANAGER_POLL } else { MANAGER_WAIT });
    }
}

/// Starts recording `name` after checking the directory: its first file.
fn start_one(
    settings: &RecordSettings,
    scene: Option<SceneOptions>,
    bias: &Bias,
    switch: &RecordSwitch,
    incoming: &ArrayQueue<Recorder>,
    name: &str,
    watch: &mut Option<FailureWatch>,
) -> RecordAnswer {
    check_directory(&settings.directory, switch.bytes_per_minute())?;
    let rec = Recorder::start(recorder_config(settings, scene, name, bias, false))
        .map_err(|e| format!("{}: {e}", settings.directory.display()))?;
    tracing::info!(
        "recording into {}/{name}-*.mcap",
        settings.directory.display()
    );
    switch.set_current(&settings.directory, name);
    switch.failure.store(0, Ordering::Relaxed);
    *watch = Some(rec.failure_watch(std::thread::current()));
    let _ = incoming.push(rec);
    Ok(first_file(&settings.directory, name).display().to_string())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]

    use super::*;
    use sar_msgs::msgs::{Outgoing, WrenchStamped};

    /// A paused recorder (no writer thread) into `dir`.
    fn recorder(dir: &Path, name: &str) -> Recorder {
        Recorder::new_paused(RecorderConfig::new(FileOptions::new(dir, name))).unwrap()
    }

    /// On a simulated clock the loop waits for `has_room`: a full queue
    /// has none, a failed recording (whose writer drains nothing) always
    /// has, so a dead writer cannot stall the simulation for good.
    #[test]
    fn a_full_queue_has_no_room_and_a_failed_recording_always_has() {
        let dir = std::env::temp_dir().join(format!("sar-live-room-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut config = RecorderConfig::new(FileOptions::new(&dir, "room"));
        config.queue_capacity = 8;
        let mut rec = Recorder::new_paused(config).unwrap();
        for i in 0..8 {
            assert!(rec.push(Outgoing::SimTruth(WrenchStamped::base_force(i, [0.0; 3]))));
        }
        let live = |active: Recorder| LiveRecorder {
            switch: Arc::new(RecordSwitch::default()),
            incoming: Arc::new(ArrayQueue::new(1)),
            outgoing: Arc::new(ArrayQueue::new(1)),
            active: Some(active),
            held: None,
            dropped_before: 0,
            last_joints_stamp_ns: None,
            snapshot: Box::new(sar_snapshot::Snapshot::new()),
            snapshot_period_ns: 1,
            next_snapshot_ns: None,
        };
        let live = live(rec);
        assert!(!live.has_room(), "a full queue has room");
        live.active.as_ref().unwrap().fail_for_test();
        assert!(live.has_room(), "a failed recording stalls the loop");
        let mut none = live;
        none.active = None;
        assert!(none.has_room());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Issue 35: with the hand-back queue full (a manager that has not yet
    /// closed what it was handed), `release` dropped the whole recorder on
    /// the loop's thread (its queue freed there, its recording lost). Now
    /// it is held, handed back once there is room, and no new recording is
    /// taken meanwhile: every recorder reaches the manager.
    #[test]
    fn a_full_hand_back_queue_holds_the_recorder_instead_of_dropping_it() {
        let dir = std::env::temp_dir().join(format!("sar-live-hold-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let switch = Arc::new(RecordSwitch::default());
        let incoming = Arc::new(ArrayQueue::new(1));
        let outgoing = Arc::new(ArrayQueue::new(4));
        for i in 0..4 {
            assert!(outgoing.push(recorder(&dir, &format!("old{i}"))).is_ok());
        }
        let mut live = LiveRecorder {
            switch: Arc::clone(&switch),
            incoming: Arc::clone(&incoming),
            outgoing: Arc::clone(&outgoing),
            active: Some(recorder(&dir, "active")),
            held: None,
            dropped_before: 0,
            last_joints_stamp_ns: None,
            snapshot: Box::new(sar_snapshot::Snapshot::new()),
            snapshot_period_ns: 1,
            next_snapshot_ns: None,
        };
        switch.recording.store(true, Ordering::Release);
        live.release();
        // Not dropped: held, the recording flag down.
        assert!(live.held.is_some(), "the recorder was dropped");
        assert!(live.active.is_none());
        assert!(!switch.recording());
        // Still no room: still held.
        assert!(live.hand_back_held());
        // The manager closes one: the held one goes at the next cycle.
        let mut closed = vec![outgoing.pop().unwrap()];
        assert!(!live.hand_back_held());
        while let Some(r) = outgoing.pop() {
            closed.push(r);
        }
        assert_eq!(closed.len(), 5, "every recorder reached the manager");
        assert!(live.take_held().is_none());
        drop(closed);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
