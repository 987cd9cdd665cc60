//! What the reader gives of a recording: its schemas and channels, and its
//! messages (owned, [`RawMessage`], or borrowed, [`MessageRef`], with the
//! [`Visitor`] that takes them).

use std::collections::BTreeMap;
use std::sync::Arc;

/// A schema of the recording, shared by every channel that names it (one
/// copy, however many channels: a schema of 2 MiB named by 4000 channels
/// is 2 MiB, not 8 GB).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SchemaInfo {
    /// Schema name (the ROS 2 type).
    pub name: String,
    /// Schema encoding (`ros2msg`).
    pub encoding: String,
    /// Schema text.
    pub data: Vec<u8>,
}

/// A channel of the recording with its schema.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// Channel id.
    pub id: u16,
    /// Topic.
    pub topic: String,
    /// Message encoding (`cdr`).
    pub message_encoding: String,
    /// Schema id (0: none).
    pub schema_id: u16,
    /// The schema (`None`: no schema, or one not defined before the
    /// channel), shared with the reader and the other channels.
    pub schema: Option<Arc<SchemaInfo>>,
    /// Channel metadata.
    pub metadata: BTreeMap<String, String>,
}

impl ChannelInfo {
    /// Schema name (the ROS 2 type), empty without schema.
    pub fn schema_name(&self) -> &str {
        self.schema.as_deref().map_or("", |s| s.name.as_str())
    }
    /// Schema encoding (`ros2msg`), empty without schema.
    pub fn schema_encoding(&self) -> &str {
        self.schema.as_deref().map_or("", |s| s.encoding.as_str())
    }
    /// Schema text, empty without schema.
    pub fn schema_data(&self) -> &[u8] {
        self.schema.as_deref().map_or(&[], |s| s.data.as_slice())
    }
}

/// One message as recorded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawMessage {
    /// Channel id.
    pub channel_id: u16,
    /// Sequence number.
    pub sequence: u32,
    /// Log time, ns.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// The CDR bytes.
    pub data: Vec<u8>,
}

/// One message as recorded, borrowed from the reader's current chunk (see
/// [`McapReader::visit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageRef<'m> {
    /// Channel id.
    pub channel_id: u16,
    /// Sequence number.
    pub sequence: u32,
    /// Log time, ns.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// The CDR bytes.
    pub data: &'m [u8],
}

impl MessageRef<'_> {
    /// An owned copy.
    pub fn to_owned_message(&self) -> RawMessage {
        RawMessage {
            channel_id: self.channel_id,
            sequence: self.sequence,
            log_time_ns: self.log_time_ns,
            publish_time_ns: self.publish_time_ns,
            data: self.data.to_vec(),
        }
    }
}

/// The callback of [`McapReader::visit`] as a trait object: the channels
/// known so far and one message. (`visit` takes any such closure; a concrete
/// one is inlined into the record loop, the hot path of a replay.)
pub type Visitor<'v, E> =
    dyn FnMut(&BTreeMap<u16, ChannelInfo>, MessageRef<'_>) -> Result<(), E> + 'v;

/// The bound of the record loop's callback: any closure of the [`Visitor`]
/// shape, or a [`Visitor`] itself.
pub(super) trait OnMessage<E>:
    FnMut(&BTreeMap<u16, ChannelInfo>, MessageRef<'_>) -> Result<(), E>
{
}

impl<E, F> OnMessage<E> for F where
    F: FnMut(&BTreeMap<u16, ChannelInfo>, MessageRef<'_>) -> Result<(), E> + ?Sized
{
}
