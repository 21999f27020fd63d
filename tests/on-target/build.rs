//! Links the bare-metal binaries with cortex-m-rt's `link.x` against the workspace root's
//! `memory.x`, with `__board_mps2_an386` defined so the code sits in the AN386's SSRAM at 0
//! where QEMU loads it (see `memory.x`).
use std::{env, path::PathBuf};

fn main() {
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let workspace_root = manifest_dir.join("../..");
    println!("cargo:rustc-link-search={}", workspace_root.display());
    println!("cargo:rerun-if-changed=../../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    // Only the binaries are linked; the arguments are scoped to them so that no global
    // rustflags are needed (the firmware package links with its own scripts).
    println!("cargo:rustc-link-arg-bins=--defsym=__board_mps2_an386=1");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
}
