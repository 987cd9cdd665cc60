//! The reader as iterators: raw messages, every SAR topic decoded, one
//! message type.

use super::McapReader;
use super::error::ReadError;
use super::info::{ChannelInfo, RawMessage};
use sar_msgs::msgs::{Outgoing, RosMessage, Topic};

impl<'a> McapReader<'a> {
    /// Every message of the SAR topics ([`Topic`]) decoded, with its topic and
    /// log time; other topics are skipped, and so are the snapshots
    /// (`/sar/cycle/snapshot`, variable length: decode the raw message with
    /// [`sar_msgs::msgs::StateSnapshot`]).
    pub fn decoded(self) -> impl Iterator<Item = Result<(Topic, u64, Outgoing), ReadError>> + 'a {
        self.picked(|channel, msg| {
            let Some(topic) = Topic::from_name(&channel.topic) else {
                return Pick::Skip;
            };
            if matches!(topic, Topic::StateSnapshot | Topic::CycleBatch) {
                return Pick::Skip;
            }
            if channel.schema_name() != topic.type_name() {
                return Pick::Fail(ReadError::WrongType {
                    topic: channel.topic.clone(),
                    expected: topic.type_name(),
                    found: channel.schema_name().to_owned(),
                });
            }
            Pick::Give(
                Outgoing::decode(topic, &msg.data)
                    .map(|m| (topic, msg.log_time_ns, m))
                    .map_err(|source| ReadError::Decode {
                        topic: channel.topic.clone(),
                        log_time_ns: msg.log_time_ns,
                        source,
                    }),
            )
        })
    }

    /// The messages of `topic` decoded as `M` (the topic's schema must be
    /// `M::TYPE_NAME`), with their log times. Other topics are skipped.
    pub fn typed<M: RosMessage + 'a>(
        self,
        topic: &'a str,
    ) -> impl Iterator<Item = Result<(u64, M), ReadError>> + 'a {
        let mut checked: Option<u16> = None;
        self.picked(move |channel, msg| {
            if channel.topic != topic {
                return Pick::Skip;
            }
            if checked != Some(msg.channel_id) {
                if channel.schema_name() != M::TYPE_NAME {
                    return Pick::Fail(ReadError::WrongType {
                        topic: topic.to_owned(),
                        expected: M::TYPE_NAME,
                        found: channel.schema_name().to_owned(),
                    });
                }
                checked = Some(msg.channel_id);
            }
            Pick::Give(
                M::decode(&msg.data)
                    .map(|m| (msg.log_time_ns, m))
                    .map_err(|source| ReadError::Decode {
                        topic: topic.to_owned(),
                        log_time_ns: msg.log_time_ns,
                        source,
                    }),
            )
        })
    }

    /// Every message with its channel handed to `pick`, which skips it,
    /// gives an item, or fails; a failure, as a read error, is the last
    /// item.
    pub(super) fn picked<T: 'a>(
        self,
        mut pick: impl FnMut(&ChannelInfo, &RawMessage) -> Pick<T> + 'a,
    ) -> impl Iterator<Item = Result<T, ReadError>> + 'a {
        let mut reader = self;
        let mut failed = false;
        std::iter::from_fn(move || {
            if failed {
                return None;
            }
            loop {
                let msg = match reader.next()? {
                    Ok(m) => m,
                    Err(e) => {
                        failed = true;
                        return Some(Err(e));
                    }
                };
                let channel = reader.channels.get(&msg.channel_id)?;
                match pick(channel, &msg) {
                    Pick::Skip => {}
                    Pick::Give(item) => return Some(item),
                    Pick::Fail(e) => {
                        failed = true;
                        return Some(Err(e));
                    }
                }
            }
        })
    }
}

/// What [`McapReader::picked`]'s choice makes of a message.
pub(super) enum Pick<T> {
    /// Not wanted: the next one.
    Skip,
    /// An item (one that cannot be decoded is an error item, and the
    /// iteration goes on).
    Give(Result<T, ReadError>),
    /// An error that ends the iteration.
    Fail(ReadError),
}

impl Iterator for McapReader<'_> {
    type Item = Result<RawMessage, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Some(Ok(m));
            }
            if self.done {
                return None;
            }
            let stepped = self.step();
            if let Some(e) = self.after_step(stepped) {
                return Some(Err(e));
            }
        }
    }
}
