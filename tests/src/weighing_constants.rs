//! The firmware's weighing constants: `firmware/src/weighing_config.rs` is generated from
//! `firmware/weighing.toml` by host-sim's one TOML reader
//! (`host_sim::calibrate::firmware_constants`), so the firmware builds without host-sim's
//! `std` side. This module generates them (for the check, for `cargo xtask` building with
//! another configuration) and says where they live.
//!
//! What must never happen: an image built from constants that differ from its TOML file.
//! `cargo test -p tests --test weighing_constants` fails when the committed file is stale and
//! rewrites it when run with `UPDATE_WEIGHING_CONSTANTS=1`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// The shipped weighing configuration, relative to the workspace root.
pub const SHIPPED_CONFIG: &str = "firmware/weighing.toml";
/// Its generated constants, relative to the workspace root (`firmware/build.rs` reads them).
pub const SHIPPED_CONSTANTS: &str = "firmware/src/weighing_config.rs";
/// Set to rewrite the committed constants instead of checking them.
pub const UPDATE_VAR: &str = "UPDATE_WEIGHING_CONSTANTS";
/// The variable `firmware/build.rs` reads a generated constants file's path from.
pub const CONSTANTS_VAR: &str = "FIRMWARE_WEIGHING_CONSTANTS";

/// The workspace root (this crate's parent).
pub fn workspace_root() -> PathBuf {
    let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest_dir.parent().unwrap_or(manifest_dir).to_path_buf()
}

/// The Rust constants of the weighing configuration `config` (a TOML file), named in their
/// header by `shown` (the path as the user knows it).
pub fn generate(config: &Path, shown: &Path) -> Result<String> {
    let text = std::fs::read_to_string(config)
        .with_context(|| format!("weighing config {}: cannot read it", shown.display()))?;
    host_sim::calibrate::firmware_constants(shown, &text)
}

/// The constants of the shipped configuration, as they must stand in [`SHIPPED_CONSTANTS`].
pub fn shipped() -> Result<String> {
    generate(
        &workspace_root().join(SHIPPED_CONFIG),
        Path::new(SHIPPED_CONFIG),
    )
}
