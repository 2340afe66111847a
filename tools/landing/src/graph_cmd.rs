//! `landing graph`: prints the pipeline's dataflow graph (deploy/graph.toml) as text,
//! one JSON object or Graphviz DOT, after checking every rule of it.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use stack_config::deploy_dir;

/// Arguments of `landing graph`.
#[derive(Debug, Args)]
pub struct GraphArgs {
    /// The graph file (default: the deploy directory's graph.toml).
    #[arg(long, value_name = "FILE")]
    graph: Option<PathBuf>,
    /// The deploy directory (default: $LANDING_DEPLOY_DIR, else found above the current
    /// directory or the executable).
    #[arg(long, value_name = "DIR")]
    deploy_dir: Option<PathBuf>,
    /// Print one JSON object: {"nodes": [{"name", "inputs", "outputs", "rate_hz", ...}],
    /// "topics": [{"name", "service", "type", ...}]}.
    #[arg(long, conflicts_with = "dot")]
    json: bool,
    /// Print Graphviz DOT (`landing graph --dot | dot -Tsvg > graph.svg`).
    #[arg(long)]
    dot: bool,
}

/// Loads, checks and prints the graph.
pub fn run(args: &GraphArgs) -> Result<()> {
    let path = args.graph.clone().unwrap_or_else(|| {
        graph::default_path(&args.deploy_dir.clone().unwrap_or_else(deploy_dir))
    });
    let g = graph::Graph::load(&path)?;
    if args.json {
        println!("{}", serde_json::to_string(&g)?);
    } else if args.dot {
        print!("{}", graph::dot(&g));
    } else {
        println!("graph {}", path.display());
        print!("{}", graph::text(&g));
    }
    Ok(())
}
