//! Paths and process helpers shared by the xtask modules (also meant for `firmware.rs`).

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

/// The bare-metal target of the Cortex-M4F.
pub const THUMB_TARGET: &str = "thumbv7em-none-eabihf";

/// The variable through which the host tests find the `on-target` ELFs (a directory).
pub const ON_TARGET_ELF_DIR_VAR: &str = "ON_TARGET_ELF_DIR";

/// The workspace root (the `tests` package sits one level below it).
pub fn workspace_root() -> PathBuf {
    let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest_dir.parent().unwrap_or(manifest_dir).to_path_buf()
}

/// Cargo's target directory for builds started from here: `CARGO_TARGET_DIR` if set,
/// otherwise `<workspace>/target` (the project sets no `build.target-dir`).
pub fn target_dir() -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) => {
            let dir = PathBuf::from(dir);
            if dir.is_absolute() {
                dir
            } else {
                workspace_root().join(dir)
            }
        }
        None => workspace_root().join("target"),
    }
}

/// A `cargo` command (the same cargo that runs the xtask) in the workspace root.
pub fn cargo() -> Command {
    let program = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut command = Command::new(program);
    command.current_dir(workspace_root());
    command
}

/// Run a command with inherited stdio; `Err` if it cannot start or exits non-zero.
pub fn run_checked(command: &mut Command) -> Result<()> {
    let shown = format!("{command:?}");
    let status = command
        .status()
        .with_context(|| format!("cannot start {shown}"))?;
    if !status.success() {
        bail!("{shown} exited with {status}");
    }
    Ok(())
}

/// Build every binary of the bare-metal `on-target` package (release: fat LTO, as shipped)
/// and return the directory of the ELFs, checking that `expected_bin` is there.
pub fn build_on_target(expected_bin: &str) -> Result<PathBuf> {
    run_checked(cargo().args([
        "build",
        "--release",
        "-p",
        "on-target",
        "--target",
        THUMB_TARGET,
        "--bins",
    ]))?;
    let dir = target_dir().join(THUMB_TARGET).join("release");
    if !dir.join(expected_bin).is_file() {
        bail!(
            "built on-target but found no {expected_bin} in {}",
            dir.display()
        );
    }
    Ok(dir)
}
