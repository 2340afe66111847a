//! The pipeline never sees ground truth: no process crate but the simulator (and the
//! stage and runtime crates, whose drivers carry every topic) may name the evaluator-only
//! truth topic or its message, and the simulator's library must not hand
//! its truth to the MAVLink side (it reports the estimate).

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn no_pipeline_process_opens_the_truth_topic() {
    let processes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../processes");
    let mut offenders = Vec::new();
    for entry in std::fs::read_dir(&processes).expect("processes/") {
        let dir = entry.expect("entry").path();
        // The simulator makes the truth; `stage` and `runtime` carry every topic's
        // message type, and both drivers refuse a node reading an evaluator-only topic
        // (tested in stage/tests/lockstep.rs), as the graph's check does (`graph`
        // names the truth topic to refuse it: processes/graph/src/check.rs).
        if dir
            .file_name()
            .is_some_and(|n| n == "sim" || n == "stage" || n == "runtime" || n == "graph")
        {
            continue;
        }
        let mut files = Vec::new();
        rust_files(&dir.join("src"), &mut files);
        // The recorder's library also writes the evaluator's truth file (`landing run
        // --record`: FILE.truth.mcap), so it names the truth types; its process (main.rs,
        // and process.rs, which picks what it subscribes to) must not, and takes no
        // evaluator-only topic (the driver refuses one, too).
        if dir.file_name().is_some_and(|n| n == "recorder") {
            let picks = std::fs::read_to_string(dir.join("src/process.rs")).expect("process.rs");
            assert!(picks.contains("!t.evaluator_only"), "recorder: {picks}");
            files.retain(|f| {
                f.file_name()
                    .is_some_and(|n| n == "main.rs" || n == "process.rs")
            });
        }
        for f in files {
            let text = std::fs::read_to_string(&f).expect("read");
            if text.contains("SIM_TRUTH")
                || text.contains("TruthEvent")
                || text.contains("TruthState")
            {
                offenders.push(f);
            }
        }
    }
    assert!(offenders.is_empty(), "ground truth used in: {offenders:?}");
}

#[test]
fn the_recorder_subscribes_to_no_truth_topic_of_the_shipped_graph() {
    let deploy = Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy");
    let graph = graph::Graph::load(&graph::default_path(&deploy)).expect("graph");
    let spec = recorder::process::node_spec(&graph, &[]);
    assert!(spec.inputs.len() > 10, "{spec:?}");
    for i in &spec.inputs {
        let info = ipc_types::topics::find(&i.topic).expect("a known topic");
        assert!(!info.evaluator_only, "the recorder reads {}", i.topic);
    }
}

#[test]
fn the_simulated_autopilot_reports_the_estimate_not_the_truth() {
    let px4 = Path::new(env!("CARGO_MANIFEST_DIR")).join("../processes/sim/src/px4");
    let mut files = Vec::new();
    rust_files(&px4, &mut files);
    assert!(!files.is_empty());
    for f in files {
        let text = std::fs::read_to_string(&f).expect("read");
        assert!(
            !text.contains(".truth()"),
            "{} reads the world's truth",
            f.display()
        );
    }
}
