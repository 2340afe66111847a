//! Tests of the payload list.

use iceoryx2::prelude::ZeroCopySend;

use crate::topics::Payload;

/// Every struct of the list with the name the list gives it.
macro_rules! named_types {
    (
        structs: [$($(#[$sd:meta])* $s:ident($st:ty => $so:ty) = $sn:literal,)*],
        truth: [$($(#[$td:meta])* $t:ident($tt:ty => $to:ty) = $tn:literal,)*],
        slices: [$($(#[$cd:meta])* $c:ident($ch:ty, [$ce:ty]) = $cn:literal,)*],
        local: [$($(#[$ld:meta])* $l:ident($lt:ty) = $ln:literal,)*],
        bytes: [$($(#[$bd:meta])* $b:ident = $bn:literal,)*],
    ) => {
        /// (list name, the type's own `#[type_name]`, the payload kind).
        fn named() -> Vec<(&'static str, &'static str, Payload)> {
            // SAFETY: `type_name` only returns the name the derive wrote; no layout is
            // relied on.
            unsafe {
                vec![
                    $(($sn, <$st as ZeroCopySend>::type_name(), Payload::$s),)*
                    $(($tn, <$tt as ZeroCopySend>::type_name(), Payload::$t),)*
                    $(($cn, <$ch as ZeroCopySend>::type_name(), Payload::$c),)*
                    $(($ln, <$lt as ZeroCopySend>::type_name(), Payload::$l),)*
                ]
            }
        }
    };
}
crate::for_each_payload!(named_types);

#[test]
fn the_list_names_each_payload_by_its_types_own_versioned_type_name() {
    let named = named();
    assert_eq!(
        named.len() + 1,
        Payload::ALL.len(),
        "every kind but MAVLink"
    );
    for (listed, own, payload) in named {
        assert_eq!(listed, own, "{payload:?}");
        assert_eq!(payload.type_name(), own);
    }
}

#[test]
fn every_payload_kind_is_listed_once_and_named_apart() {
    let mut names: Vec<&str> = Payload::ALL.iter().map(|p| p.type_name()).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), Payload::ALL.len());
    assert_eq!(Payload::Mavlink.type_name(), "MAVLink 2");
    assert_eq!(Payload::DepthFrame.elements(), Some("u16"));
    assert_eq!(Payload::OccupancyMap.elements(), Some("u8"));
    assert_eq!(Payload::VehicleState.elements(), None);
}

#[test]
fn every_topic_carries_a_listed_payload() {
    for t in crate::topics::TABLE {
        assert!(Payload::ALL.contains(&t.payload), "{}", t.name);
    }
}
