//! Running the built `firstshot` binary.

use std::path::Path;
use std::process::{Command, Output};

/// The binary under test.
pub const BIN: &str = env!("CARGO_BIN_EXE_firstshot");

/// A command for the binary.
pub fn firstshot() -> Command {
    Command::new(BIN)
}

/// Runs the binary with `args` in `cwd` (where a default output path would land).
pub fn firstshot_in(cwd: &Path, args: &[&str]) -> Output {
    firstshot().args(args).current_dir(cwd).output().expect("running the firstshot binary")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}
