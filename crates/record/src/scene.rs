//! The 3D scene inside every recording file ([`crate::file`]): `/sar/scene`
//! (`visualization_msgs/msg/MarkerArray`), `/tf` and `/tf_static`
//! (`tf2_msgs/msg/TFMessage`), CDR like every other channel, drawn by
//! `sar_scene::draw` from the recorded messages of one cycle, decimated to
//! `[record] scene_hz`, on the writer's thread (never the loop's).
//! `/tf_static` is written once at the start of every file (durability
//! `transient_local`, as ROS 2's recorder writes it), so each file opens
//! alone with its frames.

use sar_msgs::cdr::CdrError;
use sar_msgs::msgs::{ActiveJointState, EstimatorState, Outgoing, PassiveJointState, RosMessage};
use sar_msgs::viz::MarkerArray;
use sar_scene::draw;
use sar_scene::geometry::SceneGeometry;

/// The 3D scene written into the recordings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneOptions {
    /// The robot and manipulator as drawn (from the configuration).
    pub geometry: SceneGeometry,
    /// The force limits drawn until a cycle records others (warn, stop of
    /// total, axial, lateral), N.
    pub limits_n: [f64; 6],
    /// At most one scene per this much log time, ns (33 333 333: 30 Hz).
    pub period_ns: u64,
}

impl SceneOptions {
    /// The scene the configuration asks for (`[record] scene_hz`), drawn
    /// from its geometry and limits; `None` when it asks for none
    /// (`scene_hz = 0`).
    pub fn from_config(config: &sar_config::Config) -> Option<Self> {
        let period_ns = config.record.scene_period_ns?;
        Some(Self {
            geometry: SceneGeometry::from_config(&config.estimator),
            limits_n: config.estimator.guard.force_limits().to_array(),
            period_ns,
        })
    }
}

/// One cycle's messages as the scene needs them.
#[derive(Debug, Clone, Copy)]
struct SceneCycle {
    stamp_ns: u64,
    estimator: Option<EstimatorState>,
    passive: Option<PassiveJointState>,
}

/// What the scene is drawn from: the messages of one cycle (all stamped
/// with the cycle's `now`), gathered until a message of a later cycle (or
/// the file's end) closes it, whatever their order.
pub(crate) struct SceneState {
    options: SceneOptions,
    next_ns: Option<u64>,
    cycle: Option<SceneCycle>,
    /// The limits in use (the last `/sar/cycle/input`'s).
    limits_n: [f64; 6],
    /// The last joints (`/sar/cycle/input` or `/sar/joints`).
    q_m: [f64; 3],
    markers: Box<MarkerArray>,
    buf: Vec<u8>,
    tf_buf: Vec<u8>,
    sequence: u32,
}

/// Why a scene message could not be encoded, and on which topic.
pub(crate) type SceneEncodeError = (&'static str, CdrError);

fn encoded<'b, M: RosMessage>(
    m: &M,
    buf: &'b mut Vec<u8>,
    topic: &'static str,
) -> Result<&'b [u8], SceneEncodeError> {
    m.encode(buf).map_err(|e| (topic, e))?;
    Ok(buf)
}

/// One cycle's scene, encoded: its log time, sequence number, and the
/// `/sar/scene` and `/tf` messages.
pub(crate) struct Drawn<'a> {
    pub(crate) log_ns: u64,
    pub(crate) sequence: u32,
    pub(crate) markers: &'a [u8],
    pub(crate) tf: &'a [u8],
}

impl SceneState {
    pub(crate) fn new(options: SceneOptions) -> Self {
        Self {
            options,
            next_ns: None,
            cycle: None,
            limits_n: options.limits_n,
            q_m: [0.0; 3],
            markers: Box::default(),
            buf: Vec::with_capacity(8192),
            tf_buf: Vec::with_capacity(256),
            sequence: 0,
        }
    }

    /// Whether `stamp_ns` closes the cycle gathered (a later cycle's).
    pub(crate) fn closes(&self, stamp_ns: u64) -> bool {
        self.cycle.is_some_and(|c| c.stamp_ns != stamp_ns)
    }

    /// Gathers `msg` into its cycle.
    pub(crate) fn follow(&mut self, msg: &Outgoing) {
        let stamp_ns = msg.stamp_ns();
        let cycle = self.cycle.get_or_insert(SceneCycle {
            stamp_ns,
            estimator: None,
            passive: None,
        });
        match msg {
            Outgoing::EstimatorState(e) => cycle.estimator = Some(*e),
            Outgoing::PassiveJoints(p) => cycle.passive = Some(*p),
            Outgoing::CycleInput(c) => {
                if c.limits_in_use_n.iter().all(|v| v.is_finite() && *v > 0.0) {
                    self.limits_n = c.limits_in_use_n;
                }
                self.q_m = c.joints_q_m;
            }
            Outgoing::Joints(j) => self.q_m = j.q_m,
            _ => {}
        }
    }

    /// `/tf_static` at `log_ns`, the start of a file, encoded.
    pub(crate) fn static_message(&mut self, log_ns: u64) -> Result<&[u8], SceneEncodeError> {
        let tf = draw::static_transforms(log_ns);
        encoded(&tf, &mut self.buf, sar_scene::TF_STATIC_TOPIC)
    }

    /// Closes the cycle gathered: its scene and moving frames drawn and
    /// encoded when one is due (at most one per period of log time,
    /// keeping the phase), else `None`.
    pub(crate) fn flush(&mut self) -> Result<Option<Drawn<'_>>, SceneEncodeError> {
        let Some(SceneCycle {
            stamp_ns: log_ns,
            estimator: Some(estimator),
            passive,
        }) = self.cycle.take()
        else {
            return Ok(None);
        };
        if self.next_ns.is_some_and(|next| log_ns < next) {
            return Ok(None);
        }
        let period = self.options.period_ns.max(1);
        self.next_ns = Some(match self.next_ns {
            Some(next) => next + (log_ns - next) / period * period + period,
            None => log_ns + period,
        });
        let joints = ActiveJointState {
            stamp_ns: estimator.joints_stamp_ns,
            q_m: self.q_m,
        };
        let state = sar_scene::topics::state_from_recorded(
            &estimator,
            &joints,
            passive.as_ref(),
            self.limits_n,
        );
        let g = self.options.geometry;
        draw::scene(&state, &g, &mut self.markers);
        let sequence = self.sequence;
        self.sequence = sequence.wrapping_add(1);
        let tf = draw::moving_transforms(&state, &g);
        encoded(&tf, &mut self.tf_buf, sar_scene::TF_TOPIC)?;
        encoded(&*self.markers, &mut self.buf, sar_scene::SCENE_TOPIC)?;
        Ok(Some(Drawn {
            log_ns,
            sequence,
            markers: &self.buf,
            tf: &self.tf_buf,
        }))
    }
}
