use super::*;

#[test]
fn the_live_view_listens_on_loopback_unless_the_config_says_otherwise() {
    let cfg = RecorderConfig::default();
    assert!(!cfg.live);
    assert!(cfg.live_socket().unwrap().ip().is_loopback());
    let shipped: toml::Table =
        toml::from_str(include_str!("../../../deploy/config/landing.toml")).unwrap();
    let shipped: RecorderConfig = shipped["recorder"].clone().try_into().unwrap();
    assert!(!shipped.live);
    assert!(shipped.live_socket().unwrap().ip().is_loopback());
}

#[test]
fn a_live_address_that_is_not_ip_and_port_names_the_key_and_what_is_allowed() {
    for bad in ["localhost:8765", "127.0.0.1", "8765", ""] {
        let cfg = RecorderConfig {
            live_address: bad.into(),
            ..RecorderConfig::default()
        };
        let e = cfg.validate().unwrap_err();
        assert_eq!(e.key, "live_address");
        assert!(e.message.contains("IP:PORT"), "{}", e.message);
    }
}
