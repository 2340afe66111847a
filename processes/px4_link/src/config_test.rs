#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;

fn with_link(link: &str) -> Px4LinkConfig {
    Px4LinkConfig {
        link: link.into(),
        ..Px4LinkConfig::default()
    }
}

#[test]
fn a_serial_link_names_its_device_and_baud_rate() {
    assert_eq!(
        with_link("serial:/dev/ttyTHS1:921600").address().unwrap(),
        LinkAddress::Serial {
            path: "/dev/ttyTHS1".into(),
            baud: 921_600
        }
    );
}

#[test]
fn a_serial_link_with_a_nonstandard_baud_rate_is_refused_naming_the_allowed_ones() {
    let e = with_link("serial:/dev/ttyTHS1:12345")
        .validate()
        .unwrap_err();
    assert_eq!(e.key, "link");
    assert!(e.message.contains("12345"), "{}", e.message);
    assert!(e.message.contains("921600"), "{}", e.message);
}

#[test]
fn a_serial_link_without_an_absolute_device_or_a_baud_is_refused() {
    for bad in [
        "serial:ttyS0:57600",
        "serial:/dev/ttyS0",
        "serial:",
        "tcp:1.2.3.4:5",
    ] {
        let e = with_link(bad).validate().unwrap_err();
        assert!(e.message.contains("allowed"), "{bad}: {}", e.message);
    }
}

#[test]
fn a_udp_link_still_parses() {
    assert!(matches!(
        with_link("udp:127.0.0.1:14540").address().unwrap(),
        LinkAddress::Udp(_)
    ));
}
