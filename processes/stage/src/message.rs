//! Messages as stages see them: borrowed for a call ([`Message`]), owned while a driver
//! queues them ([`OwnedMessage`]).

use ipc_types::msg::Header;
use ipc_types::topics::Payload;

/// Writes [`Message`], [`OwnedMessage`], [`SliceHeader`] and their conversions from the
/// payload list ([`ipc_types::for_each_payload!`]): one variant per payload kind, so a
/// new kind needs no line here.
macro_rules! messages {
    (
        structs: [$($(#[$sd:meta])* $s:ident($st:ty => $so:ty) = $sn:literal,)*],
        truth: [$($(#[$td:meta])* $t:ident($tt:ty => $to:ty) = $tn:literal,)*],
        slices: [$($(#[$cd:meta])* $c:ident($ch:ty, [$ce:ty]) = $cn:literal,)*],
        local: [$($(#[$ld:meta])* $l:ident($lt:ty) = $ln:literal,)*],
        bytes: [$($(#[$bd:meta])* $b:ident = $bn:literal,)*],
    ) => {
        /// One message of any topic, borrowed.
        #[derive(Debug, Clone, Copy)]
        pub enum Message<'a> {
            $($(#[$sd])* $s(&'a $st),)*
            $($(#[$td])* $t(&'a $tt),)*
            $($(#[$cd])* $c(&'a $ch, &'a [$ce]),)*
            $($(#[$ld])* $l(&'a $lt),)*
            $($(#[$bd])* $b(&'a [u8]),)*
        }

        impl Message<'_> {
            /// The payload kind, to check it against the topic's.
            pub fn payload(&self) -> Payload {
                match self {
                    $(Self::$s(..) => Payload::$s,)*
                    $(Self::$t(..) => Payload::$t,)*
                    $(Self::$c(..) => Payload::$c,)*
                    $(Self::$l(..) => Payload::$l,)*
                    $(Self::$b(..) => Payload::$b,)*
                }
            }

            /// The message's header (`None` for MAVLink bytes).
            pub fn header(&self) -> Option<&Header> {
                Some(match self {
                    $(Self::$s(m) => &m.msg,)*
                    $(Self::$t(m) => &m.msg,)*
                    $(Self::$c(h, _) => &h.msg,)*
                    $(Self::$l(m) => &m.msg,)*
                    $(Self::$b(..) => return None,)*
                })
            }

            /// An owned copy, for a queue.
            pub fn to_owned(&self) -> OwnedMessage {
                match *self {
                    $(Self::$s(m) => OwnedMessage::$s((*m).into()),)*
                    $(Self::$t(m) => OwnedMessage::$t((*m).into()),)*
                    $(Self::$c(h, p) => OwnedMessage::$c(*h, p.to_vec()),)*
                    $(Self::$l(m) => OwnedMessage::$l(*m),)*
                    $(Self::$b(b) => OwnedMessage::$b(b.to_vec()),)*
                }
            }
        }

        /// One message of any topic, owned (a driver's queue, a recording, a test). Small
        /// messages stay inline: a queue holds them behind an `Rc` anyway; the large ones
        /// are boxed, as the payload list says.
        #[allow(clippy::large_enum_variant)]
        #[derive(Debug, Clone, PartialEq)]
        pub enum OwnedMessage {
            $($(#[$sd])* $s($so),)*
            $($(#[$td])* $t($to),)*
            $($(#[$cd])* $c($ch, Vec<$ce>),)*
            $($(#[$ld])* $l($lt),)*
            $($(#[$bd])* $b(Vec<u8>),)*
        }

        impl OwnedMessage {
            /// Borrowed, for a stage call.
            pub fn as_message(&self) -> Message<'_> {
                match self {
                    $(Self::$s(m) => Message::$s(m),)*
                    $(Self::$t(m) => Message::$t(m),)*
                    $(Self::$c(h, p) => Message::$c(h, p),)*
                    $(Self::$l(m) => Message::$l(m),)*
                    $(Self::$b(b) => Message::$b(b),)*
                }
            }

            /// The header, to stamp a stage's exit (`None` for MAVLink bytes).
            pub fn header_mut(&mut self) -> Option<&mut Header> {
                Some(match self {
                    $(Self::$s(m) => &mut m.msg,)*
                    $(Self::$t(m) => &mut m.msg,)*
                    $(Self::$c(h, _) => &mut h.msg,)*
                    $(Self::$l(m) => &mut m.msg,)*
                    $(Self::$b(..) => return None,)*
                })
            }
        }

        /// The header a stage returns for a slice it filled.
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub enum SliceHeader {
            $($(#[$cd])* $c($ch),)*
        }

        impl SliceHeader {
            /// The payload kind.
            pub fn payload(&self) -> Payload {
                match self {
                    $(Self::$c(_) => Payload::$c,)*
                }
            }

            /// The header of the message.
            pub fn header(&self) -> &Header {
                match self {
                    $(Self::$c(h) => &h.msg,)*
                }
            }
        }
    };
}
ipc_types::for_each_payload!(messages);

/// The output buffer [`crate::Outbox::publish_slice`] lends a stage.
#[derive(Debug)]
pub enum SliceMut<'a> {
    /// Pixels or cells.
    U8(&'a mut [u8]),
    /// Depths.
    U16(&'a mut [u16]),
}

/// The driver lends a stage its loaned sample's pixels or cells as they come.
impl<'a> From<&'a mut [u8]> for SliceMut<'a> {
    fn from(s: &'a mut [u8]) -> Self {
        Self::U8(s)
    }
}

/// The driver lends a stage its loaned sample's depths as they come.
impl<'a> From<&'a mut [u16]> for SliceMut<'a> {
    fn from(s: &'a mut [u16]) -> Self {
        Self::U16(s)
    }
}
