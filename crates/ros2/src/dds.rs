//! The DDS side (RustDDS): one participant on the configured domain and
//! local addresses, one writer per published topic with its ROS 2 name,
//! type and QoS ([`crate::topics`]). Messages go out as they are encoded:
//! the CDR of the recordings, whose 4-byte encapsulation header RustDDS
//! writes itself (little-endian CDR, `00 01 00 00`).
//!
//! No write waits: best-effort writers never do, and the reliable ones are
//! created with a zero blocking time and a bounded window
//! ([`RELIABLE_WINDOW`]): a full window (a reliable subscriber that stopped
//! acknowledging) drops the message and counts it ([`WriterCounts`]).

use crate::names::{NameError, dds_topic, dds_type};
use crate::topics::{ALL, Published, Qos};
use bytes::Bytes;
use rustdds::dds::adapters::no_key::SerializerAdapter;
use rustdds::no_key::DataWriter;
use rustdds::policy::{Durability, History, Reliability, ResourceLimits};
use rustdds::{
    DomainParticipant, DomainParticipantBuilder, QosPolicies, QosPolicyBuilder,
    RepresentationIdentifier, TopicKind,
};
use std::net::IpAddr;

/// Unacknowledged messages a reliable writer keeps for its slowest
/// subscriber at most; beyond, a write fails at once (counted).
pub const RELIABLE_WINDOW: i32 = 256;

/// Why the DDS side could not start.
#[derive(Debug, thiserror::Error)]
pub enum DdsError {
    /// A name that is not ROS 2's (a bug).
    #[error(transparent)]
    Name(#[from] NameError),
    /// RustDDS refused to create the participant (no usable interface, the
    /// domain's ports taken, ...).
    #[error("cannot join DDS domain {domain_id}: {detail}")]
    Participant {
        /// The domain.
        domain_id: u16,
        /// RustDDS's reason.
        detail: String,
    },
    /// RustDDS refused a topic, publisher or writer.
    #[error("cannot create the DDS writer of {topic}: {detail}")]
    Writer {
        /// The ROS 2 topic.
        topic: &'static str,
        /// RustDDS's reason.
        detail: String,
    },
    /// An encoded message without the little-endian CDR header.
    #[error("a message of {topic} is not little-endian CDR")]
    NotCdr {
        /// The ROS 2 topic.
        topic: &'static str,
    },
}

/// The recordings' CDR as RustDDS's payload: the bytes after the
/// encapsulation header, which RustDDS writes (CDR little-endian).
struct Cdr;

/// Never fails (the bytes are already encoded).
#[derive(Debug, thiserror::Error)]
#[error("unreachable")]
pub struct NoError;

impl SerializerAdapter<Bytes> for Cdr {
    type Error = NoError;
    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }
    fn to_bytes(value: &Bytes) -> Result<Bytes, NoError> {
        Ok(value.clone())
    }
}

/// RustDDS's QoS of a topic's [`Qos`].
pub fn qos_policies(qos: Qos) -> QosPolicies {
    let reliability = if qos.reliable() {
        Reliability::Reliable {
            max_blocking_time: rustdds::Duration::ZERO,
        }
    } else {
        Reliability::BestEffort
    };
    let durability = if qos.transient_local() {
        Durability::TransientLocal
    } else {
        Durability::Volatile
    };
    let mut b = QosPolicyBuilder::new()
        .reliability(reliability)
        .durability(durability)
        .history(History::KeepLast { depth: qos.depth() });
    if qos.reliable() {
        b = b.resource_limits(ResourceLimits {
            max_samples: RELIABLE_WINDOW.max(qos.depth()),
            max_instances: 1,
            max_samples_per_instance: RELIABLE_WINDOW.max(qos.depth()),
        });
    }
    b.build()
}

/// What one writer did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WriterCounts {
    /// Messages handed to DDS.
    pub written: u64,
    /// Messages DDS refused (a reliable window full): lost for every
    /// subscriber of the topic.
    pub refused: u64,
}

/// The participant and its writers.
pub struct Dds {
    participant: DomainParticipant,
    writers: Vec<DataWriter<Bytes, Cdr>>,
    counts: Vec<WriterCounts>,
}

impl std::fmt::Debug for Dds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Dds")
            .field("domain_id", &self.participant.domain_id())
            .field("counts", &self.counts)
            .finish()
    }
}

impl Dds {
    /// Joins `domain_id` on `interfaces` (their addresses; `None`: every
    /// interface) and creates a writer for every topic of [`ALL`].
    pub fn new(domain_id: u16, interfaces: Option<&[IpAddr]>) -> Result<Self, DdsError> {
        let mut builder = DomainParticipantBuilder::new(domain_id);
        if let Some(addrs) = interfaces {
            builder = builder.with_only_networks(addrs.iter().copied());
        }
        let participant = builder.build().map_err(|e| DdsError::Participant {
            domain_id,
            detail: e.to_string(),
        })?;
        let mut writers = Vec::with_capacity(ALL.len());
        for topic in ALL {
            writers.push(writer(&participant, topic)?);
        }
        Ok(Self {
            participant,
            counts: vec![WriterCounts::default(); writers.len()],
            writers,
        })
    }

    /// The domain joined.
    pub fn domain_id(&self) -> u16 {
        self.participant.domain_id()
    }

    /// Publishes one encoded message (CDR with its encapsulation header) on
    /// `topic`. Never waits; a refusal is counted.
    pub fn write(&mut self, topic: Published, cdr: &[u8]) -> Result<(), DdsError> {
        let body = match cdr {
            [0, 1, 0, 0, body @ ..] => body,
            _ => {
                return Err(DdsError::NotCdr {
                    topic: topic.name(),
                });
            }
        };
        let i = topic.index();
        let (Some(writer), Some(counts)) = (self.writers.get(i), self.counts.get_mut(i)) else {
            return Ok(());
        };
        match writer.write(Bytes::copy_from_slice(body), None) {
            Ok(()) => counts.written += 1,
            Err(_) => counts.refused += 1,
        }
        Ok(())
    }

    /// Each topic's counts, in [`ALL`]'s order.
    pub fn counts(&self) -> impl Iterator<Item = (Published, WriterCounts)> + '_ {
        ALL.iter().copied().zip(self.counts.iter().copied())
    }
}

/// The writer of one topic: its DDS topic (`rt/...`), type
/// (`pkg::msg::dds_::Type_`) and QoS.
fn writer(
    participant: &DomainParticipant,
    topic: Published,
) -> Result<DataWriter<Bytes, Cdr>, DdsError> {
    let qos = qos_policies(topic.qos());
    let err = |e: &dyn std::fmt::Display| DdsError::Writer {
        topic: topic.name(),
        detail: e.to_string(),
    };
    let dds = participant
        .create_topic(
            dds_topic(topic.name())?,
            dds_type(topic.type_name())?,
            &qos,
            TopicKind::NoKey,
        )
        .map_err(|e| err(&e))?;
    let publisher = participant.create_publisher(&qos).map_err(|e| err(&e))?;
    publisher
        .create_datawriter_no_key::<Bytes, Cdr>(&dds, Some(qos))
        .map_err(|e| err(&e))
}
