//! `dynaflow`: the command-line front end ([`dynaflow::cli`]).

use std::process::ExitCode;

fn main() -> ExitCode {
    ExitCode::from(dynaflow::cli::main_with(std::env::args_os()))
}
