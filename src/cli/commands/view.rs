//! `dynaflow view FILE.rrd`: hand the file to the rerun viewer.

use std::path::Path;

use crate::cli::{EXIT_BAD_INPUT, EXIT_FAILED, EXIT_OK};

/// The rerun version our recordings are written with; the viewer must match.
const RERUN_VERSION: &str = "0.36.3";

pub fn view(file: &Path) -> u8 {
    if !file.is_file() {
        eprintln!("error: {}: no such recording", file.display());
        return EXIT_BAD_INPUT;
    }
    match std::process::Command::new("rerun").arg(file).status() {
        Ok(status) if status.success() => EXIT_OK,
        Ok(status) => {
            eprintln!("error: the rerun viewer exited with {status}");
            EXIT_FAILED
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            eprintln!(
                "error: the rerun viewer is not installed.\n  install it with `pip install rerun-sdk=={RERUN_VERSION}` (or `cargo install rerun-cli@{RERUN_VERSION} --locked`),\n  then run `rerun {}`",
                file.display()
            );
            EXIT_FAILED
        }
        Err(e) => {
            eprintln!("error: cannot start `rerun`: {e}");
            EXIT_FAILED
        }
    }
}
