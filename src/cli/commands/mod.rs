//! One module per subcommand.

pub mod bench;
pub mod compare;
pub mod diff;
pub mod eval;
pub mod graph;
pub mod infer;
pub mod inspect;
pub mod merge;
pub mod octree;
pub mod ops;
pub mod run;
pub mod segment;
pub mod synth;
pub mod top;
pub mod validate;
pub mod view;
pub mod vocab;

use std::path::Path;

use dynaflow_engine::{LoadRequest, Loaded};

/// Load a graph with the shipped operators; print diagnostics (rich on a terminal, plain
/// `file:line:col: …` otherwise). `None` when it cannot run.
pub fn load_and_report(path: &Path, req: &LoadRequest) -> Option<Loaded> {
    let registry = crate::registry();
    let loaded = match dynaflow_engine::load(path, &registry, req) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("error: cannot read graph file {}: {e}", path.display());
            return None;
        }
    };
    print_diagnostics(&loaded);
    Some(loaded)
}

/// Print every diagnostic of a load to stderr.
pub fn print_diagnostics(loaded: &Loaded) {
    use std::io::IsTerminal;
    let rich = std::io::stderr().is_terminal();
    for d in &loaded.diagnostics {
        if rich {
            eprintln!("{:?}", loaded.source.report(d));
        } else {
            eprintln!("{}", loaded.source.plain(d));
        }
    }
}
