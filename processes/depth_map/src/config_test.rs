use super::*;

#[test]
fn the_defaults_are_valid_and_give_valid_map_settings() {
    let c = DepthMapConfig::default();
    c.validate().unwrap();
    c.map_settings().validate().unwrap();
    assert_eq!(c.map_settings(), MapSettings::default());
}

#[test]
fn the_shipped_stack_file_section_is_read_strictly() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/config/landing.toml");
    let (_, c): (_, DepthMapConfig) = stack_config::load_process(&path, "depth_map").unwrap();
    assert_eq!(
        c,
        DepthMapConfig::default(),
        "the shipped file states the defaults"
    );
}

#[test]
fn an_unknown_key_or_an_out_of_range_value_names_the_key() {
    let dir = std::env::temp_dir().join(format!("depth_map_cfg_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("l.toml");
    for (text, key) in [
        ("[depth_map]\nresolution = 0.1\n", "depth_map.resolution"),
        ("[depth_map]\npixel_step = 0\n", "depth_map.pixel_step"),
        ("[depth_map]\ninput = \"v4l2\"\n", "depth_map.input"),
        (
            "[depth_map]\nlog_odds_occupied = 3.0\n",
            "depth_map.log_odds_occupied",
        ),
        (
            "[depth_map]\nsize_m = [10.0, 10.0, 0.1]\n",
            "depth_map.size_m[2]",
        ),
        ("[depth_map]\nfloor_z_m = nan\n", "depth_map.floor_z_m"),
    ] {
        std::fs::write(&file, text).unwrap();
        let e = stack_config::load_process::<DepthMapConfig>(&file, "depth_map")
            .unwrap_err()
            .to_string();
        assert!(e.contains(key), "{text}: {e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    }
    std::fs::write(&file, "[depth_map]\nfloor_z_m = -inf\n").unwrap();
    assert!(stack_config::load_process::<DepthMapConfig>(&file, "depth_map").is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_input_flag_names_the_two_topics() {
    assert_eq!(
        Input::parse("sim").map(Input::service),
        Some(services::SIM_DEPTH)
    );
    assert_eq!(
        Input::parse("depth-frame").map(Input::service),
        Some(services::DEPTH_FRAME)
    );
    assert_eq!(Input::parse("v4l2"), None);
}
