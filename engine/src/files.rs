//! The names of a run's output files, built in one place: `<out>/<stem>.<what>` for the run's
//! own files (summary, recordings) and `<out>/<stem>.<node>.<what>` for an operator's, with
//! `<stem>` the graph name, or `<graph>-<variant>`, so variants and nodes never overwrite each
//! other. The CLI, the operators (through their `Context`) and `bench` all name files here.

use std::path::{Path, PathBuf};

/// Where a run writes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunFiles {
    /// The output folder.
    pub dir: PathBuf,
    /// `<graph>` or `<graph>-<variant>`.
    pub stem: String,
}

impl RunFiles {
    /// The files of graph `graph` (and `variant`) in `dir`.
    pub fn new(dir: impl AsRef<Path>, graph: &str, variant: Option<&str>) -> Self {
        Self { dir: dir.as_ref().to_path_buf(), stem: Self::stem_of(graph, variant) }
    }
    /// `<graph>` or `<graph>-<variant>`.
    pub fn stem_of(graph: &str, variant: Option<&str>) -> String {
        match variant {
            Some(v) => format!("{graph}-{v}"),
            None => graph.to_owned(),
        }
    }
    /// `<stem>.summary.json`.
    pub fn summary(&self) -> PathBuf {
        self.run_file("summary.json")
    }
    /// `<stem>.<ext>`: a recording (`rrd`, `mcap`, `messages.jsonl`).
    pub fn run_file(&self, ext: &str) -> PathBuf {
        self.dir.join(format!("{}.{ext}", self.stem))
    }
    /// `<stem>.<node>.<what>`: a file an operator writes (`trajectory.txt`, `ot`, ...).
    pub fn node_file(&self, node: &str, what: &str) -> PathBuf {
        self.dir.join(format!("{}.{node}.{what}", self.stem))
    }
}
