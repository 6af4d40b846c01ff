//! `dynaflow inspect BAG [--json]`: what a ROS 1 or ROS 2 bag holds (topics with their types,
//! counts, header-stamp spans and rates) and which topic a run would take for each role, or the
//! candidates when a role is ambiguous.

use std::path::PathBuf;

use dynaflow_ros::Bag;
use dynaflow_ros::inspect::{ROLES, inspect as inventory};

use crate::cli::{EXIT_BAD_INPUT, EXIT_OK};

/// `dynaflow inspect` arguments.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {
    /// A ROS 1 `.bag`, a rosbag2 folder (`metadata.yaml`), or a bare `.mcap` / `.db3`.
    pub bag: PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

/// Exit 0 with the listing; 2 for a missing, corrupt or truncated bag (the error names it).
pub fn inspect(args: &InspectArgs) -> u8 {
    let inv = match Bag::open(&args.bag).and_then(|bag| inventory(&bag)) {
        Ok(inv) => inv,
        Err(e) => {
            eprintln!("error: {e}");
            return EXIT_BAD_INPUT;
        }
    };
    if args.json {
        let mut v = serde_json::to_value(&inv).unwrap_or_default();
        v["bag"] = args.bag.display().to_string().into();
        println!("{v}");
        return EXIT_OK;
    }
    println!("{}", args.bag.display());
    let width = inv.topics.iter().map(|t| t.topic.len()).max().unwrap_or(5).max(5);
    let tw = inv.topics.iter().map(|t| t.ty.len()).max().unwrap_or(4).max(4);
    println!("  {:width$}  {:tw$}  {:>7}  {:>9}  {:>8}  content", "topic", "type", "count", "rate Hz", "span s");
    for t in &inv.topics {
        println!(
            "  {:width$}  {:tw$}  {:>7}  {:>9.2}  {:>8.2}  {}",
            t.topic,
            t.ty,
            t.count,
            t.rate_hz,
            t.span_s[1] - t.span_s[0],
            t.content.as_deref().unwrap_or("")
        );
    }
    println!("a run would use:");
    for role in ROLES {
        let c = inv.candidates.get(role).map(Vec::as_slice).unwrap_or_default();
        match c {
            [] => println!("  {role:12} none"),
            [one] => println!("  {role:12} {one}"),
            many => println!("  {role:12} ambiguous: {} (more than one topic fits; none is taken)", many.join(", ")),
        }
    }
    EXIT_OK
}
