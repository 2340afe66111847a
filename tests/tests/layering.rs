//! The crates keep their layers: `ipc_types` is messages only, process libraries never
//! touch the runtime or iceoryx2 (only the binaries do, through `runtime`), crates
//! without a binary do not depend on the runtime at all, and no process crate depends
//! on another process's crate (what two processes share is a library crate of its own:
//! optics, state_history, bspline, px4_protocol). The lockstep runner drives the
//! libraries without IPC; a library that reached for a port would break that quietly.
//! The crate diagram of docs/ARCHITECTURE.md is drawn from `cargo metadata` and checked
//! here, and every crate has a README.

#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a panic is a failed test

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The package names in a manifest's `[dependencies]` (not dev- or build-dependencies).
fn dependencies(manifest: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(manifest).expect("read Cargo.toml");
    let doc: toml::Table = toml::from_str(&text).expect("parse Cargo.toml");
    doc.get("dependencies")
        .and_then(|d| d.as_table())
        .map(|t| t.keys().cloned().collect())
        .unwrap_or_default()
}

/// The package name of the crate at `dir`.
fn package_name(dir: &Path) -> String {
    let text = std::fs::read_to_string(dir.join("Cargo.toml")).expect("read Cargo.toml");
    let doc: toml::Table = toml::from_str(&text).expect("parse Cargo.toml");
    doc.get("package")
        .and_then(|p| p.get("name"))
        .and_then(|n| n.as_str())
        .expect("[package] name")
        .to_string()
}

/// True when the crate at `dir` builds a binary (`src/main.rs` or a `[[bin]]`).
fn has_binary(dir: &Path) -> bool {
    let text = std::fs::read_to_string(dir.join("Cargo.toml")).expect("read Cargo.toml");
    dir.join("src/main.rs").is_file() || text.contains("[[bin]]")
}

/// The library's source files: everything under `src/` but `main.rs`, `src/bin/` and the
/// unit-test files (`*_test.rs`, compiled only under `cfg(test)`).
fn library_sources(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    // Modules the binary declares itself (`mod capture;` in main.rs) are the binary's
    // code, not the library's: its I/O beside the stage (a camera thread, a socket).
    let binary_modules: Vec<String> = std::fs::read_to_string(dir.join("main.rs"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| {
            l.trim()
                .strip_prefix("mod ")?
                .strip_suffix(';')
                .map(|m| format!("{m}.rs"))
        })
        .collect();
    for e in entries.flatten() {
        let p = e.path();
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        if p.is_dir() {
            if name != "bin" {
                library_sources(&p, out);
            }
        } else if name.ends_with(".rs")
            && name != "main.rs"
            && !name.ends_with("_test.rs")
            && !binary_modules.iter().any(|m| m == name)
        {
            out.push(p);
        }
    }
}

/// The code of a Rust file without its `//` comments (doc comments included), so that a
/// sentence mentioning iceoryx2 is not taken for a use of it.
fn code_of(path: &Path) -> String {
    let text = std::fs::read_to_string(path).expect("read source");
    text.lines()
        .map(|l| l.split("//").next().unwrap_or_default())
        .collect::<Vec<_>>()
        .join("\n")
}

/// Byte offsets where `word` starts as a whole path segment (not the tail of a longer
/// identifier).
fn uses_of(code: &str, word: &str) -> Vec<usize> {
    code.match_indices(word)
        .filter(|(i, _)| {
            code[..*i]
                .chars()
                .next_back()
                .is_none_or(|c| !(c.is_alphanumeric() || c == '_'))
        })
        .map(|(i, _)| i)
        .collect()
}

fn process_crates() -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root().join("processes"))
        .expect("processes/")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("Cargo.toml").is_file())
        .collect();
    dirs.sort();
    assert!(
        dirs.len() >= 10,
        "processes/ holds the stack's crates: {dirs:?}"
    );
    dirs
}

#[test]
fn no_process_library_uses_the_runtime_or_iceoryx2() {
    let mut offenders = Vec::new();
    for dir in process_crates() {
        if dir.ends_with("runtime") {
            continue;
        }
        let mut files = Vec::new();
        library_sources(&dir.join("src"), &mut files);
        for f in files {
            let code = code_of(&f);
            for word in ["runtime::", "iceoryx2"] {
                if !uses_of(&code, word).is_empty() {
                    offenders.push(format!("{} uses {word}", f.display()));
                }
            }
        }
    }
    assert!(
        offenders.is_empty(),
        "process libraries take messages and time as arguments; only main.rs binds them \
         to the runtime:\n{}",
        offenders.join("\n")
    );
}

#[test]
fn only_binaries_depend_on_the_runtime_and_none_on_iceoryx2_directly() {
    let mut offenders = Vec::new();
    for dir in process_crates() {
        if dir.ends_with("runtime") {
            continue;
        }
        let deps = dependencies(&dir.join("Cargo.toml"));
        if deps.iter().any(|d| d == "iceoryx2") {
            offenders.push(format!(
                "{}: iceoryx2 in [dependencies] (a binary reaches it through runtime)",
                dir.display()
            ));
        }
        if !has_binary(&dir) && deps.iter().any(|d| d == "runtime") {
            offenders.push(format!(
                "{}: runtime in [dependencies] of a crate without a binary",
                dir.display()
            ));
        }
    }
    assert!(offenders.is_empty(), "{}", offenders.join("\n"));
}

#[test]
fn no_process_crate_depends_on_another_process() {
    let crates = process_crates();
    let processes: Vec<String> = crates
        .iter()
        .filter(|d| has_binary(d))
        .map(|d| package_name(d))
        .collect();
    assert!(processes.iter().any(|p| p == "fsm") && processes.iter().any(|p| p == "sim"));
    let mut offenders = Vec::new();
    for dir in &crates {
        for dep in dependencies(&dir.join("Cargo.toml")) {
            if processes.contains(&dep) {
                offenders.push(format!("{} depends on {dep}", package_name(dir)));
            }
        }
    }
    assert!(
        offenders.is_empty(),
        "a process crate must not pull in another process (tests may, as a \
         dev-dependency); share a library crate instead:\n{}",
        offenders.join("\n")
    );
}

#[test]
fn ipc_types_is_the_message_crate_only() {
    let dir = root().join("ipc_types");
    let deps = dependencies(&dir.join("Cargo.toml"));
    for banned in ["runtime", "stack_config"] {
        assert!(
            !deps.iter().any(|d| d == banned),
            "ipc_types depends on {banned}: it must stay the bottom of the graph"
        );
    }
    let mut files = Vec::new();
    library_sources(&dir.join("src"), &mut files);
    assert!(!files.is_empty());
    for f in files {
        let code = code_of(&f);
        assert!(
            uses_of(&code, "runtime::").is_empty(),
            "{} uses the runtime",
            f.display()
        );
        // iceoryx2 only for the derive that gives payloads their versioned type names.
        for at in uses_of(&code, "iceoryx2") {
            assert!(
                code[at..].starts_with("iceoryx2::prelude::ZeroCopySend"),
                "{}: iceoryx2 beyond ZeroCopySend: {}",
                f.display(),
                code[at..].lines().next().unwrap_or_default()
            );
        }
    }
}

#[test]
fn the_checks_see_a_use_and_ignore_a_comment() {
    let code = "/// binds it to iceoryx2\nfn f() {} // runtime::x\nuse stack_runtime::y;";
    let dir = std::env::temp_dir().join(format!("layering-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("lib.rs");
    std::fs::write(&file, code).unwrap();
    let stripped = code_of(&file);
    assert!(uses_of(&stripped, "iceoryx2").is_empty());
    assert!(uses_of(&stripped, "runtime::").is_empty());
    std::fs::write(&file, "use runtime::Ipc;\nlet x: iceoryx2::Foo;").unwrap();
    let stripped = code_of(&file);
    assert_eq!(uses_of(&stripped, "runtime::"), vec![4]);
    assert_eq!(uses_of(&stripped, "iceoryx2").len(), 1);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every dependency name of a manifest: normal, dev and build.
fn all_dependencies(manifest: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(manifest).expect("read Cargo.toml");
    let doc: toml::Table = toml::from_str(&text).expect("parse Cargo.toml");
    ["dependencies", "dev-dependencies", "build-dependencies"]
        .iter()
        .filter_map(|k| doc.get(*k).and_then(|d| d.as_table()))
        .flat_map(|t| t.keys().cloned())
        .collect()
}

/// The crates in a top-level folder (`tools`, `processes`).
fn crates_in(folder: &str) -> Vec<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root().join(folder))
        .expect("folder")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("Cargo.toml").is_file())
        .collect();
    dirs.sort();
    dirs
}

#[test]
fn nothing_under_processes_or_ipc_types_depends_on_a_tool() {
    let tools: Vec<String> = crates_in("tools").iter().map(|d| package_name(d)).collect();
    assert!(
        tools.iter().any(|t| t == "stack") && tools.iter().any(|t| t == "landing"),
        "{tools:?}"
    );
    let mut offenders = Vec::new();
    for dir in crates_in("processes")
        .into_iter()
        .chain([root().join("ipc_types")])
    {
        for dep in all_dependencies(&dir.join("Cargo.toml")) {
            if tools.contains(&dep) {
                offenders.push(format!(
                    "{} depends on the tool crate {dep}",
                    package_name(&dir)
                ));
            }
        }
    }
    assert!(
        offenders.is_empty(),
        "every crate under processes/ stands below everything under tools/:\n{}",
        offenders.join("\n")
    );
}

/// The longest a process's `main.rs` may be: it parses its arguments, builds its stage
/// through the stage's one constructor and hands it to the driver (issue 15's rule).
const MAIN_LINES: usize = 60;

#[test]
fn every_process_main_is_at_most_60_lines() {
    let mut offenders = Vec::new();
    for dir in process_crates() {
        let main = dir.join("src").join("main.rs");
        let Ok(text) = std::fs::read_to_string(&main) else {
            continue;
        };
        let lines = text.lines().count();
        if lines > MAIN_LINES {
            offenders.push(format!("{}: {lines} lines", main.display()));
        }
    }
    assert!(
        offenders.is_empty(),
        "a process main.rs holds at most {MAIN_LINES} lines; move the rest into its library:\n{}",
        offenders.join("\n")
    );
}

/// The raw constructors of each stage's library, and the one file that may call them:
/// the file of the stage's `from_config`, its one constructor, which its binary, the
/// lockstep registry, the benchmarks, `landing pad detect` and the fuzz targets all call.
const ONE_CONSTRUCTOR: &[(&str, &str)] = &[
    ("PadEstimator::new(", "processes/aruco_pnp/src/stage.rs"),
    ("ArucoStage::new(", "processes/aruco_pnp/src/stage.rs"),
    ("Ingest::new(", "processes/camera_ingest/src/stage.rs"),
    ("IngestStage::new(", "processes/camera_ingest/src/stage.rs"),
    (
        "DepthMapper::from_config(",
        "processes/depth_map/src/stage.rs",
    ),
    ("DepthStage::new(", "processes/depth_map/src/stage.rs"),
    ("PlannerNode::new(", "processes/planner/src/stage.rs"),
    ("Fsm::new(", "processes/fsm/src/stage.rs"),
    ("LinkNode::new(", "processes/px4_link/src/stage.rs"),
    ("LinkStage::new(", "processes/px4_link/src/stage.rs"),
    ("Watchdog::new(", "processes/watchdog/src/stage.rs"),
    ("SimStage::new(", "processes/sim/src/stage.rs"),
    ("SimStage::paced(", "processes/sim/src/stage.rs"),
    ("RecorderStage::new(", "processes/recorder/src/process.rs"),
];

/// Every Rust file of the workspace that is not test code: under `ipc_types/`,
/// `processes/` and `tools/`, outside `tests/` folders and `*_test.rs` files.
fn non_test_sources() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if p.is_dir() {
                if !matches!(name, "tests" | "target" | "fuzz_corpus") {
                    walk(&p, out);
                }
            } else if name.ends_with(".rs") && !name.ends_with("_test.rs") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    for folder in ["ipc_types", "processes", "tools"] {
        walk(&root().join(folder), &mut out);
    }
    out
}

#[test]
fn every_stage_is_built_through_its_one_constructor() {
    let root = root().canonicalize().unwrap();
    let mut offenders = Vec::new();
    for (_, allowed) in ONE_CONSTRUCTOR {
        let home = root.join(allowed);
        let text = std::fs::read_to_string(&home).unwrap_or_default();
        assert!(
            text.contains("pub fn from_config("),
            "{allowed} has no `from_config`, the stage's one constructor"
        );
    }
    for file in non_test_sources() {
        let file = file.canonicalize().unwrap();
        let code = code_of(&file);
        for (call, allowed) in ONE_CONSTRUCTOR {
            if uses_of(&code, call).is_empty() || file == root.join(allowed) {
                continue;
            }
            offenders.push(format!(
                "{} calls {call}..): build the stage with its from_config ({allowed})",
                file.strip_prefix(&root).unwrap_or(&file).display()
            ));
        }
    }
    assert!(offenders.is_empty(), "{}", offenders.join("\n"));
}

/// One crate of the workspace as `cargo metadata` describes it.
#[derive(Debug)]
struct Member {
    /// Its package name.
    name: String,
    /// Its folder, relative to the workspace root (`processes/stage`, `tests`).
    dir: String,
    /// The workspace crates in its `[dependencies]` (not dev- or build-dependencies).
    deps: std::collections::BTreeSet<String>,
}

/// Every crate of the workspace with its normal dependencies on the others, sorted by
/// name, from `cargo metadata --no-deps` (no registry, no lock file: it reads the
/// manifests only, in a few milliseconds).
fn workspace_members() -> Vec<Member> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = std::process::Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(root())
        .output()
        .expect("run cargo metadata");
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).expect("metadata JSON");
    let ws_root = PathBuf::from(meta["workspace_root"].as_str().expect("workspace_root"));
    let packages = meta["packages"].as_array().expect("packages");
    let names: std::collections::BTreeSet<String> = packages
        .iter()
        .map(|p| p["name"].as_str().expect("name").to_string())
        .collect();
    let mut members: Vec<Member> = packages
        .iter()
        .map(|p| {
            let manifest = Path::new(p["manifest_path"].as_str().expect("manifest_path"));
            let dir = manifest
                .parent()
                .and_then(|d| d.strip_prefix(&ws_root).ok())
                .expect("a member's folder is under the workspace root");
            let deps = p["dependencies"]
                .as_array()
                .expect("dependencies")
                .iter()
                .filter(|d| d["kind"].is_null())
                .filter_map(|d| d["name"].as_str())
                .filter(|d| names.contains(*d))
                .map(str::to_string)
                .collect();
            Member {
                name: p["name"].as_str().expect("name").to_string(),
                dir: dir.to_string_lossy().replace('\\', "/"),
                deps,
            }
        })
        .collect();
    members.sort_by(|a, b| a.name.cmp(&b.name));
    members
}

/// The layers of the diagram, top to bottom: the top-level folder a crate is in and the
/// title of its box.
const LAYERS: &[(&str, &str)] = &[
    ("tests", "tests/"),
    ("tools", "tools/"),
    ("processes", "processes/"),
    ("ipc_types", "ipc_types/"),
];

/// A crate's node id in the diagram: `c_` and its name with `-` as `_` (so that no id is
/// a Mermaid keyword such as `graph` or `end`).
fn node_id(name: &str) -> String {
    format!(
        "c_{}",
        name.replace(|c: char| !c.is_ascii_alphanumeric(), "_")
    )
}

/// The crate diagram: a Mermaid flowchart (an arrow from a crate to what it depends on,
/// drawn only where no longer path already leads there, one box per top-level folder),
/// then every direct dependency as a line `crate -> dep, dep`. Sorted throughout, so the
/// same workspace always gives the same text.
fn crate_diagram(members: &[Member]) -> String {
    use std::collections::BTreeSet;
    use std::fmt::Write as _;
    let deps_of = |name: &str| -> &BTreeSet<String> {
        &members
            .iter()
            .find(|m| m.name == name)
            .expect("a workspace crate")
            .deps
    };
    // Whether `to` is reachable from `from` without taking the edge `from -> skip`.
    let reaches_without = |from: &str, skip: &str, to: &str| -> bool {
        let mut stack: Vec<&str> = deps_of(from)
            .iter()
            .map(String::as_str)
            .filter(|d| *d != skip)
            .collect();
        let mut seen = BTreeSet::new();
        while let Some(c) = stack.pop() {
            if c == to {
                return true;
            }
            if seen.insert(c) {
                stack.extend(deps_of(c).iter().map(String::as_str));
            }
        }
        false
    };
    let mut s = String::new();
    s.push_str("```mermaid\nflowchart TD\n");
    for (folder, title) in LAYERS {
        let inside: Vec<&Member> = members
            .iter()
            .filter(|m| m.dir.split('/').next() == Some(*folder))
            .collect();
        if inside.is_empty() {
            continue;
        }
        writeln!(s, "  subgraph layer_{folder} [\"{title}\"]").unwrap();
        for m in inside {
            writeln!(s, "    {}[\"{}\"]", node_id(&m.name), m.name).unwrap();
        }
        s.push_str("  end\n");
    }
    for m in members {
        for d in &m.deps {
            if !reaches_without(&m.name, d, d) {
                writeln!(s, "  {} --> {}", node_id(&m.name), node_id(d)).unwrap();
            }
        }
    }
    s.push_str("```\n\n");
    s.push_str(
        "<details><summary>Every direct dependency between workspace crates \
         ([dependencies] only)</summary>\n\n```\n",
    );
    for m in members {
        let deps: Vec<&str> = m.deps.iter().map(String::as_str).collect();
        if deps.is_empty() {
            writeln!(s, "{} ({})", m.name, m.dir).unwrap();
        } else {
            writeln!(s, "{} ({}) -> {}", m.name, m.dir, deps.join(", ")).unwrap();
        }
    }
    s.push_str("```\n\n</details>\n");
    s
}

const DIAGRAM_START: &str = "<!-- crate-diagram:start -->\n";
const DIAGRAM_END: &str = "<!-- crate-diagram:end -->";

#[test]
fn the_crate_diagram_in_the_architecture_doc_is_the_workspace_as_built() {
    let members = workspace_members();
    assert!(
        members.iter().any(|m| m.name == "stage") && members.iter().any(|m| m.name == "landing"),
        "{members:?}"
    );
    // Every crate sits in one of the diagram's boxes.
    for m in &members {
        let folder = m.dir.split('/').next().unwrap_or_default();
        assert!(
            LAYERS.iter().any(|(f, _)| *f == folder),
            "{} ({}) is in no layer of the diagram: add its folder to LAYERS",
            m.name,
            m.dir
        );
    }
    let expected = crate_diagram(&members);
    let path = root().join("docs/ARCHITECTURE.md");
    let doc = std::fs::read_to_string(&path).expect("read docs/ARCHITECTURE.md");
    let block = doc.find(DIAGRAM_START).and_then(|start| {
        let body = start + DIAGRAM_START.len();
        doc[body..].find(DIAGRAM_END).map(|len| (body, body + len))
    });
    let Some((from, to)) = block else {
        panic!(
            "docs/ARCHITECTURE.md has no {} ... {} block; add one holding:\n\n{expected}",
            DIAGRAM_START.trim_end(),
            DIAGRAM_END
        );
    };
    if doc[from..to] == expected {
        return;
    }
    if std::env::var_os("UPDATE_CRATE_DIAGRAM").is_some() {
        let updated = format!("{}{expected}{}", &doc[..from], &doc[to..]);
        std::fs::write(&path, updated).expect("write docs/ARCHITECTURE.md");
        eprintln!("docs/ARCHITECTURE.md: crate diagram rewritten from cargo metadata");
        return;
    }
    panic!(
        "the crate diagram in docs/ARCHITECTURE.md is not the workspace as built; paste this \
         between the markers (or run with UPDATE_CRATE_DIAGRAM=1):\n\n{expected}"
    );
}

#[test]
fn the_crate_diagram_draws_only_the_edges_no_longer_path_implies() {
    let member = |name: &str, dir: &str, deps: &[&str]| Member {
        name: name.into(),
        dir: dir.into(),
        deps: deps.iter().map(|d| d.to_string()).collect(),
    };
    let members = [
        member("base", "ipc_types", &[]),
        member("mid", "processes/mid", &["base"]),
        member("top-cli", "tools/top-cli", &["base", "mid"]),
    ];
    let text = crate_diagram(&members);
    assert!(text.contains("  c_mid --> c_base\n"), "{text}");
    assert!(text.contains("  c_top_cli --> c_mid\n"), "{text}");
    assert!(!text.contains("c_top_cli --> c_base"), "{text}");
    assert!(
        text.contains("top-cli (tools/top-cli) -> base, mid\n"),
        "{text}"
    );
    assert!(text.contains("base (ipc_types)\n"), "{text}");
    assert!(
        !text.contains("layer_tests"),
        "an empty layer is not drawn: {text}"
    );
}

#[test]
fn every_crate_has_a_readme() {
    let mut missing = Vec::new();
    for m in workspace_members() {
        let readme = root().join(&m.dir).join("README.md");
        let text = std::fs::read_to_string(&readme).unwrap_or_default();
        if text.trim().lines().count() < 3 {
            missing.push(format!("{} ({}/README.md)", m.name, m.dir));
        }
    }
    assert!(
        missing.is_empty(),
        "every crate says in its README what it holds, what it reads and publishes, and \
         how to run or test it alone:\n{}",
        missing.join("\n")
    );
}
