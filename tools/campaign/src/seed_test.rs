use super::*;

#[test]
fn a_seed_depends_on_the_base_the_scenario_and_the_index_only() {
    assert_eq!(derive(1, "paper-sim", 7), derive(1, "paper-sim", 7));
    let mut seen = std::collections::HashSet::new();
    for base in [1, 2] {
        for scenario in ["paper-sim", "outdoor-2"] {
            for i in 0..1000 {
                assert!(
                    seen.insert(derive(base, scenario, i)),
                    "{base} {scenario} {i}"
                );
            }
        }
    }
}
