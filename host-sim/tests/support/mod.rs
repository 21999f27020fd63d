//! What the command-line tests share: the `host-sim` binary, a scratch directory per test
//! binary and process, and running a command that must succeed.
// Each test binary uses its own part of this module.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// The `host-sim` binary of this build.
pub fn host_sim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

/// This test process's scratch directory for the test binary `suite` (not created).
pub fn scratch_dir(suite: &str) -> PathBuf {
    std::env::temp_dir().join(format!("host-sim-{suite}-{}", std::process::id()))
}

/// A file `name` in [`scratch_dir`], the directory created.
pub fn scratch(suite: &str, name: &str) -> PathBuf {
    let dir = scratch_dir(suite);
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// Run `command`; it must succeed. Its stdout (stderr in the failure message).
pub fn run_ok(command: &mut Command) -> String {
    let output = command.output().unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
}

/// Run `command`; it must fail. Its stderr (what the user is told).
pub fn run_refused(command: &mut Command) -> String {
    let output = command.output().unwrap();
    assert!(!output.status.success());
    String::from_utf8_lossy(&output.stderr).into_owned()
}
