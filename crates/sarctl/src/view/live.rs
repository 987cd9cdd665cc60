//! The live view's server (cargo feature `view`): see the module above.

use super::front;
#[allow(unused_imports)]
pub use super::{DEFAULT_BIND, DEFAULT_SCENE_HZ};
use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer};
use sar_estimator::guard::ForceLimits;
use sar_msgs::msgs::{Outgoing, RosMessage, SceneStatus, Topic};
use sar_msgs::scene::{MarkerArray, TfMessage};
use sar_msgs::wire::{StateMsg, flags, guard_state_name, reason_name};
use sar_scene::geometry::SceneGeometry;
use sar_scene::{
    SCENE_STATUS_TOPIC, SCENE_TOPIC, TF_STATIC_TOPIC, TF_TOPIC, draw as scene, topics,
};
use sar_shm::{Client, StateSubscription};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The view's status (JSON).
pub const STATUS_TOPIC: &str = "/sar/view/status";
/// Messages queued per client before the oldest are dropped (about 0.4 s of
/// every topic at 1 kHz).
const BACKLOG: usize = 2048;
/// Without a state for this long, the view subscribes again (a restarted
/// daemon).
const IDLE: Duration = Duration::from_secs(2);

/// The recordings' topics the view serves (what the state holds, [`topics`]).
pub const RECORD_TOPICS: [Topic; 5] = [
    Topic::Joints,
    Topic::TipWrench,
    Topic::PassiveJoints,
    Topic::EstimatorState,
    Topic::GuardEvents,
];

/// Every topic the view serves.
pub fn served_topics() -> Vec<&'static str> {
    let mut t: Vec<&'static str> = RECORD_TOPICS.iter().map(|t| t.name()).collect();
    t.extend([
        SCENE_TOPIC,
        SCENE_STATUS_TOPIC,
        TF_TOPIC,
        TF_STATIC_TOPIC,
        STATUS_TOPIC,
    ]);
    t
}

/// What `sarctl view` is asked.
#[derive(Debug, Clone)]
pub struct ViewOptions {
    /// The daemon's service prefix.
    pub prefix: String,
    /// The address to serve on (port 0: any free port).
    pub bind: SocketAddr,
    /// The scene's rate, Hz.
    pub scene_hz: f64,
    /// The geometry of the scene.
    pub geometry: SceneGeometry,
}

/// `sarctl view` from its command line: loads `config` (default: the
/// built-in one), serves until SIGINT or SIGTERM. Prints the served URL on
/// stdout (`sarctl view: serving ws://ADDR:PORT ...`).
pub fn run_cli(
    prefix: &str,
    config: Option<&std::path::Path>,
    bind: &str,
    scene_hz: f64,
) -> Result<(), String> {
    let cfg = match config {
        Some(path) => sar_config::load(path),
        None => sar_config::builtin(),
    }
    .map_err(|e| e.to_string())?;
    let bind: SocketAddr = bind
        .parse()
        .map_err(|e| format!("--bind {bind:?}: {e} (expected ADDR:PORT)"))?;
    if !(scene_hz.is_finite() && scene_hz > 0.0) {
        return Err(format!(
            "--scene-hz {scene_hz:?}: must be a positive number"
        ));
    }
    sar_loop::rt::install_stop_handler()
        .map_err(|e| format!("cannot install signal handlers: {e}"))?;
    run(
        &ViewOptions {
            prefix: prefix.to_owned(),
            bind,
            scene_hz,
            geometry: SceneGeometry::from_config(&cfg.estimator),
        },
        sar_loop::rt::stop_requested,
    )
}

/// The channels of the recordings' topics this view serves.
struct RecordChannels {
    channels: Vec<(Topic, Arc<RawChannel>)>,
}

/// A channel of CDR messages with a `ros2msg` schema, as in a recording.
fn ros2_channel(
    ctx: &Arc<Context>,
    topic: &str,
    type_name: &str,
    schema: &'static str,
) -> Result<Arc<RawChannel>, String> {
    ChannelBuilder::new(topic)
        .message_encoding("cdr")
        .schema(Schema::new(type_name, "ros2msg", schema.as_bytes()))
        .context(ctx)
        .build_raw()
        .map_err(|e| format!("cannot create the channel {topic}: {e}"))
}

impl RecordChannels {
    fn new(ctx: &Arc<Context>) -> Result<Self, String> {
        let mut channels = Vec::new();
        for topic in RECORD_TOPICS {
            let channel = ros2_channel(ctx, topic.name(), topic.type_name(), topic.schema())?;
            channels.push((topic, channel));
        }
        Ok(Self { channels })
    }

    fn get(&self, topic: Topic) -> Option<&Arc<RawChannel>> {
        self.channels
            .iter()
            .find(|(t, _)| *t == topic)
            .map(|(_, c)| c)
    }
}

/// The JSON schema of [`STATUS_TOPIC`].
pub const STATUS_SCHEMA: &str = r#"{
  "type": "object",
  "properties": {
    "cycle": {"type": "integer"},
    "guard": {"type": "string"},
    "guard_code": {"type": "integer"},
    "reason": {"type": "string"},
    "observable": {"type": "boolean"},
    "halted": {"type": "boolean"},
    "force_total_n": {"type": "number"},
    "axial_n": {"type": "number"},
    "lateral_n": {"type": "number"},
    "warn_total_n": {"type": "number"},
    "stop_total_n": {"type": "number"},
    "warn_axial_n": {"type": "number"},
    "stop_axial_n": {"type": "number"},
    "warn_lateral_n": {"type": "number"},
    "stop_lateral_n": {"type": "number"},
    "truth_tip_force_n": {"type": "array", "items": {"type": "number"}},
    "wakeup_p99_us": {"type": "number"},
    "compute_p99_us": {"type": "number"},
    "overruns": {"type": "integer"},
    "quick_stops": {"type": "integer"},
    "view_lost": {"type": "integer"}
  }
}"#;

fn status_json(s: &StateMsg, lost: u64) -> serde_json::Value {
    let f = s.tip_force_n;
    let total = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
    let estimate = s.flags & flags::ESTIMATE != 0;
    let mut status = serde_json::json!({
        "cycle": s.cycle,
        "guard": guard_state_name(s.guard_state),
        "guard_code": s.guard_state,
        "reason": reason_name(s.guard_reason),
        "observable": s.flags & flags::OBSERVABLE != 0,
        "halted": s.flags & flags::HALTED != 0,
        "force_total_n": estimate.then_some(total),
        "axial_n": estimate.then_some(s.tip_axial_lateral_n[0]),
        "lateral_n": estimate.then_some(s.tip_axial_lateral_n[1]),
        "truth_tip_force_n": (s.flags & flags::SIM_TRUTH != 0).then_some(s.truth_tip_force_n),
        "wakeup_p99_us": s.wakeup_ns[1] as f64 / 1e3,
        "compute_p99_us": s.compute_ns[1] as f64 / 1e3,
        "overruns": s.overruns,
        "quick_stops": s.quick_stops,
        "view_lost": lost,
    });
    // The six force limits under their names (`ForceLimits::NAMES`, the
    // order of `limits_n`).
    if let serde_json::Value::Object(fields) = &mut status {
        for (name, v) in ForceLimits::NAMES.iter().zip(s.limits_n) {
            fields.insert((*name).to_owned(), serde_json::json!(v));
        }
    }
    status
}

/// The view's state between two published states.
struct Publisher {
    records: RecordChannels,
    scene: Arc<RawChannel>,
    tf: Arc<RawChannel>,
    tf_static: Arc<RawChannel>,
    scene_status: Arc<RawChannel>,
    status: Arc<RawChannel>,
    geometry: SceneGeometry,
    scene_period_ns: u64,
    next_scene_ns: u64,
    previous: Option<StateMsg>,
    /// States the view did not receive (gaps in the cycle numbers).
    lost: u64,
    messages: Vec<Outgoing>,
    buf: Vec<u8>,
}

impl Publisher {
    fn on_state(&mut self, s: &StateMsg) {
        if let Some(p) = &self.previous
            && s.cycle > p.cycle.saturating_add(1)
        {
            self.lost += s.cycle - p.cycle - 1;
        }
        let meta = || PartialMetadata::with_log_time(s.now_ns);
        topics::messages(s, self.previous.as_ref(), &mut self.messages);
        for m in &self.messages {
            let Some(channel) = self.records.get(m.topic()) else {
                continue;
            };
            if channel.has_sinks() && m.encode(&mut self.buf).is_ok() {
                channel.log_with_meta(&self.buf, meta());
            }
        }
        // The scene and the status, decimated by the state's clock.
        if s.now_ns >= self.next_scene_ns {
            // Keep the phase (30 Hz on a 1 ms loop is 30 Hz, not 1/34 ms);
            // after a gap, start again from this state.
            self.next_scene_ns = self.next_scene_ns.saturating_add(self.scene_period_ns);
            if self.next_scene_ns <= s.now_ns {
                self.next_scene_ns = s.now_ns.saturating_add(self.scene_period_ns);
            }
            // The same messages as a recording's; `/tf_static` with every
            // scene, so that a client that joins later has the fixed frames.
            if self.scene.has_sinks()
                && scene::scene(s, &self.geometry)
                    .encode(&mut self.buf)
                    .is_ok()
            {
                self.scene.log_with_meta(&self.buf, meta());
            }
            if self.tf.has_sinks()
                && scene::moving_frames(s, &self.geometry)
                    .encode(&mut self.buf)
                    .is_ok()
            {
                self.tf.log_with_meta(&self.buf, meta());
            }
            if self.tf_static.has_sinks()
                && scene::static_frames(s.now_ns).encode(&mut self.buf).is_ok()
            {
                self.tf_static.log_with_meta(&self.buf, meta());
            }
            if self.scene_status.has_sinks()
                && topics::scene_status(s).encode(&mut self.buf).is_ok()
            {
                self.scene_status.log_with_meta(&self.buf, meta());
            }
            if self.status.has_sinks()
                && let Ok(bytes) = serde_json::to_vec(&status_json(s, self.lost))
            {
                self.status.log_with_meta(&bytes, meta());
            }
        }
        self.previous = Some(*s);
    }
}

/// Serves the daemon's state until `stop()` says so. Fails at once when no
/// daemon runs with `opts.prefix` or the address cannot be bound.
pub fn run(opts: &ViewOptions, stop: impl Fn() -> bool) -> Result<(), String> {
    let client = Client::new(&opts.prefix).map_err(|e| e.to_string())?;
    let sub = client.subscribe().map_err(|e| e.to_string())?;
    let ctx = Context::new();
    let publisher = Publisher::new(&ctx, opts)?;
    let server = serve(&ctx, opts)?;
    follow(&client, sub, publisher, stop);
    let _ = server.stop();
    Ok(())
}

impl Publisher {
    /// The view's channels in `ctx`, nothing published yet.
    fn new(ctx: &Arc<Context>, opts: &ViewOptions) -> Result<Self, String> {
        let records = RecordChannels::new(ctx)?;
        let scene = ros2_channel(
            ctx,
            SCENE_TOPIC,
            MarkerArray::TYPE_NAME,
            MarkerArray::SCHEMA,
        )?;
        let tf = ros2_channel(ctx, TF_TOPIC, TfMessage::TYPE_NAME, TfMessage::SCHEMA)?;
        let scene_status = ros2_channel(
            ctx,
            SCENE_STATUS_TOPIC,
            SceneStatus::TYPE_NAME,
            SceneStatus::SCHEMA,
        )?;
        let tf_static = ros2_channel(
            ctx,
            TF_STATIC_TOPIC,
            TfMessage::TYPE_NAME,
            TfMessage::SCHEMA,
        )?;
        let status = ChannelBuilder::new(STATUS_TOPIC)
            .message_encoding("json")
            .schema(Schema::new(
                "sar_view.Status",
                "jsonschema",
                STATUS_SCHEMA.as_bytes(),
            ))
            .context(ctx)
            .build_raw()
            .map_err(|e| format!("cannot create the channel {STATUS_TOPIC}: {e}"))?;
        Ok(Self {
            records,
            scene,
            tf,
            tf_static,
            scene_status,
            status,
            geometry: opts.geometry,
            scene_period_ns: (1e9 / opts.scene_hz) as u64,
            next_scene_ns: 0,
            previous: None,
            lost: 0,
            messages: Vec::with_capacity(8),
            buf: Vec::with_capacity(512),
        })
    }
}

/// Starts the Foxglove server of `ctx` on loopback and the relay on
/// `opts.bind` in front of it; prints the served URL.
fn serve(
    ctx: &Arc<Context>,
    opts: &ViewOptions,
) -> Result<foxglove::WebSocketServerHandle, String> {
    let server = WebSocketServer::new()
        .name(format!("sarctl view ({})", opts.prefix))
        // On loopback: clients connect to the relay.
        .bind("127.0.0.1", 0)
        .message_backlog_size(BACKLOG)
        .context(ctx)
        .start_blocking()
        .map_err(|e| format!("cannot start the Foxglove server: {e}"))?;
    let backend = SocketAddr::from(([127, 0, 0, 1], server.port()));
    let served = front::start(opts.bind, backend)
        .map_err(|e| format!("cannot serve on {}: {e}", opts.bind))?;
    println!(
        "sarctl view: serving ws://{served} (daemon prefix {:?}); open it in Foxglove",
        opts.prefix
    );
    use std::io::Write;
    let _ = std::io::stdout().flush();
    Ok(server)
}

/// Publishes each state of `sub` until `stop()`; a daemon silent for
/// [`IDLE`] is said on stderr and subscribed to again (a restarted daemon
/// has new services).
fn follow(
    client: &Client,
    mut sub: StateSubscription,
    mut publisher: Publisher,
    stop: impl Fn() -> bool,
) {
    let mut last = Instant::now();
    let mut waiting = false;
    while !stop() {
        let n = sub.wait(Duration::from_millis(100), |s| publisher.on_state(s));
        if n > 0 {
            last = Instant::now();
            if waiting {
                eprintln!("sarctl view: the daemon publishes again");
                waiting = false;
            }
        } else if last.elapsed() > IDLE {
            if !waiting {
                eprintln!("sarctl view: the daemon stopped publishing; waiting for it");
                waiting = true;
            }
            // A restarted daemon has new services: subscribe again.
            if let Ok(s) = client.subscribe() {
                sub = s;
                publisher.previous = None;
            }
            last = Instant::now();
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::*;

    #[test]
    fn the_status_names_the_six_limits_as_its_schema_does() {
        let state = StateMsg {
            limits_n: [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            ..StateMsg::default()
        };
        let status = status_json(&state, 0);
        let schema: serde_json::Value = serde_json::from_str(STATUS_SCHEMA).unwrap();
        let properties = schema["properties"].as_object().unwrap();
        let fields = status.as_object().unwrap();
        // The status has exactly the schema's fields.
        let mut a: Vec<&String> = fields.keys().collect();
        let mut b: Vec<&String> = properties.keys().collect();
        a.sort();
        b.sort();
        assert_eq!(a, b);
        for (i, name) in ForceLimits::NAMES.iter().enumerate() {
            assert_eq!(fields[*name], serde_json::json!(i as f64 + 1.0), "{name}");
            assert_eq!(properties[*name]["type"], "number", "{name}");
        }
    }
}
