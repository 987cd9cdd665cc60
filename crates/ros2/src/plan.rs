//! What the bridge publishes of each state, as encoded CDR messages, without
//! DDS (so that it is tested alone): the recording's messages of the cycle
//! (`sar_scene::topics::messages`, decimated per topic by the cycles'
//! stamps), and at the scene's rate the 3D scene drawn as the recorder draws
//! it (`sar_scene::topics::scene_state`, `sar_scene::draw`), `/tf_static`
//! once.

use crate::topics::{Published, rate_of};
use sar_config::{Ros2Settings, TopicRate};
use sar_msgs::cdr::CdrError;
use sar_msgs::msgs::{EstimatorState, Outgoing, RosMessage, Topic};
use sar_msgs::wire::StateMsg;
use sar_scene::draw;
use sar_scene::geometry::SceneGeometry;
use sar_scene::rate::Decimator;
use sar_scene::topics::{self, SceneInput};

/// What the bridge draws and how often.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanOptions {
    /// The robot as drawn.
    pub geometry: SceneGeometry,
    /// The limits drawn until a state carries others, N.
    pub limits_n: [f64; 6],
    /// The per-topic rates and the scene's period.
    pub rates: sar_config::Ros2Rates,
    /// At most one scene per this many ns (`None`: no scene).
    pub scene_period_ns: Option<u64>,
}

impl PlanOptions {
    /// The options of a configuration (`[ros2]`, its geometry and limits).
    pub fn from_config(config: &sar_config::Config) -> Self {
        Self::of(
            &config.ros2,
            SceneGeometry::from_config(&config.estimator),
            config.estimator.guard.force_limits().to_array(),
        )
    }

    /// The options of `[ros2]`'s settings, a geometry and the limits.
    pub fn of(settings: &Ros2Settings, geometry: SceneGeometry, limits_n: [f64; 6]) -> Self {
        Self {
            geometry,
            limits_n,
            rates: settings.rates,
            scene_period_ns: settings.scene_period_ns,
        }
    }
}

/// A topic's decimation: published every time, at most at a rate, or never.
#[derive(Debug, Clone, Copy)]
enum Gate {
    Every,
    Rate(Decimator),
    Off,
}

impl Gate {
    fn of(rate: TopicRate) -> Self {
        match rate {
            TopicRate::Every => Gate::Every,
            TopicRate::PeriodNs(p) => Gate::Rate(Decimator::new(p)),
            TopicRate::Off => Gate::Off,
        }
    }

    fn due(&mut self, stamp_ns: u64) -> bool {
        match self {
            Gate::Every => true,
            Gate::Rate(d) => d.due(stamp_ns),
            Gate::Off => false,
        }
    }

    fn reset(&mut self) {
        if let Gate::Rate(d) = self {
            d.reset();
        }
    }
}

/// The states seen and lost.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PlanCounts {
    /// States received.
    pub states: u64,
    /// States not received: gaps in the cycle numbers (the shared memory's
    /// buffer overflowed: the bridge fell behind, or the daemon's
    /// publishing thread dropped them).
    pub states_lost: u64,
    /// Messages that could not be encoded (none expected).
    pub encode_errors: u64,
}

/// The bridge's state between two states received.
#[derive(Debug)]
pub struct Plan {
    options: PlanOptions,
    gates: Vec<(Topic, Gate)>,
    scene: Option<Decimator>,
    limits_n: [f64; 6],
    tf_static_sent: bool,
    previous: Option<StateMsg>,
    messages: Vec<Outgoing>,
    buf: Vec<u8>,
    counts: PlanCounts,
}

impl Plan {
    /// A plan with nothing published yet.
    pub fn new(options: PlanOptions) -> Self {
        Self {
            options,
            gates: crate::topics::RECORD_TOPICS
                .iter()
                .map(|t| (*t, Gate::of(rate_of(&options.rates, *t))))
                .collect(),
            scene: options.scene_period_ns.map(Decimator::new),
            limits_n: options.limits_n,
            tf_static_sent: false,
            previous: None,
            messages: Vec::with_capacity(32),
            buf: Vec::with_capacity(8192),
            counts: PlanCounts::default(),
        }
    }

    /// The states seen and lost so far.
    pub fn counts(&self) -> PlanCounts {
        self.counts
    }

    /// Starts again (a restarted daemon): no previous state, every rate's
    /// phase forgotten.
    pub fn restart(&mut self) {
        self.previous = None;
        for (_, g) in &mut self.gates {
            g.reset();
        }
        if let Some(d) = &mut self.scene {
            d.reset();
        }
    }

    /// The messages of one state, each handed to `emit` encoded (CDR with
    /// its 4-byte encapsulation header), with the cycle's stamp.
    pub fn on_state(&mut self, s: &StateMsg, mut emit: impl FnMut(Published, u64, &[u8])) {
        self.counts.states += 1;
        if let Some(p) = &self.previous
            && s.cycle > p.cycle.saturating_add(1)
        {
            self.counts.states_lost += s.cycle - p.cycle - 1;
        }
        let stamp_ns = topics::cycle_stamp_ns(s);
        let mut messages = std::mem::take(&mut self.messages);
        topics::messages(s, self.previous.as_ref(), &mut messages);
        for m in &messages {
            let topic = m.topic();
            if self.gate_due(topic, m.stamp_ns()) {
                match m.encode(&mut self.buf) {
                    Ok(()) => emit(Published::Record(topic), stamp_ns, &self.buf),
                    Err(_) => self.counts.encode_errors += 1,
                }
            }
        }
        if topics::valid_limits(&s.limits_n) {
            self.limits_n = s.limits_n;
        }
        if self.scene.as_mut().is_some_and(|d| d.due(stamp_ns)) {
            self.draw(s, stamp_ns, &messages, &mut emit);
        }
        self.messages = messages;
        self.previous = Some(*s);
    }

    fn gate_due(&mut self, topic: Topic, stamp_ns: u64) -> bool {
        self.gates
            .iter_mut()
            .find(|(t, _)| *t == topic)
            .is_some_and(|(_, g)| g.due(stamp_ns))
    }

    /// The scene of the cycle, drawn from its messages as the recorder
    /// draws it; `/tf_static` before the first.
    fn draw(
        &mut self,
        s: &StateMsg,
        stamp_ns: u64,
        messages: &[Outgoing],
        emit: &mut impl FnMut(Published, u64, &[u8]),
    ) {
        let mut estimator: Option<EstimatorState> = None;
        let mut input = SceneInput {
            estimator: EstimatorState::default(),
            passive: None,
            q_m: s.q_m,
            limits_n: self.limits_n,
            truth_n: None,
        };
        for m in messages {
            match m {
                Outgoing::EstimatorState(e) => estimator = Some(*e),
                Outgoing::PassiveJoints(p) => input.passive = Some(*p),
                Outgoing::SimTruth(t) => input.truth_n = Some(t.force_n),
                _ => {}
            }
        }
        let Some(estimator) = estimator else {
            return;
        };
        input.estimator = estimator;
        let state = topics::scene_state(&input);
        let g = self.options.geometry;
        if !self.tf_static_sent {
            self.tf_static_sent = true;
            let frames = draw::static_frames(stamp_ns);
            self.put(Published::TfStatic, stamp_ns, |b| frames.encode(b), emit);
        }
        let markers = draw::scene(&state, &g);
        self.put(Published::Scene, stamp_ns, |b| markers.encode(b), emit);
        let frames = draw::moving_frames(&state, &g);
        self.put(Published::Tf, stamp_ns, |b| frames.encode(b), emit);
        let status = topics::scene_status(&state);
        self.put(Published::SceneStatus, stamp_ns, |b| status.encode(b), emit);
    }

    fn put(
        &mut self,
        topic: Published,
        stamp_ns: u64,
        encode: impl FnOnce(&mut Vec<u8>) -> Result<(), CdrError>,
        emit: &mut impl FnMut(Published, u64, &[u8]),
    ) {
        match encode(&mut self.buf) {
            Ok(()) => emit(topic, stamp_ns, &self.buf),
            Err(_) => self.counts.encode_errors += 1,
        }
    }
}
