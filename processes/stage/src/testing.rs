//! A collecting [`Outbox`] for tests, replays and tools that call a stage by hand: every
//! output kept in order with its topic, slices included, types checked against the
//! topic table as the drivers check them.

use ipc_types::topics;

use crate::{Message, Outbox, OwnedMessage, SliceHeader, SliceMut, StageError};

/// Everything a stage published, oldest first.
#[derive(Debug, Default)]
pub struct Collector {
    /// `(topic, message)` in publishing order.
    pub published: Vec<(String, OwnedMessage)>,
}

impl Collector {
    /// An empty collector.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes what was published so far.
    pub fn take(&mut self) -> Vec<(String, OwnedMessage)> {
        std::mem::take(&mut self.published)
    }

    /// The messages published on `topic`, oldest first.
    pub fn on<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a OwnedMessage> + 'a {
        self.published
            .iter()
            .filter(move |(t, _)| t == topic)
            .map(|(_, m)| m)
    }
}

fn check(topic: &str, msg: &Message<'_>) -> Result<(), StageError> {
    match topics::find(topic) {
        Some(info) if info.payload != msg.payload() => Err(StageError::WrongType {
            topic: topic.to_string(),
            expected: info.payload.type_name(),
            got: msg.payload().type_name(),
        }),
        _ => Ok(()),
    }
}

impl Outbox for Collector {
    fn publish(&mut self, topic: &str, msg: Message<'_>) -> Result<(), StageError> {
        check(topic, &msg)?;
        self.published.push((topic.to_string(), msg.to_owned()));
        Ok(())
    }

    fn publish_slice(
        &mut self,
        topic: &str,
        len: usize,
        fill: &mut dyn FnMut(SliceMut<'_>) -> Option<SliceHeader>,
    ) -> Result<bool, StageError> {
        let depth = topics::find(topic).map(|t| t.payload) == Some(topics::Payload::DepthFrame);
        let (mut bytes, mut depths) = if depth {
            (Vec::new(), vec![0u16; len])
        } else {
            (vec![0u8; len], Vec::new())
        };
        let header = if depth {
            fill(SliceMut::U16(&mut depths))
        } else {
            fill(SliceMut::U8(&mut bytes))
        };
        let msg = match header {
            None => return Ok(false),
            Some(SliceHeader::CameraFrame(h)) => OwnedMessage::CameraFrame(h, bytes),
            Some(SliceHeader::OccupancyMap(h)) => OwnedMessage::OccupancyMap(h, bytes),
            Some(SliceHeader::DepthFrame(h)) => OwnedMessage::DepthFrame(h, depths),
        };
        check(topic, &msg.as_message())?;
        self.published.push((topic.to_string(), msg));
        Ok(true)
    }
}
