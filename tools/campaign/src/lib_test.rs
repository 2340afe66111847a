use super::*;

#[test]
fn shards_split_the_runs_and_bad_ones_are_refused() {
    let shards: Vec<Shard> = ["1/3", "2/3", "3/3"]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect();
    for i in 0..30u64 {
        assert_eq!(shards.iter().filter(|s| s.has(i)).count(), 1, "run {i}");
    }
    for bad in ["0/3", "4/3", "1/0", "3", "a/b", "-1/3"] {
        let e = bad.parse::<Shard>().unwrap_err();
        assert!(e.contains("allowed: K/N"), "{bad}: {e}");
    }
}

fn deploy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy")
}

#[test]
fn a_campaign_refuses_no_runs_an_unknown_scenario_and_a_scenario_twice() {
    let out = std::env::temp_dir().join("campaign-refuses");
    let specs = |s: &[&str]| s.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    let e = Campaign::new(&specs(&["paper-sim"]), 0, 1, None, &deploy(), None, &out).unwrap_err();
    assert_eq!(
        e.to_string(),
        "--runs 0 is not allowed (allowed: 1 to 1000000)"
    );
    let e = Campaign::new(&specs(&["no-such"]), 3, 1, None, &deploy(), None, &out).unwrap_err();
    assert!(e.to_string().starts_with("scenario `no-such`:"), "{e}");
    let e = Campaign::new(
        &specs(&["paper-sim", "paper-sim"]),
        3,
        1,
        None,
        &deploy(),
        None,
        &out,
    )
    .unwrap_err();
    assert_eq!(e.to_string(), "scenario `paper-sim` is asked for twice");
}

#[test]
fn a_shard_flies_its_indices_with_the_seeds_of_the_whole() {
    let out = std::env::temp_dir().join("campaign-shard-seeds");
    let s = vec!["paper-sim".to_string(), "indoor-static".to_string()];
    let whole = Campaign::new(&s, 10, 7, None, &deploy(), None, &out).unwrap();
    let mut parts = Vec::new();
    for k in 1..=3 {
        let shard = Some(Shard { k, n: 3 });
        parts.extend(
            Campaign::new(&s, 10, 7, shard, &deploy(), None, &out)
                .unwrap()
                .tasks(),
        );
    }
    let mut all = whole.tasks();
    let key = |t: &Task| (t.scenario, t.index);
    all.sort_by_key(key);
    parts.sort_by_key(key);
    assert_eq!(all, parts);
    assert_eq!(all.len(), 20);
}
