//! Tests of `scenario`.

use super::*;

fn deploy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy")
}

#[test]
fn every_shipped_scenario_loads_and_builds_a_world() {
    for name in SHIPPED {
        let s = load(name, &deploy()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(&s.scenario.name, name);
        let world = crate::world::World::new(s.world_params(7));
        assert!(world.is_ok(), "{name}: {:?}", world.err());
    }
}

fn write(text: &str, tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("sim-scn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let p = dir.join(format!("{tag}.toml"));
    std::fs::write(&p, text).expect("write");
    p
}

fn base() -> String {
    std::fs::read_to_string(deploy().join("scenarios/paper-sim.toml")).expect("paper-sim")
}

fn error_of(text: &str, tag: &str) -> String {
    let p = write(text, tag);
    load(p.to_str().expect("utf-8"), &deploy())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default()
}

#[test]
fn an_unknown_key_is_named() {
    let e = error_of(&base().replace("duration_s", "duraton_s"), "unknown");
    assert!(e.contains("duraton_s"), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn a_ground_vehicle_faster_than_60_kmh_is_refused() {
    let text = base().replace("speed_m_s = 0.778", "speed_m_s = 20.0");
    let e = error_of(&text, "fast");
    assert!(e.contains("ground_vehicle.") && e.contains("20"), "{e}");
}

#[test]
fn a_negative_mass_airframe_is_refused() {
    let dir = std::env::temp_dir().join(format!("sim-af-{}", std::process::id()));
    let airframes = dir.join("config/airframes");
    std::fs::create_dir_all(&airframes).expect("dir");
    std::fs::create_dir_all(dir.join("scenarios")).expect("dir");
    let p450 = std::fs::read_to_string(deploy().join("config/airframes/p450.toml")).expect("p450");
    std::fs::write(
        airframes.join("p450.toml"),
        p450.replace("mass_kg = 1.5", "mass_kg = -1.0"),
    )
    .expect("write");
    let scn = dir.join("scenarios/x.toml");
    std::fs::write(&scn, base()).expect("write");
    let e = load(scn.to_str().expect("utf-8"), &dir)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("airframe.mass_kg") && e.contains("-1"), "{e}");
}

#[test]
fn an_unknown_scenario_name_lists_the_shipped_ones() {
    let e = load("paper-simm", &deploy())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.contains("paper-simm") && e.contains("highspeed-30-curve"),
        "{e}"
    );
}

#[test]
fn a_faults_table_is_read_and_reaches_the_autopilot() {
    let text = format!(
        "{}\n[faults]\nreject_arming_times = 2\nreject_offboard = true\ntelemetry_stop_s = 12.0\n",
        base()
    );
    let p = write(&text, "faults");
    let s = load(p.to_str().expect("utf-8"), &deploy()).expect("loads");
    assert_eq!(s.scenario.faults.reject_arming_times, 2);
    assert!(s.scenario.faults.reject_offboard);
    assert_eq!(s.scenario.faults.telemetry_stop_s, Some(12.0));
    let sim = crate::lockstep::Simulator::new(&s, 1).expect("simulator");
    assert_eq!(sim.commander().faults(), &s.scenario.faults);
}

#[test]
fn a_bad_fault_is_named_in_one_line() {
    let e = error_of(
        &format!("{}\n[faults]\ntelemetry_stop_s = -1.0\n", base()),
        "fault-neg",
    );
    assert!(
        e.contains("faults.telemetry_stop_s") && e.contains("-1"),
        "{e}"
    );
    assert!(!e.contains('\n'), "{e}");
    let e = error_of(
        &format!(
            "{}\n[faults]\nreject_arming = true\nreject_arming_times = 1\n",
            base()
        ),
        "fault-both",
    );
    assert!(e.contains("faults.reject_arming_times"), "{e}");
    let e = error_of(
        &format!("{}\n[faults]\nreject_landing = true\n", base()),
        "fault-unknown",
    );
    assert!(e.contains("reject_landing"), "{e}");
    assert!(!e.contains('\n'), "{e}");
}

#[test]
fn the_mass_draw_differs_between_seeds_repeats_for_a_seed_and_stays_within_its_spread() {
    let errors = AirframeErrors::default();
    let factors: Vec<f64> = (0..200).map(|seed| errors.draw_mass_factor(seed)).collect();
    for (seed, k) in factors.iter().enumerate() {
        assert!((0.9..1.1).contains(k), "seed {seed}: {k}");
        assert_eq!(*k, errors.draw_mass_factor(seed as u64), "seed {seed}");
    }
    let mut distinct = factors.clone();
    distinct.sort_by(f64::total_cmp);
    distinct.dedup();
    assert_eq!(distinct.len(), factors.len(), "every seed its own mass");
    // Spread over the whole range, not bunched: both tails are reached.
    assert!(
        distinct[0] < 0.92 && distinct[distinct.len() - 1] > 1.08,
        "{distinct:?}"
    );
}

#[test]
fn a_scenario_flies_the_drawn_mass_while_its_autopilot_keeps_the_files_hover_thrust() {
    let s = load("paper-sim", &deploy()).expect("paper-sim");
    let nominal = s.airframe.clone();
    for seed in [1, 2, 3] {
        let w = s.world_params(seed);
        let k = s.scenario.airframe_errors.draw_mass_factor(seed);
        assert!((w.airframe.mass_kg - nominal.mass_kg * k).abs() < 1e-12);
        assert!(
            (w.airframe.inertia_diag_kg_m2[0] - nominal.inertia_diag_kg_m2[0] * k).abs() < 1e-15
        );
        assert_eq!(w.airframe.thrust_coefficient, nominal.thrust_coefficient);
        let autopilot = w.autopilot.expect("tuned autopilot");
        assert_eq!(autopilot.mpc_thr_hover, nominal.hover_thrust_normalized());
    }
    assert_ne!(
        s.world_params(1).airframe.mass_kg,
        s.world_params(2).airframe.mass_kg
    );
}

#[test]
fn a_zero_mass_spread_flies_the_airframe_file_and_a_large_one_is_refused() {
    let p = write(
        &format!("{}\n[airframe_errors]\nmass_spread = 0.0\n", base()),
        "mass-zero",
    );
    let s = load(p.to_str().expect("utf-8"), &deploy()).expect("loads");
    assert_eq!(s.world_params(5).airframe, s.airframe);
    let e = error_of(
        &format!("{}\n[airframe_errors]\nmass_spread = 0.5\n", base()),
        "mass-big",
    );
    assert!(
        e.contains("airframe_errors.mass_spread") && e.contains("0.5"),
        "{e}"
    );
}

#[test]
fn a_seed_moves_the_pad_vehicle_start_and_the_take_off_point_within_the_variation() {
    let v = Variation::default();
    let mut delays = Vec::new();
    for seed in 1..200 {
        let (d, start, takeoff) = v.draw(seed);
        assert_eq!(
            (d, start, takeoff),
            v.draw(seed),
            "the same for the same seed"
        );
        assert!(d.abs() <= v.start_delay_s);
        assert!(start.iter().all(|x| x.abs() <= v.start_offset_m));
        assert!(takeoff.iter().all(|x| x.abs() <= v.takeoff_offset_m));
        delays.push(d);
    }
    assert!(delays.iter().any(|d| *d > 0.3) && delays.iter().any(|d| *d < -0.3));
    assert_eq!(Variation::none().draw(5), (0.0, [0.0; 2], [0.0; 2]));
}

#[test]
fn every_seed_of_every_shipped_scenario_sets_the_vehicle_down_where_it_can_stand() {
    // A second on the ground, disarmed: the pad vehicle may drive off, nothing may crash.
    for name in SHIPPED {
        let s = load(name, &deploy()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut moved = 0;
        for seed in 1..=60 {
            let (_, start, takeoff) = s.variation(seed);
            moved += usize::from(start != [0.0; 2] || takeoff != [0.0; 2]);
            let mut world = crate::world::World::new(s.world_params(seed)).expect("world");
            for _ in 0..1000 {
                world.step(1_000_000).expect("step");
            }
            assert!(!world.crashed(), "{name} seed {seed}: {:?}", world.events());
        }
        assert!(
            moved >= 55,
            "{name}: only {moved} of 60 seeds varied the start"
        );
    }
}
