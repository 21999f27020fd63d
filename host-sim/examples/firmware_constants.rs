//! The firmware's weighing constants from a weighing configuration, for a plain cargo build
//! of an image with a file other than the shipped one (`cargo xtask` generates them itself):
//! the same `host_sim::calibrate::firmware_constants` that `cargo xtask` calls.
//!
//! `cargo run --release -p host-sim --example firmware_constants -- CONFIG.toml OUT.rs`, then
//! build with `FIRMWARE_WEIGHING_CONSTANTS=OUT.rs` (an absolute path: `firmware/build.rs`
//! reads it from the firmware's directory).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let (Some(config), Some(out)) = (args.next().map(PathBuf::from), args.next()) else {
        bail!("usage: firmware_constants CONFIG.toml OUT.rs");
    };
    let text =
        std::fs::read_to_string(&config).with_context(|| format!("read {}", config.display()))?;
    let source = host_sim::calibrate::firmware_constants(&config, &text)?;
    std::fs::write(&out, source).with_context(|| format!("write {out}"))?;
    eprintln!("{out}");
    Ok(())
}
